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

A modality may also come with other comparisons than the preset's (``alternatives``:
D1 or D2 of eq. 8-9, ShapeDNA's reweighted Euclidean distance of the spectrum): each
fold then chooses every modality's comparison with its weight, on the same loss.

The held-out choices make one dissimilarity for the whole set
(:attr:`FusionTuning.held_out_matrix`): row ``i`` fused with the choice of the fold that
held ``i`` out, so every figure computed from it (per query, or per pair read from its
first object's row) is a held-out one.

Pure numpy on all-to-all dissimilarity matrices: ``shapes tune``, ``shapes evaluate
--fusion learned`` (a labelled collection described through the evaluation cache) and a
gallery learning its own fusion (``app/gallery/weights.py``) weigh with the same code.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from worker.engine.compare import (
    combine_terms,
    dissimilarity,
    fuse,
    fusion_term,
    gallery_sigma,
    preset_dissimilarity,
)
from worker.engine.presets import COMPARISONS, SIZE, Preset

from . import metrics

#: The weights tried for every fused modality but the last (which keeps 1).
GRID = (0.0, 0.125, 0.25, 0.5, 1.0)
#: Folds of the cross-validation.
FOLDS = 5
#: Rounds of the folds (each dealt from its own seed) a gallery decides on: fewer let the
#: split decide (docs/decisions.md, "A collection learns each modality's comparison").
REPEATS = 10
#: A gallery adopts the learned fusion when the held-out folds favour it beyond their
#: noise: the one-sided corrected resampled t-test (:meth:`FusionTuning.adoption`) of the
#: folds' gains in loss rejects "no gain" at this confidence.
ADOPTION_CONFIDENCE = 0.95
#: The name of the comparison each modality's matrix in ``dissimilarities`` was made with
#: (the preset's), when the caller offers ``alternatives``.
PRESET_COMPARISON = "preset"


def all_to_all(
    vectors: NDArray[np.float64], kind: str, sigma: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """(n, n) dissimilarity of (n, M) descriptors to each other with D1 (eq. 8) or D2
    (eq. 9, with ``sigma``): exactly symmetric (D2's expansion differs from its
    transpose by rounding), zero on the diagonal."""
    x = np.atleast_2d(np.asarray(vectors, dtype=np.float64))
    return _symmetric(dissimilarity(x, x, kind, sigma))


def preset_all_to_all(
    modality: str,
    vectors: NDArray[np.float64],
    preset: Preset,
    sigma: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """:func:`all_to_all` with the modality's comparison under ``preset``
    (:func:`~worker.engine.compare.preset_dissimilarity`: the size's, or D1/D2)."""
    x = np.atleast_2d(np.asarray(vectors, dtype=np.float64))
    return _symmetric(preset_dissimilarity(modality, x, x, preset, sigma))


def _symmetric(d: ArrayLike) -> NDArray[np.float64]:
    """Exactly symmetric (the mean with the transpose), zero on the diagonal."""
    a = np.asarray(d, dtype=np.float64)
    a = 0.5 * (a + a.T)
    np.fill_diagonal(a, 0.0)
    return a


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
    comparisons : modality -> the comparison chosen with it.
    held_out : that choice's scores on this fold (:func:`fusion_scores`, ``held_out``).
    preset : the preset's own weights' scores on the same pairs and queries.
    """

    held_out_objects: int
    weights: dict[str, float]
    comparisons: dict[str, str]
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
    comparisons : modality -> comparison, chosen with ``weights``.
    loss : the loss of ``weights`` on every object.
    folds : each fold's choice and held-out scores (``repeats`` rounds of the folds, one
        after the other).
    held_out : the mean over the folds of their chosen weights' held-out scores.
    preset_held_out : the same mean for the preset's own weights, for comparison.
    sensitivity : modality -> (len(grid),) loss on every object with that modality's
        weight at each grid point and the others as chosen (how sharply the set decides;
        every modality but the last).
    held_out_matrix : (n, n), row ``i`` the fused dissimilarity of object ``i`` under
        the choice of the fold that held it out, in the first round (not symmetric; rows
        of different folds are on different scales, so a pair's score is read from the
        row of the fold it is scored in: :meth:`fold_pairs`).
    fold_of : (n,) the fold of the first round that held each object out.
    repeats : rounds of the folds.
    """

    rule: str
    grid: tuple[float, ...]
    weights: dict[str, float]
    comparisons: dict[str, str]
    loss: float
    folds: tuple[FoldResult, ...]
    held_out: FusionScores
    preset_held_out: FusionScores
    sensitivity: dict[str, tuple[float, ...]]
    held_out_matrix: NDArray[np.float64]
    fold_of: NDArray[np.int64]
    repeats: int = 1

    def fold_pairs(
        self, fold: int, labels: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The genuine and impostor scores of the pairs that involve an object of
        ``fold`` (of the first round), under that fold's choice (its held-out
        verification)."""
        labels = np.asarray(labels)
        i, j = np.triu_indices(len(labels), 1)
        first = self.fold_of[i] == fold
        tested = first | (self.fold_of[j] == fold)
        score = np.where(first, self.held_out_matrix[i, j], self.held_out_matrix[j, i])[tested]
        same = (labels[i] == labels[j])[tested]
        return score[same], score[~same]

    def adoption(self, confidence: float = ADOPTION_CONFIDENCE) -> Adoption:
        """Whether the held-out folds favour the learned choice over the preset's weights
        beyond the folds' own noise.

        Each fold's gain is the preset's held-out loss minus the learned choice's, on
        the same objects. Their mean over the ``k`` folds of every round is tested against
        zero by the corrected resampled t-test of Nadeau and Bengio (2003, "Inference for
        the generalization error"; over repeated rounds, Bouckaert and Frank's corrected
        repeated k-fold test, 2004): the folds' training sets overlap, so their gains are
        correlated and the plain paired t-test's variance ``s^2 / k`` is too small; the
        corrected one is ``s^2 (1 / k + n_test / n_train)``. Adopted when the gain is
        positive and its statistic exceeds Student's one-sided quantile at
        ``confidence`` with ``k - 1`` degrees of freedom; a choice that gains the same on
        every fold (``s = 0``) is adopted when that gain is positive.
        """
        gains = np.array([f.preset.loss - f.held_out.loss for f in self.folds])
        k = len(gains)
        n = sum(f.held_out_objects for f in self.folds)
        ratio = float(np.mean([f.held_out_objects / (n - f.held_out_objects) for f in self.folds]))
        gain = float(gains.mean())
        spread = float(gains.std(ddof=1)) * np.sqrt(1.0 / k + ratio)
        if spread > 0:
            statistic = gain / spread
        else:
            statistic = float(np.inf) if gain > 0 else 0.0
        # Imported here: scipy.stats takes most of a second to load, and the shapes
        # command (which names FOLDS in its help) must start at once.
        from scipy.stats import t as student_t

        critical = float(student_t.ppf(confidence, k - 1))
        return Adoption(
            gain=gain,
            statistic=statistic,
            critical=critical,
            confidence=confidence,
            adopted=bool(gain > 0 and statistic > critical),
        )


@dataclass(frozen=True)
class Adoption:
    """The test of a learned fusion against the preset's weights on the held-out folds.

    Attributes
    ----------
    gain : mean over the folds of the preset's loss minus the learned choice's (a
        fraction; positive: the learned choice does better).
    statistic : the corrected resampled t statistic of that gain.
    critical : Student's one-sided quantile it must exceed.
    confidence : of that quantile.
    adopted : the gain is positive and its statistic above the quantile.
    """

    gain: float
    statistic: float
    critical: float
    confidence: float
    adopted: bool


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
    if held_out is None:
        return _scores(metrics.LabelledSet(labels), dissimilarity)
    d = np.asarray(dissimilarity, dtype=np.float64)
    labels = np.asarray(labels)
    queries = np.asarray(held_out, dtype=np.int64)
    i, j = np.triu_indices(len(d), 1)
    tested = np.isin(i, queries) | np.isin(j, queries)
    same = labels[i] == labels[j]
    eer = metrics.pair_equal_error_rate(d[i, j][tested & same], d[i, j][tested & ~same])
    retrieval = metrics.retrieval_scores(d, labels, queries=queries)
    return FusionScores(eer=eer, nn=retrieval["nn"], map=retrieval["map"])


def _scores(labelled: metrics.LabelledSet, dissimilarity: ArrayLike) -> FusionScores:
    """:func:`fusion_scores` over every pair and object of ``labelled``'s set."""
    eer, nn, average_precision = labelled.figures(dissimilarity)
    return FusionScores(eer=eer, nn=nn, map=average_precision)


Candidates = Mapping[str, Mapping[str, NDArray[np.float64]]]
"""modality -> comparison -> (n, n) dissimilarity; the first comparison is the preset's."""


def choose_fusion(
    candidates: Candidates, labels: ArrayLike, rule: str, grid: tuple[float, ...] = GRID
) -> tuple[dict[str, float], dict[str, str], float]:
    """The comparisons and grid weights with the lowest loss on these objects.

    Parameters
    ----------
    candidates : modality -> comparison -> (n, n) float, in fusion order; the last
        modality keeps weight 1.
    labels : (n,) array_like.
    rule : ``"sum"`` or ``"product"``.
    grid : the weights tried for every modality but the last.

    Returns
    -------
    weights : modality -> weight; comparisons : modality -> comparison. Of equal losses
        the earlier wins: the first comparisons (the preset's), the smaller weights.
    loss : their :attr:`FusionScores.loss`.
    """
    names = list(candidates)
    if not names:
        raise ValueError("no dissimilarity to weigh")
    # The labels' work and each modality's weighted terms, once for every weighting.
    labelled = metrics.LabelledSet(labels)
    terms = {
        m: {c: {w: fusion_term(d, rule, w) for w in {*grid, 1.0}} for c, d in by.items()}
        for m, by in candidates.items()
    }
    best: tuple[float, dict[str, float], dict[str, str]] | None = None
    for chosen in itertools.product(*(list(candidates[m]) for m in names)):
        comparisons = dict(zip(names, chosen, strict=True))
        for w in itertools.product(grid, repeat=len(names) - 1):
            weights = dict(zip(names, (*w, 1.0), strict=True))
            fused = combine_terms((terms[m][comparisons[m]][weights[m]] for m in names), rule)
            loss = _scores(labelled, fused).loss
            if best is None or loss < best[0]:
                best = (loss, weights, comparisons)
    assert best is not None
    return best[1], best[2], best[0]


def choose_weights(
    dissimilarities: Mapping[str, NDArray[np.float64]],
    labels: ArrayLike,
    rule: str,
    grid: tuple[float, ...] = GRID,
) -> tuple[dict[str, float], float]:
    """:func:`choose_fusion` with one comparison per modality: the weights and their loss."""
    candidates = {m: {PRESET_COMPARISON: d} for m, d in dissimilarities.items()}
    weights, _, loss = choose_fusion(candidates, labels, rule, grid)
    return weights, loss


def _checked_folds(labels: NDArray[Any], folds: int, seed: int) -> NDArray[np.int64]:
    """:func:`stratified_folds`, or ValueError saying why they cannot cross-validate."""
    if folds < 2:
        raise ValueError(f"cross-validation needs at least 2 folds, got {folds}")
    fold = stratified_folds(labels, folds, seed)
    classes = np.unique(labels)
    for f in range(folds):
        if not np.any(fold == f):
            raise ValueError(f"{len(labels)} objects cannot fill {folds} folds: use fewer folds")
        left = {str(c): int(np.sum((labels == c) & (fold != f))) for c in classes}
        thin = sorted(c for c, count in left.items() if count < 2)
        if thin:
            raise ValueError(
                f"with {folds} folds, classes {thin} keep fewer than two objects to choose "
                "weights on: use fewer folds or more objects of them"
            )
    return fold


def feasible_folds(labels: ArrayLike, folds: int = FOLDS, seed: int = 0, repeats: int = 1) -> int:
    """The most folds, at most ``folds``, that cross-validate ``labels`` (every fold holds
    an object and leaves two of every class to choose on) in each of ``repeats`` rounds
    (dealt from ``seed``, ``seed + 1``, ...).

    Raises
    ------
    ValueError
        Not even two folds do (a class of fewer than three objects, or too few objects).
    """
    labels = np.asarray(labels)
    for k in range(folds, 2, -1):
        try:
            for r in range(repeats):
                _checked_folds(labels, k, seed + r)
        except ValueError:
            continue
        return k
    for r in range(repeats):
        _checked_folds(labels, 2, seed + r)  # raises why not even two folds do
    return 2


def tune_fusion(
    dissimilarities: Mapping[str, ArrayLike],
    labels: ArrayLike,
    rule: str,
    preset_weights: Mapping[str, float],
    *,
    folds: int = FOLDS,
    grid: tuple[float, ...] = GRID,
    seed: int = 0,
    comparison: str | Mapping[str, str] = PRESET_COMPARISON,
    alternatives: Mapping[str, Mapping[str, ArrayLike]] | None = None,
    repeats: int = 1,
) -> FusionTuning:
    """Choose one fusion weight (and comparison) per modality by class-stratified
    cross-validation.

    Parameters
    ----------
    dissimilarities : modality -> (n, n) array_like of float, all-to-all and symmetric,
        in fusion order (the last keeps weight 1); at least two modalities. Made with
        the preset's comparison, named ``comparison`` in the choices.
    labels : (n,) array_like, the class of each object.
    rule : ``"sum"`` or ``"product"``, the preset's rule.
    preset_weights : modality -> the preset's own weight, scored on the same folds.
    folds : number of folds, at least 2.
    grid : the weights tried for every modality but the last.
    seed : of :func:`stratified_folds` (round ``r`` deals from ``seed + r``).
    comparison : the name of the comparison ``dissimilarities`` were made with, or
        modality -> its name (modalities compared differently, such as the size).
    alternatives : modality -> comparison name -> (n, n), other comparisons of some
        modalities to choose from (the preset's is preferred on equal losses).
    repeats : rounds of the folds, each dealt from its own seed.

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
    named = {m: comparison if isinstance(comparison, str) else comparison[m] for m in mats}
    candidates = {
        m: {
            named[m]: d,
            **{
                c: np.asarray(a, dtype=np.float64)
                for c, a in (alternatives or {}).get(m, {}).items()
            },
        }
        for m, d in mats.items()
    }
    labels = np.asarray(labels)
    if len(mats) < 2:
        raise ValueError(f"fusion weights need at least two modalities, got {list(mats)}")
    n = len(labels)
    shapes = {
        f"{m} {c}": d.shape
        for m, by in candidates.items()
        for c, d in by.items()
        if d.shape != (n, n)
    }
    if shapes:
        raise ValueError(f"{n} labels need ({n}, {n}) dissimilarities, got {shapes}")
    preset_fused = fuse(mats, rule, preset_weights)
    results = []
    held_out_matrix = np.empty((n, n))
    first = _checked_folds(labels, folds, seed)
    for r in range(repeats):
        fold = first if r == 0 else _checked_folds(labels, folds, seed + r)
        for f in range(folds):
            train, held = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
            training = {
                m: {c: d[np.ix_(train, train)] for c, d in by.items()}
                for m, by in candidates.items()
            }
            weights, comparisons, _ = choose_fusion(training, labels[train], rule, grid)
            fused = fuse({m: candidates[m][comparisons[m]] for m in mats}, rule, weights)
            if r == 0:
                held_out_matrix[held] = fused[held]
            results.append(
                FoldResult(
                    held_out_objects=len(held),
                    weights=weights,
                    comparisons=comparisons,
                    held_out=fusion_scores(fused, labels, held),
                    preset=fusion_scores(preset_fused, labels, held),
                )
            )
    weights, comparisons, loss = choose_fusion(candidates, labels, rule, grid)
    chosen = {m: candidates[m][comparisons[m]] for m in mats}
    sensitivity = {
        m: tuple(fusion_scores(fuse(chosen, rule, {**weights, m: w}), labels).loss for w in grid)
        for m in list(mats)[:-1]
    }
    return FusionTuning(
        rule=rule,
        grid=grid,
        weights=weights,
        comparisons=comparisons,
        loss=loss,
        folds=tuple(results),
        held_out=FusionScores.mean([r.held_out for r in results]),
        preset_held_out=FusionScores.mean([r.preset for r in results]),
        sensitivity=sensitivity,
        held_out_matrix=held_out_matrix,
        fold_of=first,
        repeats=repeats,
    )


def learn_fusion(
    vectors: Mapping[str, NDArray[np.float64]],
    labels: ArrayLike,
    preset: Preset,
    sigma: Mapping[str, NDArray[np.float64]] | None = None,
    *,
    seed: int = 0,
    repeats: int = 1,
) -> FusionTuning:
    """Cross-validate every scored modality's comparison and weight on labelled
    objects, in ``FOLDS`` folds or the most that can (:func:`feasible_folds`), in
    ``repeats`` rounds.

    Each fused modality is offered with every comparison it may take
    (:data:`~worker.engine.presets.COMPARISONS`: D1, D2, and ShapeDNA's reweighted
    Euclidean distance for the spectrum), its preset's first (preferred on equal
    losses); the size, with metric units, keeps its own comparison and is weighed first,
    so that the preset's last fused modality keeps weight 1 and the size's is on the grid.

    Parameters
    ----------
    vectors : modality -> (n, M_m) float, of every scored modality.
    labels : (n,) array_like.
    preset : the rule, the comparisons to start from and the weights to beat.
    sigma : modality -> (M_m,), eq. (9)'s sigma_i (a gallery's, of more shapes than
        these); default over ``vectors``.

    Raises
    ------
    ValueError
        A class of fewer than three objects, or too few objects for two folds.
    """
    labels = np.asarray(labels)
    folds = feasible_folds(labels, seed=seed, repeats=repeats)
    metric = SIZE in preset.scored_modalities
    order = (SIZE, *preset.fused_modalities) if metric else preset.fused_modalities

    def scale(m: str) -> NDArray[np.float64]:
        return gallery_sigma(vectors[m]) if sigma is None else sigma[m]

    matrices = {m: preset_all_to_all(m, vectors[m], preset, scale(m)) for m in order}
    alternatives: dict[str, dict[str, NDArray[np.float64]]] = {
        m: {
            kind: all_to_all(vectors[m], kind, scale(m))
            for kind, modalities in COMPARISONS.items()
            if m in modalities and kind != preset.comparison(m)
        }
        for m in preset.fused_modalities
    }
    return tune_fusion(
        matrices,
        labels,
        preset.fusion,
        {m: preset.weight(m) for m in order},
        folds=folds,
        seed=seed,
        comparison={m: preset.comparison(m) for m in order},
        alternatives=alternatives,
        repeats=repeats,
    )
