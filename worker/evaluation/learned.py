"""``shapes evaluate --fusion learned``: the fusion learned on the collection itself, every
figure from held-out folds.

Each fused modality is offered with D1 and D2 (eq. 8-9), and the spectrum also with
ShapeDNA's comparison (lapy's ``reweight_ev`` then the Euclidean distance); each of five
(or fewer, :func:`learn_fusion`) class-stratified folds chooses every modality's
comparison and weight under the preset's rule on the other folds' meshes
(:func:`worker.recognition.fusion.tune_fusion`).

The report's ``learned`` row holds only held-out figures: the retrieval ones (NN, R1RR,
FT, ST, E, DCG, mAP) with each mesh as a query under the choice of the fold that held it
out (:attr:`FusionTuning.held_out_matrix`); the verification ones per fold, on the pairs
involving its meshes under its choice, then averaged (the EER the folds' mean, the ROC
averaged vertically: each fold's fusion has its own score scale, so their scores are not
pooled under one threshold). ``learned_fusion`` in report.json holds each fold's choice,
and the preset's weights scored on the same folds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict
from typing import Any

import numpy as np
from scipy.spatial.distance import cdist

from worker.engine.presets import SIZE, Preset
from worker.recognition.calibration import calibrate
from worker.recognition.fusion import (
    ADOPTION_MARGIN,
    FusionTuning,
    feasible_folds,
    tune_fusion,
)

from .scoring import (
    FAR_OPERATING_POINTS,
    ROC_POINTS_STORED,
    modality_dissimilarity,
    preset_matrix,
    score_dissimilarity,
)

LEARNED = "learned"
#: ShapeDNA's comparison of the spectrum, as an alternative the folds may choose.
REWEIGHTED = "reweighted euclidean"


def reweighted_euclidean(spectra: np.ndarray) -> np.ndarray:
    """ShapeDNA's comparison (lapy's ``reweight_ev`` and Euclidean distance) of spectra
    without the zero eigenvalue: entry ``j`` (0-based) is eigenvalue ``j + 2`` of lapy's
    numbering, divided by ``j + 2``."""
    x = np.asarray(spectra, dtype=np.float64)
    weighted = x / np.arange(2, x.shape[1] + 2)
    return np.asarray(cdist(weighted, weighted), dtype=np.float64)


def learn_fusion(
    vectors: Mapping[str, np.ndarray], labels: Sequence[str], preset: Preset
) -> FusionTuning:
    """Cross-validate the fused modalities' comparisons and weights on a collection, in
    ``FOLDS`` folds or the most that can (:func:`feasible_folds`: each holds a mesh and
    leaves two of every class to choose on).

    With metric units the size is weighed too (``vectors`` has it), first, so that the
    preset's last modality keeps weight 1 and the size's is on the grid, always with its
    own comparison (:meth:`Preset.comparison`).

    Raises
    ------
    ValueError
        A class of fewer than three meshes, or too few meshes for two folds.
    """
    folds = feasible_folds(labels)
    own = preset.dissimilarity
    other = "D2" if own == "D1" else "D1"
    metric = preset.units == "metric"
    order = (SIZE, *preset.fused_modalities) if metric else preset.fused_modalities
    dissimilarities = {m: preset_matrix(m, vectors[m], preset)[0] for m in order}
    alternatives: dict[str, dict[str, np.ndarray]] = {
        m: {other: modality_dissimilarity(vectors[m], other)[0]} for m in preset.fused_modalities
    }
    if "spectrum" in alternatives:
        alternatives["spectrum"][REWEIGHTED] = reweighted_euclidean(vectors["spectrum"])
    weights = {m: preset.weight(m) for m in order}
    return tune_fusion(
        dissimilarities,
        np.asarray(labels),
        preset.fusion,
        weights,
        folds=folds,
        comparison={m: preset.comparison(m) for m in order},
        alternatives=alternatives,
    )


def _fold_verification(tuning: FusionTuning, labels: Sequence[str]) -> dict[str, Any]:
    """EER, ROC and FRR at the operating FARs, each fold on its own pairs, averaged."""
    grid = np.concatenate([[0.0], np.geomspace(1e-4, 1.0, ROC_POINTS_STORED - 1)])
    eers, curves, operating = [], [], []
    for fold in range(len(tuning.folds)):
        fit = calibrate(*tuning.fold_pairs(fold, labels), min_pairs=1)
        eers.append(fit.eer)
        # The lowest FRR among thresholds whose FAR is at most each grid point.
        order = np.argsort(fit.far, kind="stable")
        lowest = np.minimum.accumulate(fit.frr[order])
        at = np.searchsorted(fit.far[order], grid, side="right") - 1
        curves.append(np.where(at >= 0, lowest[np.maximum(at, 0)], 1.0))
        operating.append([float(fit.frr[fit.far <= t].min()) for t in FAR_OPERATING_POINTS])
    return {
        "eer": float(np.mean(eers)),
        "roc": {"far": grid.tolist(), "frr": np.mean(curves, axis=0).tolist()},
        "frr_at_far": {
            str(t): float(v)
            for t, v in zip(FAR_OPERATING_POINTS, np.mean(operating, 0), strict=True)
        },
    }


def learned_row(
    tuning: FusionTuning,
    preset: Preset,
    labels: Sequence[str],
    names: Sequence[str],
    gallery_idx: np.ndarray,
    probe_idx: np.ndarray,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The report's ``learned`` row and its ``learned_fusion`` section."""
    row = {
        "title": "Learned fusion (held-out folds)",
        "members": list(preset.scored_modalities),
        "rule": preset.fusion,
        "weights": tuning.weights,
        "comparisons": tuning.comparisons,
        **score_dissimilarity(tuning.held_out_matrix, labels, names, gallery_idx, probe_idx),
        **_fold_verification(tuning, labels),
    }
    section = {
        "folds": [
            {
                "held_out_objects": fold.held_out_objects,
                "weights": fold.weights,
                "comparisons": fold.comparisons,
                "held_out": {"learned": asdict(fold.held_out), "preset": asdict(fold.preset)},
            }
            for fold in tuning.folds
        ],
        "chosen_on_all": {
            "weights": tuning.weights,
            "comparisons": tuning.comparisons,
        },
        "held_out": {
            "learned": asdict(tuning.held_out),
            "preset": asdict(tuning.preset_held_out),
        },
        "adoption_margin": ADOPTION_MARGIN,
        "beats_preset": tuning.beats_preset(ADOPTION_MARGIN),
    }
    return row, section
