"""The gallery's verification calibration: genuine and impostor scores of its labelled shapes.

Every pair of enrolled shapes that both carry a label is genuine (same label) or
impostor (different labels); their dissimilarities under the preset, fused and per
modality, calibrated by :func:`worker.recognition.calibration.calibrate` (the code
``shapes evaluate`` reports its ROC and EER with), answer "is this the same
object?" at a chosen false acceptance rate, and give each match a confidence.

Refitted, not updated: a gallery of n labelled shapes has n(n-1)/2 pairs, all of
them scored up to ``max_pairs``; above that, half the budget goes to genuine pairs
and half to impostor pairs, drawn uniformly at random (seeded). The cost is
linear in the pairs scored: 200,000 pairs (the default budget, reached at 633
labelled shapes) take about a second, the same at 100,000 shapes.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from worker.engine.compare import fuse, paired_preset_dissimilarity
from worker.engine.presets import Preset
from worker.recognition.calibration import Calibration, calibrate

from .index import GalleryIndex

#: Row key of the preset's own fused score (the others are modality names).
FUSED = "fused"


@dataclass(frozen=True)
class GalleryCalibration:
    """A fit of the gallery's calibration.

    Attributes
    ----------
    rows : ``FUSED`` and each modality -> its Calibration.
    shapes : enrolled shapes when fitted; ``labelled`` of them carry a label,
        ``labels`` distinct ones.
    sampled : whether the pairs are a sample (above the pair budget).
    version : the gallery's change counter when fitted.
    fitted_at : Unix time of the fit.
    preset : the preset scored with (its dissimilarity and weights).
    pair_scores : each modality's dissimilarity of every scored pair, and
        ``genuine`` which of them are genuine: any other fusion a search asks for is
        calibrated from them (:meth:`for_fusion`).
    """

    rows: dict[str, Calibration]
    shapes: int
    labelled: int
    labels: int
    sampled: bool
    version: int
    fitted_at: float
    preset: Preset
    pair_scores: dict[str, np.ndarray] = field(repr=False)
    genuine: np.ndarray = field(repr=False)
    _fusions: dict[tuple[tuple[str, ...], str], Calibration] = field(
        default_factory=dict, repr=False, compare=False
    )
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def for_fusion(self, modalities: tuple[str, ...], rule: str) -> Calibration:
        """The calibration of the score a search ranks by: ``modalities`` fused by
        ``rule`` with the preset's weights, as the index fuses them (one modality: its
        own row; the preset's own fusion: ``FUSED``). Others are fitted on first use
        from the stored pair scores (milliseconds) and kept with this fit."""
        if len(modalities) == 1:
            return self.rows[modalities[0]]
        preset = self.preset
        if modalities == preset.scored_modalities and rule == preset.fusion:
            return self.rows[FUSED]
        key = (modalities, rule)
        with self._lock:
            known = self._fusions.get(key)
            if known is None:
                weights = {m: preset.weight(m) for m in modalities}
                scores = fuse({m: self.pair_scores[m] for m in modalities}, rule, weights)
                known = calibrate(scores[self.genuine], scores[~self.genuine])
                self._fusions[key] = known
            return known

    def histogram(self, bins: int = 24) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(edges, genuine, impostor)``: the fused score's pairs counted over ``bins``
        shared bins, even on a log scale (the product rule's scores span decades)."""
        preset = self.preset
        scored = preset.scored_modalities
        weights = {m: preset.weight(m) for m in scored}
        scores = np.asarray(
            fuse({m: self.pair_scores[m] for m in scored}, preset.fusion, weights),
            dtype=np.float64,
        )
        positive = scores[scores > 0]
        low = float(positive.min()) if len(positive) else 1.0
        high = max(float(scores.max()), low * 1.001)
        edges = np.geomspace(low, high, bins + 1)
        clipped = np.clip(scores, low, high)
        genuine = np.histogram(clipped[self.genuine], edges)[0]
        impostor = np.histogram(clipped[~self.genuine], edges)[0]
        return edges, genuine, impostor


class NotEnoughPairs(ValueError):
    """Too few genuine or impostor pairs among the labelled shapes; the message says so."""


def fit_calibration(
    index: GalleryIndex,
    labels: Mapping[int, str],
    preset: Preset,
    *,
    max_pairs: int,
    version: int,
    seed: int = 0,
) -> GalleryCalibration:
    """Score the labelled shapes' pairs and calibrate the fused score and each modality.

    Parameters
    ----------
    index : the gallery's index (read under its lock).
    labels : mesh id -> label, for the shapes that have one.
    preset : dissimilarity, fusion rule and weights.
    max_pairs : the most pairs scored.
    version : the gallery's change counter, recorded with the fit.

    Raises
    ------
    NotEnoughPairs
        Fewer genuine or impostor pairs than a calibration needs.
    """
    shapes = len(index)
    names, vectors, sigma = index.labelled_vectors(labels)
    _, codes = np.unique(names, return_inverse=True)
    first, second, sampled = _pairs(codes, max_pairs, np.random.default_rng(seed))
    genuine = codes[first] == codes[second]
    per = {
        m: paired_preset_dissimilarity(
            m,
            vectors[m][first],
            vectors[m][second],
            preset,
            sigma[m],
        )
        for m in index.modalities
    }
    scored = preset.scored_modalities
    weights = {m: preset.weight(m) for m in scored}
    scores = {FUSED: fuse({m: per[m] for m in scored}, preset.fusion, weights)}
    scores.update(per)
    try:
        rows = {key: calibrate(s[genuine], s[~genuine]) for key, s in scores.items()}
    except ValueError:
        raise NotEnoughPairs(
            f"The gallery's labelled shapes make {int(genuine.sum())} genuine (same label) and "
            f"{int((~genuine).sum())} impostor pairs; calibration needs at least 10 of each: "
            "enroll more meshes with labels, several per label."
        ) from None
    return GalleryCalibration(
        rows=rows,
        shapes=shapes,
        labelled=len(names),
        labels=int(len(set(names.tolist()))),
        sampled=sampled,
        version=version,
        fitted_at=time.time(),
        preset=preset,
        pair_scores=per,
        genuine=genuine,
    )


def _pairs(
    codes: np.ndarray, max_pairs: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Indices of the pairs to score: all of them, or a sample of genuine and impostor."""
    n = len(codes)
    if n * (n - 1) // 2 <= max_pairs:
        first, second = np.triu_indices(n, 1)
        return first, second, False
    half = max_pairs // 2
    # Genuine: a class drawn in proportion to its pairs, then two of its members.
    members = [np.flatnonzero(codes == c) for c in range(codes.max() + 1)]
    sizes = np.array([len(m) for m in members], dtype=np.float64)
    weight = sizes * (sizes - 1) / 2
    chosen: list[tuple[np.ndarray, np.ndarray]] = []
    if weight.sum() > 0:
        classes = rng.choice(len(members), size=half, p=weight / weight.sum())
        a = np.empty(half, dtype=np.int64)
        b = np.empty(half, dtype=np.int64)
        for c in np.unique(classes):
            rows = np.flatnonzero(classes == c)
            size = len(members[c])
            i = rng.integers(0, size, len(rows))
            j = rng.integers(0, size - 1, len(rows))
            j += j >= i  # two distinct members
            a[rows], b[rows] = members[c][i], members[c][j]
        chosen.append((a, b))
    # Impostor: uniform pairs of different labels (most random pairs are).
    a = rng.integers(0, n, size=2 * half)
    b = rng.integers(0, n, size=2 * half)
    other = codes[a] != codes[b]
    chosen.append((a[other][:half], b[other][:half]))
    return (
        np.concatenate([c[0] for c in chosen]),
        np.concatenate([c[1] for c in chosen]),
        True,
    )
