"""Every number of the report: all-to-all dissimilarity matrices and their metrics.

Pure functions on arrays, tested directly.

For D2 (eq. 9) the ``sigma_i`` are the standard deviations of descriptor element
``i`` over *all* evaluated objects: in the all-to-all protocol the whole set is the
gallery. The paper does not say which set it used.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from worker.engine.compare import fuse, gallery_sigma
from worker.engine.presets import MODALITIES, SIZE, Preset
from worker.recognition import metrics
from worker.recognition.calibration import calibrate
from worker.recognition.fusion import all_to_all, preset_all_to_all

from .shapedna import BASELINE, shapedna_dissimilarity

#: Rows of the report, in table order: key -> (title, members, fusion rule).
#: ``members`` are modalities, or the baseline; ``rule`` is None for a single one.
#: A collection of metric units has two more before the baseline's (:func:`report_rows`).
ROWS: dict[str, tuple[str, tuple[str, ...], str | None]] = {
    "gdm": ("GDM", ("gdm",), None),
    "ddt": ("DDT", ("ddt",), None),
    "spectrum": ("Spectrum", ("spectrum",), None),
    "gdm+ddt sum": ("GDM+DDT sum", ("gdm", "ddt"), "sum"),
    "gdm+ddt product": ("GDM+DDT product", ("gdm", "ddt"), "product"),
    "gdm+ddt+spectrum sum": ("GDM+DDT+Spectrum sum", ("gdm", "ddt", "spectrum"), "sum"),
    "gdm+ddt+spectrum product": (
        "GDM+DDT+Spectrum product",
        ("gdm", "ddt", "spectrum"),
        "product",
    ),
    BASELINE: ("ShapeDNA (lapy)", (BASELINE,), None),
}

Row = tuple[str, tuple[str, ...], str | None]


def metric_row_key(preset: Preset) -> str:
    """The row of the preset's score with the size (units "metric"), e.g.
    ``"gdm+ddt+spectrum+size product"``."""
    return "+".join(preset.scored_modalities) + f" {preset.fusion}"


def report_rows(preset: Preset) -> dict[str, Row]:
    """The report's rows for ``preset``, in table order: :data:`ROWS`, and with units
    "metric" the size alone and the preset's score with the size, before the baseline."""
    if preset.units != "metric":
        return dict(ROWS)
    titles = {"gdm": "GDM", "ddt": "DDT", "spectrum": "Spectrum", SIZE: "Size"}
    rows = {k: v for k, v in ROWS.items() if k != BASELINE}
    rows[SIZE] = ("Size", (SIZE,), None)
    scored = preset.scored_modalities
    rows[metric_row_key(preset)] = (
        "+".join(titles[m] for m in scored) + f" {preset.fusion}",
        scored,
        preset.fusion,
    )
    rows[BASELINE] = ROWS[BASELINE]
    return rows


#: Table columns: key in a row's scores -> header.
COLUMNS: dict[str, str] = {
    "nn": "NN",
    "r1rr": "R1RR",
    "eer": "EER",
    "first_tier": "FT",
    "second_tier": "ST",
    "e_measure": "E",
    "dcg": "DCG",
    "map": "mAP",
}

#: FAR values at which the report states the FRR.
FAR_OPERATING_POINTS = (0.001, 0.01, 0.05, 0.1)
#: The ROC stored in report.json is thinned to at most this many points.
ROC_POINTS_STORED = 400


def modality_dissimilarity(vectors: np.ndarray, kind: str) -> tuple[np.ndarray, dict[str, Any]]:
    """All-to-all dissimilarity of one modality with D1 (eq. 8) or D2 (eq. 9).

    Parameters
    ----------
    vectors : (n, M) float, one flat descriptor per object.
    kind : ``"D1"`` or ``"D2"`` (:func:`worker.engine.compare.dissimilarity`).

    Returns
    -------
    matrix : (n, n) float, symmetric, zero diagonal.
    info : how it was made; for D2 it holds ``sigma`` (M,), the per-element standard
        deviation over all ``n`` objects (the all-to-all protocol's gallery).
    """
    x = np.atleast_2d(np.asarray(vectors, dtype=np.float64))
    info: dict[str, Any] = {"dissimilarity": kind}
    sigma = None
    if kind == "D2":  # recorded in the report, so computed here rather than inside
        sigma = gallery_sigma(x)
        info.update(sigma=sigma, sigma_over="all evaluated objects")
    return all_to_all(x, kind, sigma), info


def preset_matrix(
    modality: str, vectors: np.ndarray, preset: Preset
) -> tuple[np.ndarray, dict[str, Any]]:
    """All-to-all dissimilarity of one modality as the preset compares it: the size by
    :func:`~worker.recognition.fusion.preset_all_to_all` (the size's comparison at the
    preset's tolerance, zero on the diagonal), the others by :func:`modality_dissimilarity`
    with its D1 or D2."""
    if modality != SIZE:
        return modality_dissimilarity(vectors, preset.dissimilarity)
    return preset_all_to_all(SIZE, vectors, preset), {"dissimilarity": preset.comparison(SIZE)}


def dissimilarity_matrices(
    vectors: Mapping[str, np.ndarray],
    preset: Preset,
    baseline: np.ndarray | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
    """Every row of the report as an all-to-all dissimilarity matrix.

    Parameters
    ----------
    vectors : modality -> (n, M) float, for every modality in ``MODALITIES`` (and
        ``SIZE`` when the preset's units are metric).
    preset : gives the dissimilarity (D1/D2; the size's, :func:`preset_matrix`), the
        fusion weights and the units.
    baseline : (n, k) float, ShapeDNA descriptors; the baseline row is left out if None.

    Returns
    -------
    matrices : row key (:func:`report_rows`) -> (n, n) float.
    info : row key -> how the matrix was made.

    Notes
    -----
    Fusion combines the raw per-modality matrices with the preset's weights:
    sum ``sum_m w_m D_m``, product ``prod_m D_m ** w_m``. The product's ranking does
    not depend on each modality's scale; the sum's does (with D2 the modality with
    more elements weighs more), exactly as the paper's rules are stated.
    """
    per_modality: dict[str, np.ndarray] = {}
    matrices: dict[str, np.ndarray] = {}
    info: dict[str, dict[str, Any]] = {}
    for modality in MODALITIES:
        per_modality[modality], info[modality] = modality_dissimilarity(
            vectors[modality], preset.dissimilarity
        )
    if preset.units == "metric":
        per_modality[SIZE], info[SIZE] = preset_matrix(SIZE, vectors[SIZE], preset)
    for key, (_, members, rule) in report_rows(preset).items():
        if key == BASELINE:
            if baseline is not None:
                matrices[key] = shapedna_dissimilarity(baseline)
                info[key] = {
                    "dissimilarity": "euclidean (lapy.shapedna.compute_distance, dist='euc')"
                }
            continue
        if rule is None:
            matrices[key] = per_modality[members[0]]
            continue
        weights = {m: preset.weight(m) for m in members}
        matrices[key] = fuse({m: per_modality[m] for m in members}, rule, weights)
        info[key] = {"fusion": rule, "weights": weights}
    return matrices, info


def _thin(far: np.ndarray, frr: np.ndarray, points: int) -> tuple[list[float], list[float]]:
    if far.size <= points:
        return far.tolist(), frr.tolist()
    idx = np.unique(np.round(np.geomspace(1, far.size, points)).astype(int) - 1)
    idx = np.union1d(idx, np.linspace(0, far.size - 1, points // 4).astype(int))
    return far[idx].tolist(), frr[idx].tolist()


def score_dissimilarity(
    dissimilarity: np.ndarray,
    labels: Sequence[str],
    names: Sequence[str],
    gallery_idx: np.ndarray,
    probe_idx: np.ndarray,
) -> dict[str, Any]:
    """Every metric of one all-to-all dissimilarity matrix.

    Parameters
    ----------
    dissimilarity : (n, n) float, symmetric.
    labels, names : (n,) class and file name of each object.
    gallery_idx, probe_idx : the identification split (:func:`metrics.first_instance_split`).

    Returns
    -------
    dict with the table's numbers (``nn``, ``r1rr``, ``eer``, ``first_tier``,
    ``second_tier``, ``e_measure``, ``dcg``, ``map``, all fractions in [0, 1]),
    ``cmc`` (g,), ``roc`` (thinned far/frr lists), ``frr_at_far``, and the errors:
    ``nn_errors`` and ``rank1_errors`` (which object was mistaken for which).
    """
    d = np.asarray(dissimilarity, dtype=np.float64)
    classes = np.asarray([str(x) for x in labels])
    retrieval = metrics.retrieval_scores(d, classes)
    # Verification with the service's calibration code, so that this report's ROC and
    # EER are GET /calibration's for a gallery of the same labelled meshes.
    i, j = np.triu_indices(len(d), 1)
    same = classes[i] == classes[j]
    verification = calibrate(d[i, j][same], d[i, j][~same], min_pairs=1)
    far, frr = verification.far, verification.frr
    cmc = metrics.cmc_curve(d, classes, gallery_idx, probe_idx)
    roc_far, roc_frr = _thin(far, frr, ROC_POINTS_STORED)
    # FRR at a FAR operating point: the lowest FRR among thresholds with FAR <= target.
    frr_at_far = {str(t): float(frr[far <= t].min()) for t in FAR_OPERATING_POINTS}

    masked = d + np.diag(np.full(len(d), np.inf))
    nearest = np.argmin(masked, axis=1)  # ties -> lower index, as metrics' retrieval
    nn_errors = [
        {"query": names[i], "class": classes[i], "nearest": names[j], "nearest_class": classes[j]}
        for i, j in enumerate(nearest)
        if classes[i] != classes[j]
    ]
    scores = d[np.ix_(probe_idx, gallery_idx)]
    best = np.argmin(scores, axis=1)
    rank1_errors = [
        {
            "probe": names[p],
            "class": classes[p],
            "matched": names[gallery_idx[b]],
            "matched_class": classes[gallery_idx[b]],
        }
        for p, b in zip(probe_idx, best, strict=True)
        if classes[gallery_idx[b]] != classes[p]
    ]
    return {
        **retrieval,
        "r1rr": float(cmc[0]),
        "eer": verification.eer,
        "cmc": cmc.tolist(),
        "roc": {"far": roc_far, "frr": roc_frr},
        "frr_at_far": frr_at_far,
        "nn_errors": nn_errors,
        "rank1_errors": rank1_errors,
    }
