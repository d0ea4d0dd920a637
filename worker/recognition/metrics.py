"""Evaluation metrics for 3D shape retrieval.

Pure numpy, no I/O. Every metric works on an all-to-all dissimilarity matrix
``dissimilarity : (n, n) float`` (smaller = more similar; the diagonal is never read)
and a vector of class labels ``labels : (n,)`` (strings or ints).

Three families, as used by Smeets et al. (2010) and the SHREC / Princeton Shape
Benchmark (PSB) literature:

* Verification over the unordered pairs ``i < j``: :func:`roc_curve`,
  :func:`equal_error_rate`. Only the upper triangle ``dissimilarity[i, j], i < j``
  is read, so an asymmetric matrix should be symmetrised by the caller.
* Identification with a gallery of one model per class: :func:`first_instance_split`,
  :func:`cmc_curve`, :func:`rank1_rate`. Rows are probes, columns gallery items.
* Leave-one-out retrieval: :func:`nearest_neighbor_rate`, :func:`first_tier`,
  :func:`second_tier`, :func:`e_measure`, :func:`discounted_cumulative_gain`,
  :func:`mean_average_precision`, and :func:`retrieval_scores` for all of them at
  once. Row ``i`` is the query, so each query ranks ``dissimilarity[i, j], j != i``.
* Queries against a separate gallery: :func:`query_mean_average_precision`.

Tie conventions (deliberately different per family, each the standard one):

* ROC: every pair with the same dissimilarity is accepted at the same threshold.
* CMC: pessimistic; a wrong gallery item tied with the correct one ranks before it.
* Retrieval: ties are broken by object index (stable sort), i.e. the lower index is
  retrieved first.

Input validation (square matrix, finite off-diagonal values, label count, at least
two classes) happens once, at each public function, and raises ``ValueError``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "LabelledSet",
    "cmc_curve",
    "discounted_cumulative_gain",
    "e_measure",
    "equal_error_rate",
    "first_instance_split",
    "first_tier",
    "mean_average_precision",
    "query_mean_average_precision",
    "natural_sort_key",
    "nearest_neighbor_rate",
    "pair_equal_error_rate",
    "pair_roc",
    "rank1_rate",
    "retrieval_scores",
    "roc_curve",
    "second_tier",
]

#: Number of retrieved objects used by the PSB E-measure.
E_MEASURE_CUTOFF = 32


# --------------------------------------------------------------------------- validation


def _validate(
    dissimilarity: ArrayLike, labels: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Check the common inputs and convert labels to integer class codes.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities. The diagonal is ignored (may hold anything).
    labels : (n,) array_like
        Class label of each object (strings or ints).

    Returns
    -------
    d : (n, n) ndarray of float64
        The dissimilarity matrix as a float array.
    codes : (n,) ndarray of int
        Class index of each object, ``0 .. n_classes - 1``.

    Raises
    ------
    ValueError
        If the matrix is not square, has non-finite off-diagonal entries, the label
        count does not match, or fewer than two classes are present.
    """
    d = _square(dissimilarity)
    n = d.shape[0]
    lab = np.asarray(labels)
    if lab.ndim != 1:
        raise ValueError(f"labels must be a 1-D array, got shape {lab.shape}")
    if lab.shape[0] != n:
        raise ValueError(
            f"labels has {lab.shape[0]} entries but dissimilarity is {n} x {n}; they must match"
        )
    _check_finite(d, ~np.eye(n, dtype=bool))
    classes, codes = np.unique(lab, return_inverse=True)
    if classes.size < 2:
        raise ValueError(f"at least two classes are required, got {classes.size}")
    return d, codes.reshape(-1)


def _square(dissimilarity: ArrayLike) -> NDArray[np.float64]:
    d = np.asarray(dissimilarity, dtype=np.float64)
    if d.ndim != 2 or d.shape[0] != d.shape[1]:
        raise ValueError(f"dissimilarity must be a square (n, n) matrix, got shape {d.shape}")
    return d


def _check_finite(d: NDArray[np.float64], off_diagonal: NDArray[np.bool_]) -> None:
    if not np.all(np.isfinite(d[off_diagonal])):
        raise ValueError("dissimilarity has NaN or infinite off-diagonal entries")


def _check_no_singleton(codes: NDArray[np.int64], labels: ArrayLike) -> None:
    """Retrieval needs every class to hold two objects (one to query, one to find)."""
    class_sizes = np.bincount(codes)
    if np.any(class_sizes < 2):
        singletons = np.unique(np.asarray(labels)[class_sizes[codes] < 2])
        raise ValueError(
            "retrieval metrics need every class to have at least two objects; "
            f"singleton classes: {singletons.tolist()}"
        )


# --------------------------------------------------------------------------- verification


def roc_curve(
    dissimilarity: ArrayLike, labels: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Verification ROC over all unordered pairs ``i < j``.

    A pair is *genuine* when both objects share a label and an *impostor* pair
    otherwise. At threshold ``t`` a pair is accepted when its dissimilarity is
    ``<= t``; all pairs with equal dissimilarity are therefore accepted together.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; only the upper triangle (``i < j``) is read.
    labels : (n,) array_like
        Class label of each object.

    Returns
    -------
    far : (m + 1,) ndarray of float
        False acceptance rate, accepted impostors / impostors. Non-decreasing.
    frr : (m + 1,) ndarray of float
        False rejection rate, rejected genuines / genuines. Non-increasing.
    thresholds : (m + 1,) ndarray of float
        ``-inf`` (accept nothing: FAR = 0, FRR = 1) followed by the ``m`` distinct
        pair dissimilarities in increasing order. The last threshold accepts every
        pair, so the curve always ends at FAR = 1, FRR = 0.

    Raises
    ------
    ValueError
        On invalid inputs, or when no class has two objects (no genuine pairs).
    """
    d, codes = _validate(dissimilarity, labels)
    iu, ju = np.triu_indices(d.shape[0], k=1)
    values = d[iu, ju]
    genuine_mask = codes[iu] == codes[ju]
    if not genuine_mask.any():
        raise ValueError("no genuine pairs: every class has a single object")
    return pair_roc(values[genuine_mask], values[~genuine_mask])


def pair_roc(
    genuine: ArrayLike, impostor: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Verification ROC from the dissimilarities of genuine and impostor pairs.

    The curve of :func:`roc_curve` for any set of pairs (e.g. only the pairs that
    involve a held-out object, or the scores a service has collected).

    Parameters
    ----------
    genuine : (g,) array_like of float, g >= 1
    impostor : (i,) array_like of float, i >= 1

    Returns
    -------
    far, frr, thresholds : as :func:`roc_curve`.
    """
    genuine = np.sort(np.asarray(genuine, dtype=np.float64).ravel())
    impostor = np.sort(np.asarray(impostor, dtype=np.float64).ravel())
    if genuine.size == 0 or impostor.size == 0:
        raise ValueError("a ROC needs at least one genuine and one impostor pair")
    thresholds = np.unique(np.concatenate([genuine, impostor]))
    # side="right" counts values <= t, so tied pairs are accepted together.
    accepted_impostors = np.searchsorted(impostor, thresholds, side="right")
    accepted_genuines = np.searchsorted(genuine, thresholds, side="right")
    far = np.concatenate(([0.0], accepted_impostors / impostor.size))
    frr = np.concatenate(([1.0], 1.0 - accepted_genuines / genuine.size))
    return far, frr, np.concatenate(([-np.inf], thresholds))


def equal_error_rate(dissimilarity: ArrayLike, labels: ArrayLike) -> float:
    """Equal error rate: the error where FAR = FRR on the ROC of :func:`roc_curve`.

    The ROC points are joined by straight line segments in the (FAR, FRR) plane and
    the EER is where that polyline crosses the diagonal FAR = FRR. If a ROC point
    lies exactly on the diagonal, its FAR is returned; otherwise the crossing is
    linearly interpolated between the last point with FRR > FAR and the first point
    with FRR < FAR. (Since FAR rises from 0 to 1 and FRR falls from 1 to 0, the
    crossing always exists and is unique.)

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; only the upper triangle is read.
    labels : (n,) array_like
        Class label of each object.

    Returns
    -------
    float
        EER in ``[0, 1]``; 0 for perfect separation.
    """
    far, frr, _ = roc_curve(dissimilarity, labels)
    return _crossing(far, frr)


def pair_equal_error_rate(genuine: ArrayLike, impostor: ArrayLike) -> float:
    """The EER of :func:`pair_roc` (the same crossing as :func:`equal_error_rate`)."""
    far, frr, _ = pair_roc(genuine, impostor)
    return _crossing(far, frr)


def _crossing(far: NDArray[np.float64], frr: NDArray[np.float64]) -> float:
    gap = frr - far  # goes from +1 (first point) to -1 (last point), non-increasing
    k = int(np.argmax(gap <= 0.0))  # first point at or past the crossing
    if gap[k] == 0.0:
        return float(far[k])
    # Segment (k-1) -> k: solve gap[k-1] + alpha * (gap[k] - gap[k-1]) = 0.
    alpha = gap[k - 1] / (gap[k - 1] - gap[k])
    return float(far[k - 1] + alpha * (far[k] - far[k - 1]))


# --------------------------------------------------------------------------- identification


def natural_sort_key(name: str) -> tuple[tuple[str | int, ...], str]:
    """Sort key ordering file names naturally (``"cat2" < "cat10"``).

    Runs of ASCII digits compare as integers, other text case-insensitively; the
    original string breaks remaining ties (e.g. ``"cat02"`` vs ``"cat2"``).

    Parameters
    ----------
    name : str
        File name or path.

    Returns
    -------
    tuple
        Key for :func:`sorted`.
    """
    parts = re.split(r"([0-9]+)", name)
    # re.split with a capture group alternates text (even) and digits (odd), so keys
    # of two names always compare str with str and int with int.
    return tuple(int(p) if i % 2 else p.casefold() for i, p in enumerate(parts)), name


def first_instance_split(
    names: Sequence[str], labels: ArrayLike
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Split objects into a one-per-class gallery and probes.

    The gallery holds, for each class, the object whose name comes first in natural
    order (see :func:`natural_sort_key`); every other object is a probe.

    Parameters
    ----------
    names : (n,) sequence of str
        File name of each object.
    labels : (n,) array_like
        Class label of each object.

    Returns
    -------
    gallery_idx : (n_classes,) ndarray of int
        Indices of the gallery objects, in increasing index order.
    probe_idx : (n - n_classes,) ndarray of int
        Indices of all other objects, in increasing index order (may be empty).

    Raises
    ------
    ValueError
        If ``names`` and ``labels`` differ in length or are empty.
    """
    names = [str(name) for name in names]
    lab = np.asarray(labels)
    if lab.ndim != 1 or lab.shape[0] != len(names):
        raise ValueError(
            f"names has {len(names)} entries but labels has shape {lab.shape}; they must match"
        )
    if not names:
        raise ValueError("names and labels are empty")
    order = sorted(range(len(names)), key=lambda i: natural_sort_key(names[i]))
    _, codes = np.unique(lab, return_inverse=True)
    codes = codes.reshape(-1)
    is_gallery = np.zeros(len(names), dtype=bool)
    seen: set[int] = set()
    for i in order:
        code = int(codes[i])
        if code not in seen:  # first object of this class in natural name order
            seen.add(code)
            is_gallery[i] = True
    return np.flatnonzero(is_gallery), np.flatnonzero(~is_gallery)


def _validate_split(
    n: int, gallery_idx: ArrayLike, probe_idx: ArrayLike
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Check gallery / probe index arrays: 1-D ints in range, unique, disjoint, non-empty."""
    result = []
    for name, idx in (("gallery_idx", gallery_idx), ("probe_idx", probe_idx)):
        arr = np.asarray(idx)
        if arr.ndim != 1 or arr.size == 0:
            raise ValueError(f"{name} must be a non-empty 1-D index array, got shape {arr.shape}")
        if not np.issubdtype(arr.dtype, np.integer):
            raise ValueError(f"{name} must hold integers, got dtype {arr.dtype}")
        if arr.min() < 0 or arr.max() >= n:
            raise ValueError(f"{name} has indices outside [0, {n})")
        if np.unique(arr).size != arr.size:
            raise ValueError(f"{name} has repeated indices")
        result.append(arr.astype(np.intp))
    gallery, probes = result
    if np.intersect1d(gallery, probes).size:
        raise ValueError("gallery_idx and probe_idx overlap")
    return gallery, probes


def cmc_curve(
    dissimilarity: ArrayLike,
    labels: ArrayLike,
    gallery_idx: ArrayLike,
    probe_idx: ArrayLike,
) -> NDArray[np.float64]:
    """Cumulative match characteristic of closed-set identification.

    Each probe ranks the gallery by ``dissimilarity[probe, gallery]``. Its rank is
    the position of the best-matching gallery item of its own class. Ties are
    counted pessimistically: ``rank = 1 + #{wrong-class gallery items with
    dissimilarity <= that of the best correct item}``, so a wrong item tied with the
    correct one is ranked before it.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; rows are read as probes, columns as gallery.
    labels : (n,) array_like
        Class label of each object.
    gallery_idx : (g,) array_like of int
        Indices of the gallery objects.
    probe_idx : (p,) array_like of int
        Indices of the probe objects, disjoint from ``gallery_idx``.

    Returns
    -------
    cmc : (g,) ndarray of float
        ``cmc[r - 1]`` = fraction of probes whose rank is ``<= r``. Non-decreasing,
        and ``cmc[-1] == 1``.

    Raises
    ------
    ValueError
        On invalid inputs, or if a probe's class has no gallery item.
    """
    d, codes = _validate(dissimilarity, labels)
    gallery, probes = _validate_split(d.shape[0], gallery_idx, probe_idx)
    scores = d[np.ix_(probes, gallery)]  # (p, g)
    correct = codes[probes][:, None] == codes[gallery][None, :]  # (p, g)
    missing = ~correct.any(axis=1)
    if missing.any():
        raise ValueError(f"probes {probes[missing].tolist()} have a class with no gallery item")
    best_correct = np.where(correct, scores, np.inf).min(axis=1)  # (p,)
    ranks = 1 + np.sum(~correct & (scores <= best_correct[:, None]), axis=1)  # (p,)
    return np.array([np.mean(ranks <= r) for r in range(1, gallery.size + 1)])


def rank1_rate(
    dissimilarity: ArrayLike,
    labels: ArrayLike,
    gallery_idx: ArrayLike,
    probe_idx: ArrayLike,
) -> float:
    """Rank-1 identification rate, ``cmc_curve(...)[0]``.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities.
    labels : (n,) array_like
        Class label of each object.
    gallery_idx : (g,) array_like of int
        Indices of the gallery objects.
    probe_idx : (p,) array_like of int
        Indices of the probe objects.

    Returns
    -------
    float
        Fraction of probes whose best gallery match (pessimistic ties) is correct.
    """
    return float(cmc_curve(dissimilarity, labels, gallery_idx, probe_idx)[0])


# --------------------------------------------------------------------------- retrieval


def _ranked_relevance(dissimilarity: ArrayLike, labels: ArrayLike) -> NDArray[np.bool_]:
    """Leave-one-out ranking of every query, as a relevance matrix.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; row ``i`` is query ``i``.
    labels : (n,) array_like
        Class label of each object.

    Returns
    -------
    relevant : (n, n - 1) ndarray of bool
        ``relevant[i, k]`` is True when the ``(k + 1)``-th object retrieved for query
        ``i`` (query excluded, ties broken by lower index first) shares its label.

    Raises
    ------
    ValueError
        On invalid inputs, or if some class has a single object (no relevant items).
    """
    retrieved, codes = _retrieved(dissimilarity, labels)
    relevant: NDArray[np.bool_] = codes[retrieved] == codes[:, None]
    return relevant


def _retrieved(
    dissimilarity: ArrayLike, labels: ArrayLike
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(n, n - 1) the objects each query retrieves, in order (query excluded, ties
    broken by lower index first), and (n,) the label codes; raises as
    :func:`_ranked_relevance`."""
    d, codes = _validate(dissimilarity, labels)
    n = d.shape[0]
    _check_no_singleton(codes, labels)
    rows = np.arange(n)[:, None]
    cols = np.arange(n - 1)[None, :]
    others = cols + (cols >= rows)  # (n, n-1): row i lists j != i in increasing order
    order = np.argsort(d[rows, others], axis=1, kind="stable")  # stable: index breaks ties
    retrieved: NDArray[np.int64] = np.take_along_axis(others, order, axis=1)
    return retrieved, codes


def nearest_neighbor_misses(
    dissimilarity: ArrayLike, labels: ArrayLike
) -> dict[str, dict[str, int]]:
    """Where the nearest-neighbour rate's misses go: for each class, how many of its
    queries retrieve first an object of each other class (ties by lower index, as for
    :func:`nearest_neighbor_rate`; classes without a miss left out).

    Parameters and errors as :func:`nearest_neighbor_rate`.

    Returns
    -------
    {query's label: {first retrieved object's label: count}}, labels as ``str``.
    """
    retrieved, codes = _retrieved(dissimilarity, labels)
    names = np.asarray(labels).astype(str)
    first = retrieved[:, 0]
    misses: dict[str, dict[str, int]] = {}
    for i in np.flatnonzero(codes[first] != codes):
        asked, answered = names[i], names[first[i]]
        misses.setdefault(asked, {})
        misses[asked][answered] = misses[asked].get(answered, 0) + 1
    return misses


def _nearest_neighbor(relevant: NDArray[np.bool_]) -> float:
    return float(np.mean(relevant[:, 0]))


def _tier(relevant: NDArray[np.bool_], multiple: int) -> float:
    n_relevant = relevant.sum(axis=1)  # (n,) = C - 1
    cutoff = np.minimum(multiple * n_relevant, relevant.shape[1])
    hits = np.cumsum(relevant, axis=1)[np.arange(relevant.shape[0]), cutoff - 1]
    return float(np.mean(hits / n_relevant))


def _e_measure(relevant: NDArray[np.bool_], cutoff: int) -> float:
    k = min(cutoff, relevant.shape[1])
    hits = relevant[:, :k].sum(axis=1)
    precision = hits / k
    recall = hits / relevant.sum(axis=1)
    # 2 / (1/P + 1/R) == 2PR / (P + R); defined as 0 when there is no hit.
    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.where(hits > 0, 2.0 * precision * recall / (precision + recall), 0.0)
    return float(np.mean(e))


def _dcg(relevant: NDArray[np.bool_]) -> float:
    positions = np.arange(1, relevant.shape[1] + 1)
    discount = np.ones(positions.size)
    discount[1:] = 1.0 / np.log2(positions[1:])  # DCG_1 = G_1, then G_i / log2(i)
    dcg = relevant @ discount
    ideal = np.cumsum(discount)[relevant.sum(axis=1) - 1]  # all C-1 relevant first
    return float(np.mean(dcg / ideal))


def _mean_average_precision(relevant: NDArray[np.bool_]) -> float:
    positions = np.arange(1, relevant.shape[1] + 1)
    precision_at = np.cumsum(relevant, axis=1) / positions
    ap = np.sum(precision_at * relevant, axis=1) / relevant.sum(axis=1)
    return float(np.mean(ap))


def query_mean_average_precision(
    dissimilarity: ArrayLike, query_labels: ArrayLike, gallery_labels: ArrayLike
) -> float:
    """mAP of queries against a separate gallery: each query ranks the whole gallery,
    the gallery objects of its class relevant (every query needs one).

    Parameters
    ----------
    dissimilarity : (q, n) float.
    query_labels : (q,); gallery_labels : (n,).
    """
    d = np.asarray(dissimilarity, dtype=np.float64)
    order = np.argsort(d, axis=1, kind="stable")
    gallery = np.asarray(gallery_labels)
    relevant = gallery[order] == np.asarray(query_labels)[:, None]
    if not relevant.any(axis=1).all():
        raise ValueError("a query has no object of its class in the gallery")
    return _mean_average_precision(relevant)


def nearest_neighbor_rate(dissimilarity: ArrayLike, labels: ArrayLike) -> float:
    """Nearest-neighbour rate: fraction of queries whose closest other object is relevant.

    Ties are broken by lower index, as for every retrieval metric.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; row ``i`` ranks the other objects for query ``i``.
    labels : (n,) array_like
        Class label of each object; every class needs at least two objects.

    Returns
    -------
    float
        Score in ``[0, 1]``, averaged over all ``n`` queries (higher is better).

    Raises
    ------
    ValueError
        On invalid inputs or a singleton class.
    """
    return _nearest_neighbor(_ranked_relevance(dissimilarity, labels))


def first_tier(dissimilarity: ArrayLike, labels: ArrayLike) -> float:
    """First tier: recall within the top ``C - 1`` retrieved objects.

    ``C`` is the size of the query's class, so ``C - 1`` other objects are relevant.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; row ``i`` ranks the other objects for query ``i``.
    labels : (n,) array_like
        Class label of each object; every class needs at least two objects.

    Returns
    -------
    float
        Score in ``[0, 1]``, averaged over all ``n`` queries (higher is better).

    Raises
    ------
    ValueError
        On invalid inputs or a singleton class.
    """
    return _tier(_ranked_relevance(dissimilarity, labels), 1)


def second_tier(dissimilarity: ArrayLike, labels: ArrayLike) -> float:
    """Second tier: recall within the top ``2 (C - 1)`` retrieved objects.

    The cut-off is capped at ``n - 1``; recall is still relative to ``C - 1``.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; row ``i`` ranks the other objects for query ``i``.
    labels : (n,) array_like
        Class label of each object; every class needs at least two objects.

    Returns
    -------
    float
        Score in ``[0, 1]``, averaged over all ``n`` queries (higher is better).

    Raises
    ------
    ValueError
        On invalid inputs or a singleton class.
    """
    return _tier(_ranked_relevance(dissimilarity, labels), 2)


def e_measure(
    dissimilarity: ArrayLike, labels: ArrayLike, *, cutoff: int = E_MEASURE_CUTOFF
) -> float:
    """E-measure of the Princeton Shape Benchmark.

    With the top ``k = min(cutoff, n - 1)`` retrieved objects, precision
    ``P = hits / k`` and recall ``R = hits / (C - 1)`` give ``E = 2 / (1/P + 1/R)``;
    ``E = 0`` when there is no hit. Note that ``E < 1`` even for a perfect ranking
    unless ``k == C - 1``.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; row ``i`` ranks the other objects for query ``i``.
    labels : (n,) array_like
        Class label of each object; every class needs at least two objects.
    cutoff : int, default 32
        Number of top-ranked objects considered (32 in the PSB); must be >= 1.

    Returns
    -------
    float
        Score in ``[0, 1]``, averaged over all ``n`` queries (higher is better).

    Raises
    ------
    ValueError
        On invalid inputs or a singleton class.
    """
    if cutoff < 1:
        raise ValueError(f"cutoff must be a positive integer, got {cutoff}")
    return _e_measure(_ranked_relevance(dissimilarity, labels), cutoff)


def discounted_cumulative_gain(dissimilarity: ArrayLike, labels: ArrayLike) -> float:
    """Normalised discounted cumulative gain over the full ranked list (PSB form).

    ``G_i = 1`` if the ``i``-th retrieved object is relevant else 0, ``DCG_1 = G_1``,
    ``DCG_i = DCG_{i-1} + G_i / log2(i)``, divided by the ideal DCG with all
    ``C - 1`` relevant objects first. (Ranks 1 and 2 carry the same weight.)

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; row ``i`` ranks the other objects for query ``i``.
    labels : (n,) array_like
        Class label of each object; every class needs at least two objects.

    Returns
    -------
    float
        Score in ``[0, 1]``, averaged over all ``n`` queries (higher is better).

    Raises
    ------
    ValueError
        On invalid inputs or a singleton class.
    """
    return _dcg(_ranked_relevance(dissimilarity, labels))


def mean_average_precision(dissimilarity: ArrayLike, labels: ArrayLike) -> float:
    """Mean average precision over leave-one-out queries.

    Per query, the mean of ``precision@r`` over the ranks ``r`` of its ``C - 1``
    relevant objects (the full list is ranked, so all are retrieved).

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; row ``i`` ranks the other objects for query ``i``.
    labels : (n,) array_like
        Class label of each object; every class needs at least two objects.

    Returns
    -------
    float
        Score in ``[0, 1]``, averaged over all ``n`` queries (higher is better).

    Raises
    ------
    ValueError
        On invalid inputs or a singleton class.
    """
    return _mean_average_precision(_ranked_relevance(dissimilarity, labels))


def retrieval_scores(
    dissimilarity: ArrayLike, labels: ArrayLike, queries: ArrayLike | None = None
) -> dict[str, float]:
    """All leave-one-out retrieval scores from a single ranking.

    Parameters
    ----------
    dissimilarity : (n, n) array_like of float
        All-to-all dissimilarities; row ``i`` ranks the other objects for query ``i``.
    labels : (n,) array_like
        Class label of each object; every class needs at least two objects.
    queries : (q,) array_like of int, optional
        Average over these queries only (each still ranks all other objects), e.g.
        the held-out fold of a cross-validation. Default: every object.

    Returns
    -------
    dict of str to float
        Keys ``nn`` (:func:`nearest_neighbor_rate`), ``first_tier``, ``second_tier``,
        ``e_measure`` (cutoff 32), ``dcg`` (:func:`discounted_cumulative_gain`) and
        ``map`` (:func:`mean_average_precision`).

    Raises
    ------
    ValueError
        On invalid inputs or a singleton class.
    """
    relevant = _ranked_relevance(dissimilarity, labels)
    if queries is not None:
        relevant = relevant[np.asarray(queries, dtype=np.int64)]
    return {
        "nn": _nearest_neighbor(relevant),
        "first_tier": _tier(relevant, 1),
        "second_tier": _tier(relevant, 2),
        "e_measure": _e_measure(relevant, E_MEASURE_CUTOFF),
        "dcg": _dcg(relevant),
        "map": _mean_average_precision(relevant),
    }


class LabelledSet:
    """The EER, NN and mAP of many all-to-all dissimilarities of one labelled set, as
    :func:`equal_error_rate` and :func:`retrieval_scores` give them, bit for bit (tested),
    with what only the labels decide worked out once: a fusion's weights are chosen by
    scoring hundreds of matrices of the same objects (:mod:`worker.recognition.fusion`).

    Each matrix's pairs are ranked by one sort, the ROC read at the end of each run of
    equal values (what :func:`pair_roc`'s thresholds count); each query's row by one
    stable sort with its own entry first (``-inf``), the others in the order of
    :func:`_ranked_relevance`: by dissimilarity, ties by index.

    Parameters
    ----------
    labels : (n,) array_like, every class with at least two objects, at least two classes.
    """

    def __init__(self, labels: ArrayLike) -> None:
        labels = np.asarray(labels)
        # A matrix of zeros validates the labels as every function does.
        _, self._codes = _validate(np.zeros((len(labels), len(labels))), labels)
        _check_no_singleton(self._codes, labels)
        self._pairs = np.triu_indices(len(labels), k=1)
        self._genuine = self._codes[self._pairs[0]] == self._codes[self._pairs[1]]
        self._genuines = int(self._genuine.sum())
        self._impostors = len(self._genuine) - self._genuines
        self._off_diagonal = ~np.eye(len(labels), dtype=bool)

    def figures(self, dissimilarity: ArrayLike) -> tuple[float, float, float]:
        """``dissimilarity`` (n, n)'s :func:`equal_error_rate` and :func:`retrieval_scores`'
        ``nn`` and ``map`` with these labels."""
        d = _square(dissimilarity)
        n = len(self._codes)
        if d.shape[0] != n:
            raise ValueError(f"{n} labels need an ({n}, {n}) dissimilarity, got {d.shape}")
        _check_finite(d, self._off_diagonal)
        values = d[self._pairs]
        order = np.argsort(values)
        ranked = values[order]
        accepted_genuines = np.cumsum(self._genuine[order])
        accepted_impostors = np.arange(1, len(values) + 1) - accepted_genuines
        # The last pair of each run of equal values: every pair <= it is accepted.
        ends = np.append(np.flatnonzero(ranked[1:] != ranked[:-1]), len(values) - 1)
        far = np.concatenate(([0.0], accepted_impostors[ends] / self._impostors))
        frr = np.concatenate(([1.0], 1.0 - accepted_genuines[ends] / self._genuines))
        rows = d.copy()
        np.fill_diagonal(rows, -np.inf)  # each query's own entry first, then the others
        retrieved = np.argsort(rows, axis=1, kind="stable")[:, 1:]
        relevant: NDArray[np.bool_] = self._codes[retrieved] == self._codes[:, None]
        return _crossing(far, frr), _nearest_neighbor(relevant), _mean_average_precision(relevant)
