"""Dissimilarities between modal descriptors (eqs. 8, 9) and their fusion.

Descriptors are compared as flat vectors of ``M`` elements. All functions take
stacks of descriptors and return matrices, so one call compares a set of queries
against a whole gallery. The preset's score of whole queries is
:func:`fused_dissimilarity`: its fused modalities, and in a collection of metric units
the size (:data:`~worker.engine.presets.SIZE`, compared by eq. 8).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from .presets import REWEIGHTED, SIZE, Comparison, Preset

_TINY = np.finfo(float).tiny
#: Gallery rows :func:`mean_normalized_manhattan` compares with a query at once.
D1_BLOCK = 512


def mean_normalized_manhattan(queries: np.ndarray, gallery: np.ndarray) -> np.ndarray:
    """D1, eq. (8): mean over elements of ``2 |s_k - s_l| / (s_k + s_l)``.

    Parameters
    ----------
    queries : (p, M) float, non-negative.
    gallery : (q, M) float, non-negative (any float type: each block is read in double
        precision).

    Returns
    -------
    (p, q) float in [0, 2]. Elements that are zero in both descriptors add 0.
    """
    q = np.atleast_2d(np.asarray(queries, dtype=np.float64))
    g = np.atleast_2d(np.asarray(gallery))
    out = np.empty((len(q), len(g)))
    # One query and D1_BLOCK gallery rows at a time, in three buffers that stay in the
    # processor's cache: a search scores thousands of candidates, and temporaries the size
    # of the gallery would be written to memory and read back by each operation.
    rows = max(1, min(D1_BLOCK, len(g)))
    num, den, ratio = (np.empty((rows, g.shape[1])) for _ in range(3))
    for i, row in enumerate(q):
        for start in range(0, len(g), rows):
            block = g[start : start + rows]
            n, d, r = num[: len(block)], den[: len(block)], ratio[: len(block)]
            np.subtract(row, block, out=n)
            np.abs(n, out=n)
            n *= 2.0
            np.add(row, block, out=d)
            r.fill(0.0)
            np.divide(n, d, out=r, where=d > _TINY)
            out[i, start : start + len(block)] = r.mean(axis=1)
    return out


def gallery_sigma(gallery: np.ndarray) -> np.ndarray:
    """Per-element standard deviation over the gallery, the sigma_i of eq. (9).

    Elements that do not vary over the gallery get sigma = 1 (they add nothing
    to D2 between gallery members, and stay comparable for queries).

    Parameters
    ----------
    gallery : (q, M) float

    Returns
    -------
    (M,) float, positive.
    """
    sigma = np.std(np.asarray(gallery, dtype=np.float64), axis=0)
    return np.where(sigma > 0, sigma, 1.0)


def normalized_euclidean(queries: np.ndarray, gallery: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """D2, eq. (9): ``sqrt(sum_i (s_k,i - s_l,i)^2 / sigma_i^2)``.

    Parameters
    ----------
    queries : (p, M) float
    gallery : (q, M) float
    sigma : (M,) float, from :func:`gallery_sigma`.

    Returns
    -------
    (p, q) float
    """
    q = np.atleast_2d(np.asarray(queries, dtype=np.float64)) / sigma
    g = np.atleast_2d(np.asarray(gallery, dtype=np.float64)) / sigma
    sq = (q**2).sum(1)[:, None] + (g**2).sum(1)[None, :] - 2.0 * q @ g.T
    distances: np.ndarray = np.sqrt(np.maximum(sq, 0.0))
    return distances


def spectrum_weights(length: int) -> np.ndarray:
    """ShapeDNA's reweighting of a spectrum without its zero eigenvalue: entry ``j``
    (0-based) is eigenvalue ``j + 2`` in lapy's numbering (the zero one is 1), and
    ``reweight_ev`` divides eigenvalue ``i`` by ``i``, so the divisors are ``2 .. length + 1``."""
    return np.arange(2, length + 2, dtype=np.float64)


def reweighted_euclidean(queries: np.ndarray, gallery: np.ndarray) -> np.ndarray:
    """ShapeDNA's comparison of spectra (Reuter et al. 2006; lapy's ``reweight_ev``
    then ``compute_distance(..., "euc")``): the Euclidean distance of the eigenvalues
    each divided by its index (:func:`spectrum_weights`), so that the high eigenvalues,
    which grow linearly (Weyl's law), do not outweigh the low ones.

    Parameters
    ----------
    queries : (p, M) float, spectra without the zero eigenvalue.
    gallery : (q, M) float

    Returns
    -------
    (p, q) float
    """
    q = np.atleast_2d(np.asarray(queries, dtype=np.float64))
    g = np.atleast_2d(np.asarray(gallery, dtype=np.float64))
    w = spectrum_weights(q.shape[1])
    return normalized_euclidean(q, g, w)


def dissimilarity(
    queries: np.ndarray,
    gallery: np.ndarray,
    kind: Comparison | str,
    sigma: np.ndarray | None = None,
) -> np.ndarray:
    """One modality's dissimilarity between every query and every gallery descriptor.

    The one place that chooses between eq. (8), eq. (9) and ShapeDNA's comparison: the
    index, the evaluation and the benchmarks all rank with it.

    Parameters
    ----------
    queries : (p, M) float
    gallery : (q, M) float
    kind : ``"D1"`` (eq. 8, :func:`mean_normalized_manhattan`), ``"D2"``
        (eq. 9, :func:`normalized_euclidean`) or ``"reweighted euclidean"``
        (:func:`reweighted_euclidean`, spectra).
    sigma : (M,) float, D2 only: the sigma_i of eq. (9). Default
        ``gallery_sigma(gallery)``; pass it when the gallery rows given are not the
        whole gallery (a subset, or one kept elsewhere with running sums).

    Returns
    -------
    (p, q) float
    """
    if kind == "D1":
        return mean_normalized_manhattan(queries, gallery)
    if kind == "D2":
        return normalized_euclidean(
            queries, gallery, gallery_sigma(gallery) if sigma is None else sigma
        )
    if kind == REWEIGHTED:
        return reweighted_euclidean(queries, gallery)
    raise ValueError(f"unknown dissimilarity {kind!r}; use 'D1', 'D2' or {REWEIGHTED!r}")


def paired_dissimilarity(
    first: np.ndarray,
    second: np.ndarray,
    kind: Comparison | str,
    sigma: np.ndarray | None = None,
) -> np.ndarray:
    """The dissimilarity of each row of ``first`` to the same row of ``second``.

    The diagonal of :func:`dissimilarity` without the rest of the matrix: what a
    calibration needs for a sample of pairs out of a large gallery.

    Parameters
    ----------
    first, second : (p, M) float
    kind : ``"D1"``, ``"D2"`` or ``"reweighted euclidean"``.
    sigma : (M,) float, D2's sigma_i (required for D2).

    Returns
    -------
    (p,) float
    """
    a = np.atleast_2d(np.asarray(first, dtype=np.float64))
    b = np.atleast_2d(np.asarray(second, dtype=np.float64))
    if kind == "D1":
        num = 2.0 * np.abs(a - b)
        den = a + b
        terms = np.where(den > _TINY, num / np.maximum(den, _TINY), 0.0)
        return np.asarray(terms.mean(axis=1))
    if kind == "D2":
        if sigma is None:
            raise ValueError("D2 between pairs needs the gallery's sigma")
        return np.asarray(np.sqrt((((a - b) / sigma) ** 2).sum(axis=1)))
    if kind == REWEIGHTED:
        w = spectrum_weights(a.shape[1])
        return np.asarray(np.sqrt((((a - b) / w) ** 2).sum(axis=1)))
    raise ValueError(f"unknown dissimilarity {kind!r}; use 'D1', 'D2' or {REWEIGHTED!r}")


def size_dissimilarity(
    queries: np.ndarray, gallery: np.ndarray, tolerance: float = 0.0
) -> np.ndarray:
    """The size modality's comparison: eq. (8), D1, of the sizes ``[sqrt(A)]``, at least
    ``tolerance``.

    For one element D1 is ``2 |s_k - s_l| / (s_k + s_l) = 2 tanh(|log(s_k / s_l)| / 2)``: a
    function of the sizes' ratio alone (no unit: a collection in millimetres compares as
    in metres), zero for equal sizes, symmetric, and about the relative difference of the
    two. Below ``tolerance`` it is raised to it: sizes closer than that are told apart by
    the shape alone (pose and scanning move one body's size by a few percent), and a
    product rule never multiplies the shape's score by 0. Eq. (8) on the size and the
    tolerance were chosen over eq. (9), the log-ratio and other tolerances by
    cross-validation (docs/decisions.md, "Metric units fuse the size").

    Parameters
    ----------
    queries : (p, 1) float, positive sizes.
    gallery : (q, 1) float, positive sizes.
    tolerance : the floor (the preset's ``size_tolerance``); 0: eq. (8) itself.

    Returns
    -------
    (p, q) float in [tolerance, 2].
    """
    d: np.ndarray = np.maximum(mean_normalized_manhattan(queries, gallery), tolerance)
    return d


def paired_size_dissimilarity(
    first: np.ndarray, second: np.ndarray, tolerance: float = 0.0
) -> np.ndarray:
    """:func:`size_dissimilarity` of each row of ``first`` to the same row of ``second``
    ((p, 1) each): (p,) float."""
    d: np.ndarray = np.maximum(paired_dissimilarity(first, second, "D1"), tolerance)
    return d


def preset_dissimilarity(
    modality: str,
    queries: np.ndarray,
    gallery: np.ndarray,
    preset: Preset,
    sigma: np.ndarray | None = None,
) -> np.ndarray:
    """One modality's dissimilarity under a preset: the size's
    (:func:`size_dissimilarity` at the preset's ``size_tolerance``), or the modality's
    comparison (:meth:`Preset.comparison`: eq. 8, eq. 9 with ``sigma``, or ShapeDNA's;
    :func:`dissimilarity`).

    Returns
    -------
    (p, q) float
    """
    if modality == SIZE:
        return size_dissimilarity(queries, gallery, preset.size_tolerance)
    return dissimilarity(queries, gallery, preset.comparison(modality), sigma)


def paired_preset_dissimilarity(
    modality: str,
    first: np.ndarray,
    second: np.ndarray,
    preset: Preset,
    sigma: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`preset_dissimilarity` of each row of ``first`` to the same row of
    ``second`` (:func:`paired_dissimilarity`; D2 needs ``sigma``): (p,) float."""
    if modality == SIZE:
        return paired_size_dissimilarity(first, second, preset.size_tolerance)
    return paired_dissimilarity(first, second, preset.comparison(modality), sigma)


#: The fusion rules, ``sum_m w_m D_m`` and ``prod_m D_m ** w_m``.
RULES = ("sum", "product")


def _checked_rule(rule: str) -> str:
    if rule not in RULES:
        raise ValueError(f"unknown fusion rule {rule!r}; use 'sum' or 'product'")
    return rule


def fusion_term(d: np.ndarray, rule: str, weight: float = 1.0) -> np.ndarray:
    """One modality's term of the ``"sum"`` rule, ``w D``, or of the ``"product"`` rule,
    ``D ** w``."""
    return weight * d if _checked_rule(rule) == "sum" else np.power(d, weight)


def combine_terms(terms: Iterable[np.ndarray], rule: str) -> np.ndarray:
    """The rule's sum or product of :func:`fusion_term`'s terms, in their order (a caller
    that fuses many weightings of the same matrices computes each term once)."""
    adding = _checked_rule(rule) == "sum"
    out: np.ndarray | None = None
    for term in terms:
        out = term if out is None else out + term if adding else out * term
    if out is None:
        raise ValueError(f"the {rule} rule needs at least one dissimilarity")
    return out


def fuse(
    dissimilarities: Mapping[str, np.ndarray],
    rule: str,
    weights: Mapping[str, float] | None = None,
) -> np.ndarray:
    """Apply the ``"sum"`` or ``"product"`` rule (weights default to 1)."""
    weights = weights or {}
    return combine_terms(
        (fusion_term(d, rule, weights.get(name, 1.0)) for name, d in dissimilarities.items()),
        rule,
    )


def fused_dissimilarity(
    queries: Mapping[str, np.ndarray],
    gallery: Mapping[str, np.ndarray],
    preset: Preset,
    sigma: Mapping[str, np.ndarray] | None = None,
) -> np.ndarray:
    """The preset's score of whole queries against a gallery.

    Each of the preset's scored modalities (``preset.scored_modalities``: the fused ones,
    and the size when the units are metric) is compared by its dissimilarity
    (:func:`preset_dissimilarity`: the preset's eq. (8) or (9); the size's
    :func:`size_dissimilarity`) and the matrices are fused by the preset's rule and
    weights. With units "any" this is the fused modalities' score exactly as before the
    size existed.

    Parameters
    ----------
    queries : modality -> (p, M_m) float, the queries' flat vectors
        (:meth:`~worker.engine.descriptor.ShapeDescriptor.vector`), at least of every
        scored modality.
    gallery : modality -> (q, M_m) float, the same for the gallery.
    sigma : modality -> (M_m,) float, eq. (9)'s sigma_i of the modalities compared by
        D2; by default over ``gallery``.

    Returns
    -------
    (p, q) float
    """
    per = {
        m: preset_dissimilarity(
            m, queries[m], gallery[m], preset, None if sigma is None else sigma.get(m)
        )
        for m in preset.scored_modalities
    }
    return fuse(per, preset.fusion, {m: preset.weight(m) for m in preset.scored_modalities})


#: Below this share of a file's surface left out, the file is still a whole (rounding,
#: specks of debris).
PARTIAL_FILE_START = 0.01


def partiality(
    longest_open_loop: float | None, kept_area_fraction: float | None, preset: Preset
) -> float:
    """How partial a query looks, from 0 (a whole) to 1, by its own surface.

    A cut or a hole leaves an open boundary loop: from ``preset.partial_loop[0]``
    square roots of the surface's area the query starts to look partial, from
    ``partial_loop[1]`` wholly (linear in between; the small gaps of a scan stay below
    the start). A file whose other, separate parts were left out
    (``kept_area_fraction`` below 1) is a part of that file: it looks wholly partial
    once a fifth of the file's surface is missing. Descriptors made before these
    were recorded (None) count as wholes.
    """
    start, end = preset.partial_loop
    by_loop = float(np.clip(((longest_open_loop or 0.0) - start) / (end - start), 0.0, 1.0))
    missing = 1.0 - (1.0 if kept_area_fraction is None else kept_area_fraction)
    by_file = float(np.clip((missing - PARTIAL_FILE_START) / (0.2 - PARTIAL_FILE_START), 0, 1))
    return max(by_loop, by_file)


def query_weights(preset: Preset, partiality: float) -> dict[str, float]:
    """The product rule's exponent of each modality for a query this partial.

    ``(1 - partiality) * fusion_weights + partiality * partial_weights``: a whole query
    is scored by the preset's fusion, a wholly partial one by its ``partial_weights``
    (the parts modality), so full queries are ranked exactly as without it. Modalities
    at exponent 0 are left out. A preset without ``partial_weights`` weighs every query
    as a whole. In a metric collection the size is one of the whole's modalities, so it
    fades out as a query looks partial (a part is smaller than its whole).
    """
    whole = {m: preset.weight(m) for m in preset.scored_modalities}
    if not preset.partial_weights or partiality <= 0.0:
        return {m: w for m, w in whole.items() if w != 0.0}
    blended = {
        m: (1.0 - partiality) * whole.get(m, 0.0) + partiality * preset.partial_weights.get(m, 0.0)
        for m in {*whole, *preset.partial_weights}
    }
    return {m: w for m, w in sorted(blended.items()) if w != 0.0}
