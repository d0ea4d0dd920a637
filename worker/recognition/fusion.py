"""Fusion weights learnt from labelled objects, by class-stratified cross-validation.

The paper fuses its modalities with equal weights and leaves weighting them to future
work (sec. 5). Here the preset's rule fuses them with one weight each,
``prod_m D_m ** w_m`` or ``sum_m w_m D_m`` (:func:`worker.engine.compare.fuse`), and the
weights are chosen on labelled objects. The last fused modality keeps weight 1: scaling
every weight by ``c`` raises the product to the power ``c`` and multiplies the sum by
``c``, neither of which changes a ranking or a ROC, so only the weights' ratios matter.
Every combination of the other weights on a grid is scored by its loss, the mean of the
EER and 1 - mAP (verification and retrieval errors weigh equally).

Cross-validation: ``k`` class-stratified folds (:func:`stratified_folds`); the weights
are chosen on the objects of the other folds and measured on what they were not chosen
on (:func:`fusion_scores` with ``held_out``): the EER over the pairs that involve a
held-out object, NN and mAP with the held-out objects as queries, each ranking every
other object.

Pure numpy on all-to-all dissimilarity matrices: ``shapes tune`` (a labelled collection
described through the evaluation cache) and a gallery learning its own fusion weigh with
the same code.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from worker.engine.compare import fuse

from . import metrics

#: The weights tried for every fused modality but the last (which keeps 1).
GRID = (0.0, 0.125, 0.25, 0.5, 1.0)
#: Folds of the cross-validation.
FOLDS = 5


def stratified_folds(labels: ArrayLike, k: int, seed: int = 0) -> NDArray[np.int64]:
    """Fold of each object for class-stratified cross-validation.

    Every class is spread evenly over the ``k`` folds (its objects in a random order,
    dealt out from a random fold onwards, so small classes do not all start in fold 0).

    Parameters
    ----------
    labels : (n,) array_like, class of each object.
    k : number of folds.
    seed : seeds the random order and the first fold of each class.

    Returns
    -------
    (n,) int, the fold of each object, in ``0 .. k - 1``.
    """
    labels = np.asarray(labels)
    rng = np.random.default_rng(seed)
    fold = np.empty(len(labels), dtype=np.int64)
    for c in np.unique(labels):
        idx = rng.permutation(np.flatnonzero(labels == c))
        fold[idx] = (np.arange(len(idx)) + rng.integers(k)) % k
    return fold


@dataclass(frozen=True)
class FusionScores:
    """How well one dissimilarity recognizes: fractions in [0, 1].

    Attributes
    ----------
    eer : equal error rate (lower is better).
    nn : nearest-neighbour rate (higher is better).
    map : mean average precision (higher is better).
    """

    eer: float
    nn: float
    map: float

    @property
    def loss(self) -> float:
        """What the weights minimize: verification and retrieval errors, equally."""
        return 0.5 * (self.eer + (1.0 - self.map))

    @classmethod
    def mean(cls, scores: list[FusionScores]) -> FusionScores:
        """Each figure's mean over ``scores`` (e.g. over the folds)."""
        return cls(
            eer=float(np.mean([s.eer for s in scores])),
            nn=float(np.mean([s.nn for s in scores])),
            map=float(np.mean([s.map for s in scores])),
        )


@dataclass(frozen=True)
class FoldResult:
    """One fold of the cross-validation.

    Attributes
    ----------
    held_out_objects : objects in this fold.
    weights : modality -> weight, chosen on the objects of the other folds.
    held_out : those weights' scores on this fold (:func:`fusion_scores`, ``held_out``).
    preset : the preset's own weights' scores on the same pairs and queries.
    """

    held_out_objects: int
    weights: dict[str, float]
    held_out: FusionScores
    preset: FusionScores


@dataclass(frozen=True)
class FusionTuning:
    """Fusion weights chosen on a labelled set, and how they do on held-out objects.

    Attributes
    ----------
    rule : the fusion rule, ``"sum"`` or ``"product"``.
    grid : the weights tried for every modality but the last.
    weights : modality -> weight, chosen on every object (what a preset takes).
    loss : the loss of ``weights`` on every object.
    folds : each fold's choice and held-out scores.
    held_out : the mean over the folds of their chosen weights' held-out scores.
    preset_held_out : the same mean for the preset's own weights, for comparison.
    sensitivity : modality -> (len(grid),) loss on every object with that modality's
        weight at each grid point and the others as chosen (how sharply the set decides;
        every modality but the last).
    """

    rule: str
    grid: tuple[float, ...]
    weights: dict[str, float]
    loss: float
    folds: tuple[FoldResult, ...]
    held_out: FusionScores
    preset_held_out: FusionScores
    sensitivity: dict[str, tuple[float, ...]]


def fusion_scores(
    dissimilarity: ArrayLike, labels: ArrayLike, held_out: ArrayLike | None = None
) -> FusionScores:
    """EER, NN and mAP of an all-to-all dissimilarity.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float, symmetric.
    labels : (n,) array_like, every class with at least two objects.
    held_out : (q,) array_like of int, optional. The EER over the pairs that involve
        one of these objects, NN and mAP with them as queries (each ranking all other
        objects): the figures of a fold whose weights were chosen on the others.
        Default: every pair and every object.

    Returns
    -------
    FusionScores
    """
    d = np.asarray(dissimilarity, dtype=np.float64)
    labels = np.asarray(labels)
    if held_out is None:
        retrieval = metrics.retrieval_scores(d, labels)
        eer = metrics.equal_error_rate(d, labels)
    else:
        queries = np.asarray(held_out, dtype=np.int64)
        i, j = np.triu_indices(len(d), 1)
        tested = np.isin(i, queries) | np.isin(j, queries)
        same = labels[i] == labels[j]
        eer = metrics.pair_equal_error_rate(d[i, j][tested & same], d[i, j][tested & ~same])
        retrieval = metrics.retrieval_scores(d, labels, queries=queries)
    return FusionScores(eer=eer, nn=retrieval["nn"], map=retrieval["map"])


def choose_weights(
    dissimilarities: Mapping[str, NDArray[np.float64]],
    labels: ArrayLike,
    rule: str,
    grid: tuple[float, ...] = GRID,
) -> tuple[dict[str, float], float]:
    """The grid weights with the lowest loss on these objects.

    Parameters
    ----------
    dissimilarities : modality -> (n, n) float, in fusion order; the last keeps weight 1.
    labels : (n,) array_like.
    rule : ``"sum"`` or ``"product"``.
    grid : the weights tried for every modality but the last.

    Returns
    -------
    weights : modality -> weight; of equal losses, the earlier grid point (the
        smaller weights) wins.
    loss : their :attr:`FusionScores.loss`.
    """
    names = list(dissimilarities)
    if not names:
        raise ValueError("no dissimilarity to weigh")
    scored = []
    for w in itertools.product(grid, repeat=len(names) - 1):
        weights = dict(zip(names, (*w, 1.0), strict=True))
        scored.append((fusion_scores(fuse(dissimilarities, rule, weights), labels).loss, weights))
    loss, weights = min(scored, key=lambda item: item[0])  # the first of equal losses
    return weights, loss


def tune_fusion(
    dissimilarities: Mapping[str, ArrayLike],
    labels: ArrayLike,
    rule: str,
    preset_weights: Mapping[str, float],
    *,
    folds: int = FOLDS,
    grid: tuple[float, ...] = GRID,
    seed: int = 0,
) -> FusionTuning:
    """Choose one fusion weight per modality by class-stratified cross-validation.

    Parameters
    ----------
    dissimilarities : modality -> (n, n) array_like of float, all-to-all and symmetric,
        in fusion order (the last keeps weight 1); at least two modalities.
    labels : (n,) array_like, the class of each object.
    rule : ``"sum"`` or ``"product"``, the preset's rule.
    preset_weights : modality -> the preset's own weight, scored on the same folds.
    folds : number of folds, at least 2.
    grid : the weights tried for every modality but the last.
    seed : of :func:`stratified_folds`.

    Returns
    -------
    FusionTuning

    Raises
    ------
    ValueError
        With fewer than two modalities, matrices of different shapes or not matching
        ``labels``, fewer than two folds, or a class too small for the folds: every
        fold must hold an object and leave at least two of every class to choose on.
    """
    mats = {m: np.asarray(d, dtype=np.float64) for m, d in dissimilarities.items()}
    labels = np.asarray(labels)
    if len(mats) < 2:
        raise ValueError(f"fusion weights need at least two modalities, got {list(mats)}")
    n = len(labels)
    shapes = {m: d.shape for m, d in mats.items() if d.shape != (n, n)}
    if shapes:
        raise ValueError(f"{n} labels need ({n}, {n}) dissimilarities, got {shapes}")
    if folds < 2:
        raise ValueError(f"cross-validation needs at least 2 folds, got {folds}")
    fold = stratified_folds(labels, folds, seed)
    classes = np.unique(labels)
    for f in range(folds):
        if not np.any(fold == f):
            raise ValueError(f"{n} objects cannot fill {folds} folds: use fewer folds")
        left = {str(c): int(np.sum((labels == c) & (fold != f))) for c in classes}
        thin = sorted(c for c, count in left.items() if count < 2)
        if thin:
            raise ValueError(
                f"with {folds} folds, classes {thin} keep fewer than two objects to choose "
                "weights on: use fewer folds or more objects of them"
            )
    results = []
    for f in range(folds):
        train, held = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        training = {m: d[np.ix_(train, train)] for m, d in mats.items()}
        weights, _ = choose_weights(training, labels[train], rule, grid)
        results.append(
            FoldResult(
                held_out_objects=len(held),
                weights=weights,
                held_out=fusion_scores(fuse(mats, rule, weights), labels, held),
                preset=fusion_scores(fuse(mats, rule, preset_weights), labels, held),
            )
        )
    weights, loss = choose_weights(mats, labels, rule, grid)
    sensitivity = {
        m: tuple(fusion_scores(fuse(mats, rule, {**weights, m: w}), labels).loss for w in grid)
        for m in list(mats)[:-1]
    }
    return FusionTuning(
        rule=rule,
        grid=grid,
        weights=weights,
        loss=loss,
        folds=tuple(results),
        held_out=FusionScores.mean([r.held_out for r in results]),
        preset_held_out=FusionScores.mean([r.preset for r in results]),
        sensitivity=sensitivity,
    )
