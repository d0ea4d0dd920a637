"""Intrinsic Delaunay flips and the finite-element operators built from edge lengths."""

from __future__ import annotations

import numpy as np
import pytest
import robust_laplacian
import trimesh
from conftest import example

from worker.engine.intrinsic import IntrinsicMesh, fem_operators, intrinsic_delaunay, mollify
from worker.engine.mesh_io import load_mesh
from worker.engine.resample import resample_mesh
from worker.engine.topology import edge_keys, euler_and_boundary


def _edge_cotan_sums(mesh: IntrinsicMesh) -> np.ndarray:
    keys = edge_keys(mesh.faces, mesh.n_vertices).ravel()
    _, inverse = np.unique(keys, return_inverse=True)
    return np.bincount(inverse, weights=mesh.corner_cotangents().ravel())


def _cotan_laplacian_reference(vertices, faces) -> np.ndarray:
    """Dense textbook cotangent Laplacian, (cot a + cot b) / 2 weights, one loop per face."""
    n = len(vertices)
    lap = np.zeros((n, n))
    for f in faces:
        for c in range(3):
            i, j, k = f[c], f[(c + 1) % 3], f[(c + 2) % 3]
            u, v = vertices[j] - vertices[i], vertices[k] - vertices[i]
            cot = u @ v / np.linalg.norm(np.cross(u, v))
            for a, b in ((j, k),):
                lap[a, b] -= cot / 2
                lap[b, a] -= cot / 2
                lap[a, a] += cot / 2
                lap[b, b] += cot / 2
    return lap


def test_stiffness_equals_textbook_cotangent_laplacian():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    ops = fem_operators(IntrinsicMesh.from_mesh(mesh.vertices, mesh.faces))
    expected = _cotan_laplacian_reference(mesh.vertices, mesh.faces)
    np.testing.assert_allclose(ops.stiffness.toarray(), expected, atol=1e-12)
    assert ops.vertex_areas.sum() == pytest.approx(mesh.area)
    assert ops.face_areas.sum() == pytest.approx(mesh.area)


@pytest.fixture(scope="module")
def decimated():
    return resample_mesh(load_mesh(example("quadruped-0")), 1000)


def test_flips_keep_the_surface_and_remove_obtuse_pairs(decimated):
    before = IntrinsicMesh.from_mesh(decimated.vertices, decimated.faces)
    after = intrinsic_delaunay(before)
    assert after.face_areas.sum() == pytest.approx(before.face_areas.sum(), rel=1e-12)
    assert len(after.faces) == len(before.faces)
    n_bad_before = np.count_nonzero(_edge_cotan_sums(before) < -1e-9)
    n_bad_after = np.count_nonzero(_edge_cotan_sums(after) < -1e-9)
    assert n_bad_before > 50
    # Only flips that would duplicate an existing edge are skipped.
    assert n_bad_after <= 0.01 * n_bad_before


def test_a_triangle_with_two_equally_violating_edges_loses_only_one_per_round():
    # A tall isosceles triangle ABC whose two long sides each face a vertex just
    # across them, mirrored: both sides are non-Delaunay by exactly the same amount
    # (the ties of symmetric meshes, a cylinder's fans). Flipping both in one round
    # gave four faces to one edge and a boundary that was not there.
    offset = 0.2 * np.array([-3.0, 1.0]) / np.sqrt(10.0)
    d = np.array([-0.5, 1.5]) + offset
    e = d * [-1.0, 1.0]
    vertices = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, 3.0], d, e])
    vertices = np.column_stack([vertices, np.zeros(5)])
    faces = np.array([[0, 1, 2], [0, 2, 3], [2, 1, 4]])
    before = IntrinsicMesh.from_mesh(vertices, faces)
    sums = _edge_cotan_sums(before)
    assert np.count_nonzero(sums < -1e-9) == 2
    assert sorted(sums)[0] == sorted(sums)[1]  # the premise: an exact tie
    after = intrinsic_delaunay(before)
    assert euler_and_boundary(after.faces, 5) == euler_and_boundary(faces, 5)
    keys = edge_keys(after.faces, 5).ravel()
    assert np.bincount(np.unique(keys, return_inverse=True)[1]).max() <= 2
    assert after.face_areas.sum() == pytest.approx(before.face_areas.sum(), rel=1e-12)
    assert np.count_nonzero(_edge_cotan_sums(after) < -1e-9) == 0


def test_matches_robust_laplacian_where_every_flip_was_possible(decimated):
    after = intrinsic_delaunay(IntrinsicMesh.from_mesh(decimated.vertices, decimated.faces))
    ops = fem_operators(after)
    lap, mass = robust_laplacian.mesh_laplacian(
        decimated.vertices, decimated.faces, mollify_factor=0.0
    )
    diff = abs(lap - ops.stiffness).tocsr()
    rows_off = np.unique(diff.nonzero()[0][diff.data > 1e-8])
    # The Delaunay triangulation is unique, so the two agree except around the few
    # edges whose flip we skip (robust-laplacian allows multi-edges there).
    assert len(rows_off) <= 0.03 * decimated.n_vertices
    same = np.setdiff1d(np.arange(decimated.n_vertices), rows_off)
    np.testing.assert_allclose(ops.vertex_areas[same], mass.diagonal()[same], rtol=1e-8)


def test_gradient_of_linear_function_is_exact():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    intrinsic = IntrinsicMesh.from_mesh(mesh.vertices, mesh.faces)
    ops = fem_operators(intrinsic)
    # A linear function of 3-D position has, in each face, the tangential part of
    # its gradient: |grad| = |a projected on the face plane|.
    a = np.array([0.3, -1.2, 0.7])
    g = ops.gradient @ (mesh.vertices @ a)
    m = len(mesh.faces)
    norms = np.hypot(g[:m], g[m:])
    normals = mesh.face_normals
    tangential = a - (normals @ a)[:, None] * normals
    np.testing.assert_allclose(norms, np.linalg.norm(tangential, axis=1), rtol=1e-9)


def test_mollification_bounds_needles_and_leaves_good_triangles_alone():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    good = IntrinsicMesh.from_mesh(sphere.vertices, sphere.faces)
    assert mollify(good) is good
    # A strip of two triangles whose shared vertex sits 1e-10 off the long edge: a
    # needle whose cotangent (1e10) no flip can remove (the flip's diagonal exists).
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1e-10, 0], [0.5, -1, 0], [0.5, 1, 0]])
    faces = np.array([[0, 1, 2], [1, 0, 3], [0, 2, 4], [2, 1, 4]])
    needle = IntrinsicMesh.from_mesh(vertices, faces)
    assert needle.corner_cotangents().max() > 1e9
    fixed = mollify(needle)
    shift = fixed.lengths - needle.lengths
    assert np.allclose(shift, shift.flat[0]) and 0 < shift.flat[0] <= 1e-4
    assert fixed.corner_cotangents().max() < 1e6
