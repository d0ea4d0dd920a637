"""Rigid verification: point feature histograms, RANSAC's triples and inlier counts against
plain loops, motions recovered
from matches with outliers, a depth view of a figure held by its own surface, not by
another figure's, and a described view verified on the wholes of a shortlist."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import trimesh
from conftest import random_rotation

from worker.engine import rigid
from worker.engine.mesh_io import Mesh
from worker.engine.pipeline import describe_mesh
from worker.engine.presets import DEFAULT_PRESET, get_preset
from worker.engine.rigid import (
    EDGE_RATIO,
    FPFH_BINS,
    agreeing_triples,
    candidate_anchors,
    fpfh,
    inlier_counts,
    kept_surface,
    pair_features,
    ransac,
    rigid_fit,
    surface_anchors,
    umeyama,
    verified_fitness,
    verified_order,
)
from worker.engine.surface_points import ANCHOR_VOXEL, VIEW_VOXEL
from worker.evaluation.partial import single_view, with_depth_noise
from worker.evaluation.samples import depth_scan, sample_mesh


def pair_reference(ps, ns, pt, nt):
    """Rusu et al. 2009, eq. (1)-(2), one pair at a time."""
    d = [b - a for a, b in zip(ps, pt, strict=True)]
    length = math.sqrt(sum(x * x for x in d))
    d = [x / length for x in d]
    dot = lambda a, b: sum(x * y for x, y in zip(a, b, strict=True))  # noqa: E731
    cross = lambda a, b: [  # noqa: E731
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
    if math.acos(min(1.0, abs(dot(ns, d)))) > math.acos(min(1.0, abs(dot(nt, d)))):
        ns, nt, d = nt, ns, [-x for x in d]
    u = ns
    v = cross(u, d)
    norm = math.sqrt(dot(v, v))
    v = [x / norm for x in v]
    w = cross(u, v)
    return dot(v, nt), dot(u, d), math.atan2(dot(w, nt), dot(u, nt))


def fpfh_reference(points, normals, radius):
    """Each point's SPFH and FPFH by loops over its neighbours (Rusu et al. 2009, eq. (3))."""
    n = len(points)
    neighbours = [
        [j for j in range(n) if j != i and np.linalg.norm(points[j] - points[i]) <= radius]
        for i in range(n)
    ]

    def blocks(h):
        h = h.reshape(3, FPFH_BINS)
        total = h.sum(axis=1, keepdims=True)
        return (h / np.where(total > 0, total, 1)).ravel()

    spfh = np.zeros((n, 3 * FPFH_BINS))
    for i in range(n):
        for j in neighbours[i]:
            alpha, phi, theta = pair_reference(points[i], normals[i], points[j], normals[j])
            spfh[i, min(int((alpha + 1) / 2 * FPFH_BINS), FPFH_BINS - 1)] += 1
            spfh[i, FPFH_BINS + min(int((phi + 1) / 2 * FPFH_BINS), FPFH_BINS - 1)] += 1
            spfh[i, 2 * FPFH_BINS + min(int((theta + np.pi) / (2 * np.pi) * FPFH_BINS), 10)] += 1
        spfh[i] = blocks(spfh[i])
    out = np.zeros_like(spfh)
    for i in range(n):
        spread = sum(
            (spfh[j] / np.linalg.norm(points[j] - points[i]) for j in neighbours[i]),
            np.zeros(3 * FPFH_BINS),
        )
        out[i] = blocks(spfh[i] + spread / max(len(neighbours[i]), 1))
    return out


def unit_rows(x):
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def test_pair_features_are_the_paper_s_from_either_end():
    rng = np.random.default_rng(0)
    p1, p2 = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    n1, n2 = unit_rows(rng.normal(size=(50, 3))), unit_rows(rng.normal(size=(50, 3)))
    forward = np.stack(pair_features(p1, n1, p2, n2), axis=1)
    np.testing.assert_allclose(forward, np.stack(pair_features(p2, n2, p1, n1), axis=1), atol=1e-12)
    expected = [pair_reference(*map(list, row)) for row in zip(p1, n1, p2, n2, strict=True)]
    np.testing.assert_allclose(forward, expected, atol=1e-12)


@pytest.mark.parametrize("source", ["random", "figure"])
def test_fpfh_equals_the_plain_loops(source):
    rng = np.random.default_rng(1)
    if source == "random":
        points, normals = rng.uniform(size=(150, 3)), unit_rows(rng.normal(size=(150, 3)))
        radius = 0.3
    else:
        mesh = sample_mesh("quadruped", 0)
        shape = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
        keep = rng.choice(len(mesh.vertices), 300, replace=False)
        points, normals = mesh.vertices[keep], shape.vertex_normals[keep]
        radius = 0.1 * float(np.ptp(points, axis=0).max())
    features = fpfh(points, normals, radius)
    np.testing.assert_allclose(features, fpfh_reference(points, normals, radius), atol=1e-12)
    assert features.shape == (len(points), 3 * FPFH_BINS)


def test_fpfh_does_not_move_with_the_surface():
    rng = np.random.default_rng(2)
    mesh = sample_mesh("bird", 1)
    normals = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).vertex_normals
    radius = 0.1 * float(np.ptp(mesh.vertices, axis=0).max())
    turn = random_rotation(rng)
    moved = fpfh(mesh.vertices @ turn.T + rng.normal(size=3), normals @ turn.T, radius)
    np.testing.assert_allclose(moved, fpfh(mesh.vertices, normals, radius), atol=1e-9)


@pytest.mark.parametrize("scaled", [False, True])
def test_umeyama_recovers_a_motion_batched(scaled):
    rng = np.random.default_rng(3)
    turns = np.stack([random_rotation(rng) for _ in range(4)])
    shifts, factors = rng.normal(size=(4, 3)), rng.uniform(0.5, 2.0, 4) if scaled else np.ones(4)
    source = rng.normal(size=(4, 10, 3))
    target = factors[:, None, None] * source @ np.swapaxes(turns, 1, 2) + shifts[:, None, :]
    rotation, translation, scale = umeyama(source, target, scaled)
    np.testing.assert_allclose(rotation, turns, atol=1e-9)
    np.testing.assert_allclose(translation, shifts, atol=1e-9)
    np.testing.assert_allclose(scale, factors, atol=1e-9)


@pytest.mark.parametrize("scales", [(1.0, 1.0), (0.7, 1.5)])
def test_agreeing_triples_equal_the_plain_loop(scales):
    rng = np.random.default_rng(7)
    source = rng.uniform(size=(60, 3))
    target = 1.1 * source + rng.normal(scale=0.03, size=(60, 3))
    spans_s, spans_t = (np.linalg.norm(p[:, None] - p[None], axis=2) for p in (source, target))
    ratios = (spans_t / np.where(spans_s > 0, spans_s, np.inf)).astype(np.float32)
    picks = rng.integers(0, 60, size=(5000, 3))
    reach = 0.05
    expected = []
    for t, triple in enumerate(picks):
        edges = [(triple[i], triple[(i + 2) % 3]) for i in range(3)]
        lengths = sorted(float(ratios[e]) for e in edges)
        if (
            lengths[0] >= EDGE_RATIO * lengths[2]
            and scales[0] * EDGE_RATIO <= lengths[1] <= scales[1] / EDGE_RATIO
            and all(spans_t[e] > reach for e in edges)
        ):
            expected.append(t)
    found = agreeing_triples(picks, ratios, spans_t.astype(np.float32), reach, scales)
    assert 0 < len(expected) < len(picks)
    assert found.tolist() == expected


def test_inlier_counts_equal_the_plain_loop():
    rng = np.random.default_rng(11)
    source = rng.uniform(size=(300, 3))
    rotation = np.stack([random_rotation(rng) for _ in range(40)])
    translation = rng.normal(scale=0.05, size=(40, 3))
    scale = rng.uniform(0.8, 1.25, size=40)
    target = source @ rotation[0].T + rng.normal(scale=0.05, size=(300, 3))
    inlier = 0.08
    expected = [
        sum(
            float(np.linalg.norm(f * r @ p + t - q)) < inlier
            for p, q in zip(source, target, strict=True)
        )
        for r, t, f in zip(rotation, translation, scale, strict=True)
    ]
    found = inlier_counts(source, target, rotation, translation, scale, inlier)
    assert 0 < max(expected) < len(source)
    assert found.tolist() == expected


@pytest.mark.parametrize("factor", [1.0, 1.3])
def test_ransac_finds_the_motion_among_wrong_matches(factor):
    rng = np.random.default_rng(4)
    source = rng.uniform(size=(200, 3))
    turn, shift = random_rotation(rng), rng.normal(size=3)
    target = factor * source @ turn.T + shift
    wrong = rng.choice(200, 120, replace=False)
    target[wrong] = rng.uniform(-2, 2, size=(120, 3))
    scales = (1.0, 1.0) if factor == 1.0 else (0.7, 1.5)
    rotation, translation, scale, inliers = ransac(source, target, 0.01, scales)
    assert inliers == 80
    np.testing.assert_allclose(rotation, turn, atol=1e-9)
    np.testing.assert_allclose(translation, shift, atol=1e-9)
    assert scale == pytest.approx(factor, abs=1e-9)


def figure_anchors(name: str, pose: int, voxel: float) -> rigid.Anchors:
    mesh = sample_mesh(name, pose)
    normals = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).vertex_normals
    return surface_anchors(mesh.vertices, normals, voxel)


def depth_view(factor: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The quadruped's left side as a depth camera's points and normals (the grid's own
    triangles', facing the camera), turned, moved and scaled by ``factor``; and where they
    were."""
    mesh = sample_mesh("quadruped", 3)
    sight = np.array([0.0, 1.0, 0.0])
    grid, _ = depth_scan(mesh, sight, 1500)
    seen = np.isfinite(grid).all(axis=2)
    rows, cols = np.nonzero(seen[:-1, :-1] & seen[1:, :-1] & seen[:-1, 1:])
    index = np.arange(grid.shape[0] * grid.shape[1]).reshape(grid.shape[:2])
    faces = np.stack([index[rows, cols], index[rows + 1, cols], index[rows, cols + 1]], axis=1)
    view = trimesh.Trimesh(np.nan_to_num(grid.reshape(-1, 3)), faces, process=False)
    used = np.unique(faces)
    normals = view.vertex_normals[used] * np.sign((view.vertex_normals[used] @ sight).sum())
    rng = np.random.default_rng(seed)
    turn = random_rotation(rng)
    points = factor * view.vertices[used] @ turn.T + rng.normal(size=3)
    return points, normals @ turn.T, view.vertices[used]


@pytest.mark.parametrize("factor", [1.0, 1.1])
def test_a_depth_view_is_held_by_its_own_figure_only(factor):
    """Up to a tenth off in scale: the features' radius is then off as much (at a fifth,
    this view is no longer found)."""
    whole = sample_mesh("quadruped", 3)
    voxel = 0.02 * math.sqrt(trimesh.Trimesh(whole.vertices, whole.faces).area)
    points, normals, truth = depth_view(factor, 5)
    # anchored at the whole's voxel, as if its scale were right; RANSAC finds the rest
    query = surface_anchors(points, normals, voxel)
    scales = (1.0, 1.0) if factor == 1.0 else (0.7, 1.4)
    held = rigid_fit(query, figure_anchors("quadruped", 3, voxel), voxel, scales)
    assert held.fitness > 0.9
    assert held.scale == pytest.approx(1.0 / factor, rel=0.05)
    placed = held.scale * points @ held.rotation.T + held.translation
    assert np.median(np.linalg.norm(placed - truth, axis=1)) < 1.5 * voxel
    for other in ("biped", "spider", "hand"):
        assert rigid_fit(query, figure_anchors(other, 0, voxel), voxel, scales).fitness < 0.6


def test_verified_order_puts_the_held_first_and_moves_only_the_other_fitted():
    fitness = np.array([0.2, np.nan, 0.9, 0.2, np.nan, 0.5])
    # the one held (HELD_FITNESS) first; the other fitted keep their three places among
    # the rest (0, 2, 4 of 0, 1, 3, 4, 5), most held first, ties in order
    np.testing.assert_array_equal(verified_order(fitness), [2, 5, 1, 0, 4, 3])
    # held ones ahead of every other, most held first, ties in order
    fitness = np.array([np.nan, 0.5, 0.95, np.nan, 0.92, 0.95])
    np.testing.assert_array_equal(verified_order(fitness), [2, 5, 4, 0, 1, 3])
    np.testing.assert_array_equal(verified_order(np.full(3, np.nan)), [0, 1, 2])


@pytest.fixture(scope="module")
def quadruped_view():
    """A view of the quadruped described as the service describes a query."""
    seen = single_view(sample_mesh("quadruped", 3), np.array([0.0, 1.0, 0.0]))
    return describe_mesh(seen, get_preset(DEFAULT_PRESET))


def test_a_described_view_is_verified_on_its_candidates(verified_wholes, quadruped_view):
    """A view of the quadruped: its own figure (another pose's mesh) holds most of it,
    other figures far less, alike on threads; an enrolled view of another pose seen from
    elsewhere holds less than ``HELD_FITNESS`` of it (NaN), and a descriptor kept before
    surfaces were is not verified at all."""
    preset = get_preset(DEFAULT_PRESET)
    query = quadruped_view
    assert query.single_view and query.surface_voxel == VIEW_VOXEL
    wholes = verified_wholes
    enrolled_view = describe_mesh(single_view(sample_mesh("quadruped", 1), np.ones(3)), preset)
    candidates = [*wholes, enrolled_view]
    fitness = verified_fitness(query, candidates, 1.0, metric=False)
    assert fitness is not None and np.isnan(fitness[-1])
    assert fitness[0] > 0.8 and fitness[0] > max(fitness[1:-1]) + 0.15, fitness
    # a caller's kept anchors fit exactly as those made anew
    kept = [candidate_anchors(c) for c in candidates]
    assert all(a is not None for a in kept)
    np.testing.assert_array_equal(verified_fitness(query, candidates, 1.0, False, kept), fitness)
    # and on threads, made anew or kept, exactly as on one
    for anchors in (None, kept):
        threaded = verified_fitness(query, candidates, 1.0, False, anchors, threads=3)
        np.testing.assert_array_equal(threaded, fitness)
    # a descriptor stored before surfaces were kept is neither fitted on nor fitted
    old = dataclasses.replace(wholes[1], surface=np.zeros((0, 6), dtype=np.float16))
    assert kept_surface(old) is None and kept_surface(wholes[1]) is not None
    assert candidate_anchors(old) is None
    assert verified_fitness(query, [wholes[0], old], 1.0, metric=False) is None
    unkept = dataclasses.replace(query, surface_voxel=None)
    assert kept_surface(unkept) is None
    assert verified_fitness(unkept, wholes, 1.0, metric=False) is None
    assert verified_fitness(wholes[0], wholes[1:], 1.0, metric=False) is None  # no view


def test_a_view_of_the_same_object_from_nearby_holds_a_view_and_goes_first(
    verified_wholes, quadruped_view
):
    """Two views share only what both saw: the quadruped's pose seen from 15 to 30 degrees
    away from the query's direction holds it (at least ``HELD_FITNESS``), and the fittest
    goes ahead of the wholes; the same direction on another pose, and another figure, hold
    less and count for nothing (NaN)."""
    preset = get_preset(DEFAULT_PRESET)
    turned = [np.radians(d) for d in (30.0, 15.0)]
    near = [
        describe_mesh(
            single_view(sample_mesh("quadruped", 3), np.array([np.sin(a), np.cos(a), 0.0])), preset
        )
        for a in turned
    ]
    ahead = np.array([0.0, 1.0, 0.0])
    other = [
        describe_mesh(single_view(sample_mesh(name, pose), ahead), preset)
        for name, pose in (("quadruped", 1), ("biped", 0))
    ]
    candidates = [*verified_wholes, *other, *near]
    fitness = verified_fitness(quadruped_view, candidates, 1.0, metric=False)
    assert fitness is not None
    assert np.isnan(fitness[-4:-2]).all() and (fitness[-2:] >= rigid.HELD_FITNESS).all()
    assert fitness[-1] > fitness[-2], fitness  # nearer holds more
    assert verified_order(fitness)[0] == len(candidates) - 1


def test_a_view_with_depth_noise_is_held_as_the_noiseless_view_is():
    """A view of a finely tessellated quadruped, every vertex moved along the ray by noise
    of 0.5% of the object's diagonal (a consumer depth camera's): rough, so smoothed before
    it is gridded (:func:`~worker.engine.denoise.view_denoised`), its unit stays within 2%
    of the noiseless view's (unsmoothed 20% above) and its own whole holds all of it, as
    all of the noiseless view (unsmoothed, under half)."""
    preset = get_preset(DEFAULT_PRESET)
    coarse = sample_mesh("quadruped", 3)
    fine = trimesh.Trimesh(coarse.vertices, coarse.faces, process=False).subdivide()
    mesh = Mesh(np.asarray(fine.vertices), np.asarray(fine.faces))
    others = [describe_mesh(sample_mesh(name, 0), preset) for name in ("biped", "hand")]
    candidates = [describe_mesh(mesh, preset), *others]
    direction = np.array([0.0, 1.0, 0.0])
    seen = single_view(mesh, direction)
    noisy = with_depth_noise(seen, mesh, direction, 0.5, np.random.default_rng(0))
    clean, query = describe_mesh(seen, preset), describe_mesh(noisy, preset)
    assert query.surface_smoothed and clean.surface_smoothed is False
    assert candidates[0].surface_smoothed is False  # a whole is never
    assert query.surface_unit == pytest.approx(clean.surface_unit, rel=0.02)
    for view in (clean, query):
        fitness = verified_fitness(view, candidates, 1.0, metric=False)
        assert fitness is not None and fitness[0] >= rigid.HELD_FITNESS > max(fitness[1:])


@pytest.mark.parametrize("name", ["quadruped", "hand"])
def test_a_view_fitted_from_view_unit_finds_its_true_scale(name, quadruped_view):
    """A view's unit (both its sides' area) is a share of its object's that the parts'
    scale does not see: fitted on its own pose's whole from ``VIEW_UNIT`` of it, within
    ``SCALE_WINDOW``, the fit holds all of the view at the two units' true ratio."""
    preset = get_preset(DEFAULT_PRESET)
    if name == "quadruped":  # the module's view, from above
        mesh, view = sample_mesh("quadruped", 3), quadruped_view
    else:
        mesh = sample_mesh("hand", 0)
        view = describe_mesh(single_view(mesh, np.array([1.0, 0.0, 0.0])), preset)
    whole = describe_mesh(mesh, preset)
    ratio = view.surface_unit / whole.surface_unit
    assert abs(math.log(ratio / rigid.VIEW_UNIT)) < math.log(rigid.SCALE_WINDOW)
    query = rigid.stored_anchors(view.surface, view.surface_voxel, rigid.VIEW_UNIT)
    window = (1.0 / rigid.SCALE_WINDOW, rigid.SCALE_WINDOW)
    fit = rigid_fit(query, candidate_anchors(whole), ANCHOR_VOXEL, window)
    assert fit.fitness > 0.95
    assert rigid.VIEW_UNIT * fit.scale == pytest.approx(ratio, rel=0.03)


def test_past_the_parts_best_a_view_is_fitted_on_the_closest_features(
    verified_wholes, quadruped_view, monkeypatch
):
    """Of a pool beyond the parts' best ``VERIFIED``, the candidates whose features lie
    closest to the view's are fitted too: with one verified and one picked, the quadruped's
    figure last in the pool is picked by its features, fitted, and ranked first; the two
    between are not fitted and keep their places."""
    quadruped, *others = verified_wholes
    pool = [*others, quadruped]
    monkeypatch.setattr(rigid, "VERIFIED", 1)
    monkeypatch.setattr(rigid, "FEATURE_PICKS", 1)
    fitness = verified_fitness(quadruped_view, pool, 1.0, metric=False)
    assert fitness is not None
    assert np.isnan(fitness[1:-1]).all() and np.isfinite(fitness[[0, -1]]).all()
    assert fitness[-1] > fitness[0] + 0.15, fitness
    np.testing.assert_array_equal(verified_order(fitness), [3, 1, 2, 0])
    # the picks are the features' closest: each candidate's quantile, by the plain sort
    query = rigid.stored_anchors(
        quadruped_view.surface, quadruped_view.surface_voxel, rigid.VIEW_UNIT
    )
    closeness = [
        np.sort(rigid.feature_matches(query, candidate_anchors(c))[1])[
            round(rigid.FEATURE_QUANTILE * (len(query.points) - 1))
        ]
        for c in pool
    ]
    assert int(np.argmin(closeness)) == len(pool) - 1, closeness
