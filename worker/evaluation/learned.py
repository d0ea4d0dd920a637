"""``shapes evaluate --fusion learned``: the fusion learned on the collection itself, every
figure from held-out folds.

Each fused modality is offered with D1 and D2 (eq. 8-9), and the spectrum also with
ShapeDNA's comparison (lapy's ``reweight_ev`` then the Euclidean distance); each of five
(or fewer) class-stratified folds chooses every modality's comparison and weight under
the preset's rule on the other folds' meshes
(:func:`worker.recognition.fusion.learn_fusion`, the code a gallery learns with).

The report's ``learned`` row holds only held-out figures: the retrieval ones (NN, R1RR,
FT, ST, E, DCG, mAP) with each mesh as a query under the choice of the fold that held it
out (:attr:`FusionTuning.held_out_matrix`); the verification ones per fold, on the pairs
involving its meshes under its choice, then averaged (the EER the folds' mean, the ROC
averaged vertically: each fold's fusion has its own score scale, so their scores are not
pooled under one threshold). ``learned_fusion`` in report.json holds each fold's choice,
and the preset's weights scored on the same folds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict
from typing import Any

import numpy as np

from worker.engine.presets import Preset
from worker.recognition.calibration import calibrate
from worker.recognition.fusion import REPEATS, Adoption, FusionTuning

from .scoring import FAR_OPERATING_POINTS, ROC_POINTS_STORED, score_dissimilarity

LEARNED = "learned"


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
    decision: Adoption,
    preset: Preset,
    labels: Sequence[str],
    names: Sequence[str],
    gallery_idx: np.ndarray,
    probe_idx: np.ndarray,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The report's ``learned`` row and its ``learned_fusion`` section (with
    ``decision``, the adoption test a gallery would make on the collection)."""
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
        "adoption": {**asdict(decision), "rounds": REPEATS},
    }
    return row, section
