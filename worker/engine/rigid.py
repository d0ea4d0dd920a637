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

Both surfaces are taken as points with normals on a voxel grid (:func:`voxel_points`),
the voxel a share of the candidate's unit (the square root of its area), and described by
fast point feature histograms (:func:`fpfh`, Rusu, Blodow and Beetz 2009, "Fast Point
Feature Histograms (FPFH) for 3D registration"). Their angles change with the side a
normal points to, so both surfaces' normals must point out of the object, as a closed
mesh wound outward and a view wound toward its sensor have them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .tol import TOL

#: Bins of each of the three angular features of a point pair.
FPFH_BINS = 11
#: The features' radius in voxels.
FEATURE_VOXELS = 5.0
#: Matches within this many voxels of where a hypothesis moves them agree with it.
INLIER_VOXELS = 1.5
#: Three matches make a hypothesis when their pairwise distances agree within this ratio.
EDGE_RATIO = 0.9
#: Hypotheses drawn per fit (seeded), scored a block at a time.
HYPOTHESES = 4000
HYPOTHESIS_BLOCK = 500
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


def voxel_points(
    points: np.ndarray, normals: np.ndarray, voxel: float
) -> tuple[np.ndarray, np.ndarray]:
    """The mean point and normal of each occupied cell of a grid of ``voxel`` spacing.

    Parameters
    ----------
    points, normals : (n, 3) float; normals need not be unit.
    voxel : the cells' edge, in the points' units.

    Returns
    -------
    (m, 3) points and (m, 3) unit normals, in the order of their cells; a cell whose
    normals cancel is left out.
    """
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    cells = np.floor((points - points.min(axis=0)) / voxel).astype(np.int64)
    _, cell, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    cell = cell.ravel()
    mean = np.stack([np.bincount(cell, points[:, a]) for a in range(3)], axis=1) / counts[:, None]
    unit = np.linalg.norm(normals, axis=1, keepdims=True)
    unit[unit == 0] = 1.0
    direction = np.stack([np.bincount(cell, normals[:, a] / unit[:, 0]) for a in range(3)], axis=1)
    length = np.linalg.norm(direction, axis=1)
    kept = length > TOL.cancelled_normals * counts
    return mean[kept], direction[kept] / length[kept, None]


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
    d = p2 - p1
    length = np.linalg.norm(d, axis=1)
    length[length == 0] = np.inf
    d = d / length[:, None]
    a1, a2 = (n1 * d).sum(axis=1), (n2 * d).sum(axis=1)
    swap = np.abs(a1) < np.abs(a2)  # n2 makes the smaller angle with the line
    u = np.where(swap[:, None], n2, n1)
    nt = np.where(swap[:, None], n1, n2)
    d = np.where(swap[:, None], -d, d)
    phi = np.where(swap, -a2, a1)
    v = np.cross(u, d)
    v_length = np.linalg.norm(v, axis=1)
    degenerate = v_length < TOL.parallel_sine
    v = v / np.where(degenerate, 1.0, v_length)[:, None]
    w = np.cross(u, v)
    alpha = (v * nt).sum(axis=1)
    theta = np.arctan2((w * nt).sum(axis=1), (u * nt).sum(axis=1))
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
    distance = np.linalg.norm(points[i] - points[j], axis=1)
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


def feature_matches(query: Anchors, candidate: Anchors) -> np.ndarray:
    """(k, 2) index pairs (query, candidate) whose features are each other's nearest."""
    forward = np.asarray(cKDTree(candidate.features).query(query.features)[1])
    backward = np.asarray(cKDTree(query.features).query(candidate.features)[1])
    mutual = backward[forward] == np.arange(len(forward))
    return np.stack([np.flatnonzero(mutual), forward[mutual]], axis=1)


def ransac(
    source: np.ndarray,
    target: np.ndarray,
    inlier: float,
    scales: tuple[float, float] = (1.0, 1.0),
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """The motion agreeing with most of the matches ``source[i] -> target[i]`` ((k, 3)
    each): ``HYPOTHESES`` drawn from three matches whose pairwise distances agree within
    ``EDGE_RATIO`` (after a scale within ``scales``: rigid when it is ``(1, 1)``), each
    counting the matches it moves within ``inlier``; the best refitted to its inliers
    (:func:`umeyama`). Returns rotation, translation, scale and the inliers' count."""
    k = len(source)
    scaled = scales[0] != scales[1]
    best: tuple[np.ndarray, np.ndarray, float, int] = (np.eye(3), np.zeros(3), 1.0, 0)
    if k < 3:
        return best
    rng = np.random.default_rng(seed)
    for _ in range(HYPOTHESES // HYPOTHESIS_BLOCK):
        picks = rng.integers(0, k, size=(HYPOTHESIS_BLOCK, 3))
        s, t = source[picks], target[picks]
        edges_s = np.linalg.norm(s - np.roll(s, 1, axis=1), axis=2)
        edges_t = np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2)
        ratio = edges_t / np.where(edges_s > 0, edges_s, np.inf)
        implied = np.median(ratio, axis=1)
        valid = (
            (ratio.min(axis=1) >= EDGE_RATIO * ratio.max(axis=1))
            & (implied >= scales[0] * EDGE_RATIO)
            & (implied <= scales[1] / EDGE_RATIO)
            & (edges_t > inlier).all(axis=1)
        )
        if not valid.any():
            continue
        rotation, translation, scale = umeyama(s[valid], t[valid], scaled)
        moved = scale[:, None, None] * np.einsum("hij,kj->hki", rotation, source)
        moved += translation[:, None, :]
        counts = (np.linalg.norm(moved - target[None], axis=2) < inlier).sum(axis=1)
        h = int(np.argmax(counts))
        if counts[h] > best[3]:
            best = (rotation[h], translation[h], float(scale[h]), int(counts[h]))
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
    query: Anchors, candidate: Anchors, voxel: float, scales: tuple[float, float] = (1.0, 1.0)
) -> RigidFit:
    """Verify ``query`` on ``candidate``, both anchored at ``voxel`` (module docstring):
    feature matches, RANSAC and point-to-plane ICP within ``scales`` of the query's size,
    and the fitness."""
    matches = feature_matches(query, candidate)
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
