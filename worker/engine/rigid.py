"""Rigid verification: how much of a partial query a candidate's surface holds in place.

A depth camera's view of an enrolled object loses most of the large-radius context its
intrinsic descriptors compare, yet keeps the surface it saw exactly as it is, up to a
rigid motion (and, in a collection without units, a scale the parts modality chooses).
An articulated object in another pose is rigid part by part. So a candidate is verified
as object recognition from range data verifies a model (Johnson and Hebert 1999, Rusu
et al. 2009, Drost et al. 2010): local features matched between the two surfaces, a
rigid motion drawn from three matches at a time (RANSAC, Fischler and Bolles 1981), the
best refined by point-to-plane ICP (Chen and Medioni 1992), and the share of the query
that then lies on the candidate (its *fitness*) is the verification's score.

Both surfaces are taken as points with normals on a voxel grid (:mod:`.surface_points`,
as each descriptor keeps its surface), the voxel a share of the candidate's unit (the
square root of its area), and described by
fast point feature histograms (:func:`fpfh`, Rusu, Blodow and Beetz 2009, "Fast Point
Feature Histograms (FPFH) for 3D registration"). Their angles change with the side a
normal points to, so both surfaces' normals must point out of the object, as a closed
mesh wound outward and a view wound toward its sensor have them.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from .descriptor import ShapeDescriptor
from .mesh_io import column_cross, column_dot
from .surface_points import ANCHOR_VOXEL, voxel_points
from .tol import TOL

#: Bins of each of the three angular features of a point pair.
FPFH_BINS = 11
#: The features' radius in voxels.
FEATURE_VOXELS = 5.0
#: Matches within this many voxels of where a hypothesis moves them agree with it.
INLIER_VOXELS = 1.5
#: Three matches make a hypothesis when their pairwise distances agree within this ratio.
EDGE_RATIO = 0.9
#: Triples of matches drawn per fit (seeded), a block at a time; of those whose edges
#: agree, the first ``HYPOTHESES`` are scored, ``HYPOTHESIS_BLOCK`` at a time. Few agree
#: (a quarter of a percent of a view's matches on a figure), so many are drawn.
DRAWS = 1_000_000
DRAW_BLOCK = 100_000
HYPOTHESES = 2500
HYPOTHESIS_BLOCK = 250
#: A hypothesis is scored on this many of the matches (drawn once per fit); the best is
#: refitted to its inliers among all.
SCORING_MATCHES = 500
#: Matches a fit draws from, at most (a view re-gridded on a whole has about 1,500).
MAX_MATCHES = 4000
#: ICP's steps and its correspondence distance in voxels; the fitness counts the query's
#: points within that distance of the candidate.
ICP_STEPS = 30
ICP_VOXELS = 1.0


@dataclass(frozen=True)
class Anchors:
    """A surface as rigid verification sees it.

    Attributes
    ----------
    points, normals : (n, 3) float, one per occupied voxel (unit normals).
    features : (n, 3 * FPFH_BINS) float, :func:`fpfh` at ``FEATURE_VOXELS`` voxels.
    """

    points: np.ndarray
    normals: np.ndarray
    features: np.ndarray


@dataclass(frozen=True)
class RigidFit:
    """A motion ``x -> rotation @ (scale x) + translation`` of the query onto a candidate,
    and the share of the query's voxels it puts within ``ICP_VOXELS`` of the candidate."""

    rotation: np.ndarray
    translation: np.ndarray
    scale: float
    fitness: float


def pair_features(
    p1: np.ndarray, n1: np.ndarray, p2: np.ndarray, n2: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Darboux frame's three angles of point pairs (Rusu et al. 2009, eq. (1)-(2)):
    ``u = n_s``, ``v = u x d``, ``w = u x v`` for the unit line ``d`` from the source ``s``
    to the target ``t``; ``alpha = v . n_t``, ``phi = u . d`` and
    ``theta = atan2(w . n_t, u . n_t)``. The source is the end whose normal makes the
    smaller angle with the line, so a pair gives the same angles from either end.

    Parameters
    ----------
    p1, n1, p2, n2 : (k, 3) float, the pairs' points and unit normals.

    Returns
    -------
    alpha, phi in [-1, 1] and theta in [-pi, pi], (k,) each; zeros for a pair whose
    line is parallel to its source's normal or of zero length.
    """
    # coordinate by coordinate ((3, k) each): a dot or cross product of (k, 3) rows sums
    # over a short axis, which numpy does slowly
    d, n1, n2 = (np.ascontiguousarray(x.T) for x in (p2 - p1, n1, n2))
    length = np.sqrt(column_dot(d, d))
    length[length == 0] = np.inf
    d = d / length
    a1, a2 = column_dot(n1, d), column_dot(n2, d)
    swap = np.abs(a1) < np.abs(a2)  # n2 makes the smaller angle with the line
    u = np.where(swap, n2, n1)
    nt = np.where(swap, n1, n2)
    d = np.where(swap, -d, d)
    phi = np.where(swap, -a2, a1)
    v = column_cross(u, d)
    v_length = np.sqrt(column_dot(v, v))
    degenerate = v_length < TOL.parallel_sine
    v = v / np.where(degenerate, 1.0, v_length)
    w = column_cross(u, v)
    alpha = column_dot(v, nt)
    theta = np.arctan2(column_dot(w, nt), column_dot(u, nt))
    return (
        np.where(degenerate, 0.0, alpha),
        np.where(degenerate, 0.0, phi),
        np.where(degenerate, 0.0, theta),
    )


def fpfh(points: np.ndarray, normals: np.ndarray, radius: float) -> np.ndarray:
    """Fast point feature histograms (Rusu et al. 2009, eq. (3)).

    Each point's simplified histogram (SPFH) bins :func:`pair_features` of its pairs
    with the points within ``radius``, ``FPFH_BINS`` bins per angle, each block a
    distribution; its FPFH adds its neighbours' SPFH weighted by one over their distance
    and divided by their count, each block normalized again.

    Parameters
    ----------
    points, normals : (n, 3) float, unit normals.
    radius : the neighbourhood's radius, in the points' units.

    Returns
    -------
    (n, 3 * FPFH_BINS) float, each block summing to 1 (zeros for a point alone).
    """
    n = len(points)
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    alpha, phi, theta = pair_features(points[i], normals[i], points[j], normals[j])
    bins = np.stack(
        [
            np.clip(((alpha + 1.0) / 2.0 * FPFH_BINS).astype(np.int64), 0, FPFH_BINS - 1),
            np.clip(((phi + 1.0) / 2.0 * FPFH_BINS).astype(np.int64), 0, FPFH_BINS - 1) + FPFH_BINS,
            np.clip(
                ((theta + np.pi) / (2.0 * np.pi) * FPFH_BINS).astype(np.int64), 0, FPFH_BINS - 1
            )
            + 2 * FPFH_BINS,
        ],
        axis=1,
    )
    width = 3 * FPFH_BINS
    ends = np.concatenate([i, j])
    cells = (ends[:, None] * width + np.concatenate([bins, bins])).ravel()
    spfh = np.bincount(cells, minlength=n * width).reshape(n, width).astype(np.float64)
    spfh = _blocks_normalized(spfh)
    offset = (points[j] - points[i]).T
    distance = np.sqrt(column_dot(offset, offset))
    weight = np.where(distance > 0, 1.0 / np.where(distance > 0, distance, 1.0), 0.0)
    neighbours = sp.coo_matrix(
        (np.concatenate([weight, weight]), (ends, np.concatenate([j, i]))), shape=(n, n)
    ).tocsr()
    count = np.bincount(ends, minlength=n).astype(np.float64)
    spread = neighbours @ spfh / np.maximum(count, 1.0)[:, None]
    return _blocks_normalized(spfh + spread)


def _blocks_normalized(histograms: np.ndarray) -> np.ndarray:
    """Each ``FPFH_BINS`` block of each row divided by its sum (zeros stay zeros)."""
    blocks = histograms.reshape(len(histograms), 3, FPFH_BINS)
    total = blocks.sum(axis=2, keepdims=True)
    return (blocks / np.where(total > 0, total, 1.0)).reshape(len(histograms), -1)


def surface_anchors(points: np.ndarray, normals: np.ndarray, voxel: float) -> Anchors:
    """A surface's points and normals (a mesh's vertices and vertex normals) on a grid of
    ``voxel`` spacing (:func:`voxel_points`), with their :func:`fpfh` features."""
    kept, unit = voxel_points(points, normals, voxel)
    return Anchors(kept, unit, fpfh(kept, unit, FEATURE_VOXELS * voxel))


def umeyama(
    source: np.ndarray, target: np.ndarray, scaled: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares motions ``x -> scale * rotation @ x + translation`` moving ``source``
    onto ``target`` (Umeyama 1991; rigid, Kabsch's, unless ``scaled``), batched: (..., k, 3)
    each, returning rotations (..., 3, 3), translations (..., 3) and scales (...)."""
    s_mean, t_mean = source.mean(axis=-2), target.mean(axis=-2)
    centred = source - s_mean[..., None, :]
    cov = np.swapaxes(centred, -1, -2) @ (target - t_mean[..., None, :])
    u, sigma, vt = np.linalg.svd(cov)
    reflected = np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(u, -1, -2)) < 0
    fix = np.ones(u.shape[:-1])
    fix[..., -1] = np.where(reflected, -1.0, 1.0)
    rotation = np.swapaxes(vt, -1, -2) @ (fix[..., :, None] * np.swapaxes(u, -1, -2))
    spread = (centred**2).sum(axis=(-1, -2))
    scale = (
        (sigma * fix).sum(axis=-1) / np.where(spread > 0, spread, 1.0)
        if scaled
        else np.ones(spread.shape)
    )
    moved = scale[..., None] * (rotation @ s_mean[..., None])[..., 0]
    return rotation, t_mean - moved, scale


def feature_matches(query: Anchors, candidate: Anchors) -> tuple[np.ndarray, np.ndarray]:
    """(k, 2) index pairs: each query point and the candidate point of the nearest features,
    and (k,) the distances between their features. Not only mutual nearest: on a view and a
    figure those are a few dozen, a handful of them right, too few for the fit to be found
    reliably."""
    distance, forward = cKDTree(candidate.features).query(query.features)
    pairs = np.stack([np.arange(len(query.features)), np.asarray(forward)], axis=1)
    return pairs, np.asarray(distance)


def feature_distance(distances: np.ndarray) -> float:
    """How close a candidate's surface comes to a view's, from the distances of the view's
    features to their nearest in the candidate (:func:`feature_matches`): their
    ``FEATURE_QUANTILE`` quantile."""
    return float(np.quantile(distances, FEATURE_QUANTILE))


def agreeing_triples(
    picks: np.ndarray,
    ratios: np.ndarray,
    spans: np.ndarray,
    reach: float,
    scales: tuple[float, float],
) -> np.ndarray:
    """The triples of matches ``picks`` ((t, 3) indices) that make a hypothesis, in their
    order: their three edges' length ratios (target over source, ``ratios`` (k, k)) agree
    within ``EDGE_RATIO``, their median within ``EDGE_RATIO`` of ``scales``, and no edge
    of the target (``spans`` (k, k)) is within ``reach``."""
    k = len(ratios)
    a, b, c = picks.T
    flat = ratios.ravel()
    # the edges (a, c), (b, a), (c, b) as flat indices into the (k, k) tables; three
    # ratios agree when every two do, so the third is looked up only where two agree
    first, second = flat[a * k + c], flat[b * k + a]
    two = np.flatnonzero(np.minimum(first, second) >= EDGE_RATIO * np.maximum(first, second))
    a, b, c = a[two], b[two], c[two]
    edges = np.stack([a * k + c, b * k + a, c * k + b])
    ratio = np.stack([first[two], second[two], flat[edges[2]]])
    low, high = ratio.min(axis=0), ratio.max(axis=0)
    implied = ratio[0] + ratio[1] + ratio[2] - low - high  # the median of three
    agree = np.flatnonzero(
        (low >= EDGE_RATIO * high)
        & (implied >= scales[0] * EDGE_RATIO)
        & (implied <= scales[1] / EDGE_RATIO)
    )
    # only the few that agree are looked up again
    far: np.ndarray = two[agree[(spans.ravel()[edges[:, agree]] > reach).all(axis=0)]]
    return far


def inlier_counts(
    source: np.ndarray,
    target: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    scale: np.ndarray,
    inlier: float,
) -> np.ndarray:
    """(h,) how many matches ``source[i] -> target[i]`` ((m, 3) each) each of h motions
    (``rotation`` (h, 3, 3), ``translation`` (h, 3), ``scale`` (h,)) moves within
    ``inlier``: every motion's turn of every point in one matrix product."""
    h, m = len(rotation), len(source)
    # (m, 3, h): each coordinate of every motion's turn of every point
    turned = (source @ rotation.transpose(2, 1, 0).reshape(3, 3 * h)).reshape(m, 3, h)
    squared = np.zeros((m, h))
    for axis in range(3):
        off = scale * turned[:, axis] + (translation[:, axis] - target[:, axis, None])
        squared += off * off
    counted: np.ndarray = (squared < inlier**2).sum(axis=0)
    return counted


def ransac(
    source: np.ndarray,
    target: np.ndarray,
    inlier: float,
    scales: tuple[float, float] = (1.0, 1.0),
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """The motion agreeing with most of the matches ``source[i] -> target[i]`` ((k, 3)
    each): of ``DRAWS`` triples of matches, those whose pairwise distances agree within
    ``EDGE_RATIO`` (after a scale within ``scales``: rigid when it is ``(1, 1)``) make
    hypotheses, the first ``HYPOTHESES`` of them each counting the matches it moves
    within ``inlier`` (of ``SCORING_MATCHES`` of them); the best refitted to its inliers
    among all (:func:`umeyama`). Returns rotation, translation, scale and the inliers'
    count. At most ``MAX_MATCHES`` matches are drawn from (a seeded sample): each pair's
    lengths are held at once."""
    k = len(source)
    scaled = scales[0] != scales[1]
    best: tuple[np.ndarray, np.ndarray, float, int] = (np.eye(3), np.zeros(3), 1.0, 0)
    if k < 3:
        return best
    rng = np.random.default_rng(seed)
    if k > MAX_MATCHES:
        kept = np.sort(rng.permutation(k)[:MAX_MATCHES])
        source, target, k = source[kept], target[kept], MAX_MATCHES
    # every pair's two lengths once; a triple's edges are three lookups
    spans_s = cdist(source, source).astype(np.float32)
    spans_t = cdist(target, target).astype(np.float32)
    ratios = spans_t / np.where(spans_s > 0, spans_s, np.float32(np.inf))
    scoring = np.sort(rng.permutation(k)[:SCORING_MATCHES])
    scoring_source, scoring_target = source[scoring], target[scoring]
    scored = 0
    for _ in range(DRAWS // DRAW_BLOCK):
        picks = rng.integers(0, k, size=(DRAW_BLOCK, 3))
        valid = agreeing_triples(picks, ratios, spans_t, inlier, scales)[: HYPOTHESES - scored]
        for start in range(0, len(valid), HYPOTHESIS_BLOCK):
            drawn = picks[valid[start : start + HYPOTHESIS_BLOCK]]
            rotation, translation, scale = umeyama(source[drawn], target[drawn], scaled)
            counts = inlier_counts(
                scoring_source, scoring_target, rotation, translation, scale, inlier
            )
            h = int(np.argmax(counts))
            if counts[h] > best[3]:
                best = (rotation[h], translation[h], float(scale[h]), int(counts[h]))
        scored += len(valid)
        if scored >= HYPOTHESES:
            break
    if best[3] >= 3:
        turn, shift, factor, count = best
        agree = np.linalg.norm(factor * source @ turn.T + shift - target, axis=1) < inlier
        refit = umeyama(source[agree], target[agree], scaled)
        best = (refit[0], refit[1], float(refit[2]), count)
    return best


def icp(
    source: np.ndarray,
    target: np.ndarray,
    target_normals: np.ndarray,
    start: tuple[np.ndarray, np.ndarray, float],
    reach: float,
    scales: tuple[float, float] = (1.0, 1.0),
    tree: cKDTree | None = None,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Point-to-plane ICP (Chen and Medioni 1992): ``ICP_STEPS`` linearized steps moving
    ``source`` onto the planes of its nearest ``target`` points within ``reach``, from the
    motion ``start`` (rotation, translation, scale); the scale refined too, within
    ``scales``, unless that is ``(1, 1)``. Returns the motion."""
    tree = tree if tree is not None else cKDTree(target)
    rotation, translation, scale = start
    scaled = scales[0] != scales[1]
    for _ in range(ICP_STEPS):
        moved = scale * source @ rotation.T + translation
        distance, nearest = tree.query(moved, distance_upper_bound=reach)
        close = np.isfinite(distance)
        if close.sum() < 7:
            break
        # linearized about the matched points' centre, where the turn moves them least
        centre = moved[close].mean(axis=0)
        nearest = np.asarray(nearest)[close]
        p, q, n = moved[close] - centre, target[nearest] - centre, target_normals[nearest]
        along = (p * n).sum(axis=1)
        jacobian = np.column_stack([np.cross(p, n), n, *([along] if scaled else [])])
        step = np.linalg.lstsq(jacobian, ((q - p) * n).sum(axis=1), rcond=None)[0]
        a, b, c = step[:3]
        u, _, vt = np.linalg.svd(np.array([[1.0, -c, b], [c, 1.0, -a], [-b, a, 1.0]]))
        turn = u @ vt  # the nearest rotation to the linearized one
        grow = float(np.clip((1.0 + step[6]) * scale, *scales)) / scale if scaled else 1.0
        rotation, scale = turn @ rotation, grow * scale
        translation = centre + grow * (turn @ (translation - centre) + step[3:6])
        if np.abs(step).max() < TOL.icp_step:
            break
    return rotation, translation, scale


def rigid_fit(
    query: Anchors,
    candidate: Anchors,
    voxel: float,
    scales: tuple[float, float] = (1.0, 1.0),
    matches: np.ndarray | None = None,
) -> RigidFit:
    """Verify ``query`` on ``candidate``, both anchored at ``voxel`` (module docstring):
    feature matches (``matches`` where the caller has them from :func:`feature_matches`),
    RANSAC and point-to-plane ICP within ``scales`` of the query's size, and the fitness."""
    if matches is None:
        matches = feature_matches(query, candidate)[0]
    rotation, translation, scale, _ = ransac(
        query.points[matches[:, 0]], candidate.points[matches[:, 1]], INLIER_VOXELS * voxel, scales
    )
    tree = cKDTree(candidate.points)
    reach = ICP_VOXELS * voxel
    rotation, translation, scale = icp(
        query.points,
        candidate.points,
        candidate.normals,
        (rotation, translation, scale),
        reach,
        scales,
        tree,
    )
    placed = scale * query.points @ rotation.T + translation
    distance = tree.query(placed, distance_upper_bound=reach)[0]
    return RigidFit(rotation, translation, scale, float(np.isfinite(distance).mean()))


#: A single view's best candidates that are verified, and re-ranked by their fitness: the
#: parts hold its own class among their best 10 for 89% of TOSCA + SCAPE's views and 79%
#: of their range scans, among their best 20 for 93% and 88% (docs/decisions.md).
VERIFIED = 20
#: A view's own source lies among the parts' best 20 for only half of those views (its
#: other poses score alike), among their best 100 for 95%; so of the parts' best
#: ``FEATURE_POOL``, the ``FEATURE_PICKS`` whose surfaces' features lie closest to the
#: view's (:func:`feature_distance`) are verified too (docs/decisions.md).
FEATURE_POOL = 100
FEATURE_PICKS = 10
#: :func:`feature_distance`'s quantile: a view shares its surface with part of a whole,
#: so the closest of its features' distances tell, not their bulk.
FEATURE_QUANTILE = 0.1
#: A single view's unit (the square root of both its sides' area) over its object's: a
#: view holds about a third of its object's surface, a range grid less (its grazing
#: triangles dropped as shortcuts), so its two sides under two thirds (``sqrt(2 / 3)`` =
#: 0.82); the parts' scale, kept near 1 by its prior, does not see it. On TOSCA + SCAPE's
#: range scans the fits that hold their own source find a median 0.80 (10-90%:
#: 0.71-0.86) over the parts' scale; of 0.78, 0.83 and 0.88, TOSCA's copies chose 0.78,
#: and SCAPE's agreed (docs/decisions.md).
VIEW_UNIT = 0.78
#: How far from ``VIEW_UNIT`` over the parts' scale a fit may move a view (either way):
#: a view's share of its object varies; a fit that holds little of the view drifts to the
#: window's edge, so a wider window lets a wrong one hold more.
SCALE_WINDOW = 1.25
#: A fit holding this share of a view lies on its own object: on TOSCA + SCAPE's `view`,
#: `range`, `range-cloud` and `view-points` copies every fittest candidate holding as much
#: was of the view's class (475 of 616 copies with their source among the candidates, 35
#: with it left out), where 0.85 let 6 of another class through and 0.8 nineteen
#: (``python -m experiments.view_held``, v18; docs/evaluation.md).
HELD_FITNESS = 0.9


def stored_anchors(surface: np.ndarray, voxel: float, factor: float = 1.0) -> Anchors:
    """A descriptor's gridded surface (:attr:`~.descriptor.ShapeDescriptor.surface`, at
    ``voxel`` of its unit) as anchors at ``ANCHOR_VOXEL`` after its points are multiplied
    by ``factor`` (into another surface's units); re-gridded when its grid is finer."""
    points = surface[:, :3].astype(np.float64) * factor
    normals = surface[:, 3:].astype(np.float64)
    if voxel * factor < ANCHOR_VOXEL * (1.0 - TOL.grid_match):
        points, normals = voxel_points(points, normals, ANCHOR_VOXEL)
    return Anchors(points, normals, fpfh(points, normals, FEATURE_VOXELS * ANCHOR_VOXEL))


def kept_surface(descriptor: ShapeDescriptor) -> tuple[np.ndarray, float, float] | None:
    """``descriptor``'s gridded surface, its grid's voxel and unit; None when it was
    stored without them (before surfaces were kept): such a shape is neither fitted nor
    fitted on."""
    voxel, unit = descriptor.surface_voxel, descriptor.surface_unit
    if not (len(descriptor.surface) and voxel and unit):
        return None
    return descriptor.surface, voxel, unit


def candidate_anchors(candidate: ShapeDescriptor) -> Anchors | None:
    """The anchors a single view is fitted on in ``candidate`` (:func:`stored_anchors` of
    its kept surface at its own grid): the same for every query, so a caller verifying
    many may keep them (:func:`verified_fitness`'s ``anchors``); None for a candidate kept
    without its surface (it is not fitted)."""
    if (kept := kept_surface(candidate)) is None:
        return None
    return stored_anchors(kept[0], kept[1])


def verified_fitness(
    query: ShapeDescriptor,
    candidates: Sequence[ShapeDescriptor],
    parts_scale: float,
    metric: bool,
    anchors: Sequence[Anchors | None] | None = None,
    threads: int = 1,
) -> np.ndarray | None:
    """(k,) the fitness of a single view on its candidates (:func:`rigid_fit` on their kept
    surfaces), NaN on those it is not fitted on; or None when the query is no single view
    or a surface is missing (a descriptor stored before surfaces were kept).

    The candidates are the parts' best (``FEATURE_POOL`` of them, in their order); the
    view is fitted on the first ``VERIFIED`` and on the ``FEATURE_PICKS`` of all whose
    features lie closest to its own (:func:`feature_distance`). A candidate that is itself
    a single view counts only where the fit holds the query (``HELD_FITNESS``; NaN below
    it): two views of an object share only what both saw, so another pose seen from
    elsewhere holds little of the query whatever its object (TOSCA's range scans all to
    all, one of each whole: ranked by every such fit, NN 54.2 -> 47.0%), while a fit that
    holds it lies on the same object seen from nearby (docs/decisions.md).

    Parameters
    ----------
    query, candidates : descriptors with their surfaces.
    parts_scale : the scale ``s`` the parts modality chose for the query; the query's
        unit is taken as ``VIEW_UNIT / s`` of a whole's (``1 / s`` of a view's) in a
        collection without units, fitted within ``SCALE_WINDOW`` of that.
    metric : a collection of metric units: the query's unit in each candidate's is the
        ratio of their ``surface_unit``, fitted at exactly that.
    anchors : each candidate's :func:`candidate_anchors` where the caller kept them (None
        where not: made here).
    threads : the candidates' anchors made, their features compared and the chosen
        fitted on this many threads (each fit is seeded alone: the fitnesses do not
        depend on it).
    """
    kept = [k for d in (query, *candidates) if (k := kept_surface(d)) is not None]
    if not query.single_view or len(kept) <= len(candidates):
        return None
    (surface, voxel, unit), held = kept[0], kept[1:]
    scales = (1.0, 1.0) if metric else (1.0 / SCALE_WINDOW, SCALE_WINDOW)
    kept_anchors = anchors if anchors is not None else [None] * len(candidates)
    factors = {
        i: unit / grid[2] if metric else (1.0 if candidate.single_view else VIEW_UNIT) / parts_scale
        for i, (candidate, grid) in enumerate(zip(candidates, held, strict=True))
    }

    def compared(i: int) -> tuple[Anchors, np.ndarray, float]:
        """The candidate's anchors, the view's matches on them and their closeness."""
        grid, grid_voxel, _ = held[i]
        made = kept_anchors[i]
        on = made if made is not None else stored_anchors(grid, grid_voxel)
        matches, distances = feature_matches(placed[factors[i]], on)
        return on, matches, feature_distance(distances)

    def fit(i: int) -> float:
        on, matches, _ = found[i]
        return rigid_fit(placed[factors[i]], on, ANCHOR_VOXEL, scales, matches).fitness

    fitness = np.full(len(candidates), np.nan)
    with ThreadPoolExecutor(threads) as pool:  # numpy and the k-d tree release the GIL
        distinct = sorted(set(factors.values()))
        views = pool.map(lambda f: stored_anchors(surface, voxel, f), distinct)
        placed = dict(zip(distinct, views, strict=True))
        found = dict(zip(factors, pool.map(compared, factors), strict=True))
        closeness = np.full(len(candidates), np.inf)
        closeness[list(found)] = [c for _, _, c in found.values()]
        closest = np.argsort(closeness, kind="stable")[:FEATURE_PICKS]
        chosen = sorted((set(range(VERIFIED)) | {int(c) for c in closest}) & set(found))
        fitness[chosen] = list(pool.map(fit, chosen))
    of_views = np.array([c.single_view for c in candidates], dtype=bool)
    fitness[of_views & ~(fitness >= HELD_FITNESS)] = np.nan
    return fitness


def verified_order(fitness: np.ndarray) -> np.ndarray:
    """The candidates' positions after verification: those whose fit holds the query
    (``HELD_FITNESS``) first, most of it held first; then the others, the fitted (a finite
    fitness) in the places they held among them, most held first, a candidate not fitted
    (NaN) keeping its place; ties in their order."""
    held = np.flatnonzero(np.nan_to_num(fitness, nan=-1.0) >= HELD_FITNESS)
    held = held[np.argsort(-fitness[held], kind="stable")]
    rest = np.setdiff1d(np.arange(len(fitness)), held)
    fitted = np.flatnonzero(np.isfinite(fitness[rest]))
    rest[fitted] = rest[fitted][np.argsort(-fitness[rest][fitted], kind="stable")]
    return np.concatenate([held, rest])
