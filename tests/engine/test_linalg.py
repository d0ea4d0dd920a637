"""The banded Cholesky solver against SuperLU."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import trimesh

from worker.engine.intrinsic import IntrinsicMesh, fem_operators, intrinsic_delaunay
from worker.engine.linalg import BandedCholesky, band_ordering


def _random_spd(n: int, density: float, seed: int) -> sp.csc_matrix:
    rng = np.random.default_rng(seed)
    a = sp.random(n, n, density=density, random_state=rng)
    a = a + a.T
    return (a + sp.diags(np.abs(a).sum(axis=1).A1 + 1.0)).tocsc()


def test_random_spd_matrices_match_superlu():
    for seed, n in enumerate([1, 5, 70, 300]):
        a = _random_spd(n, 0.05, seed)
        rhs = np.random.default_rng(seed).standard_normal((n, 7))
        expected = sla.splu(a).solve(rhs)
        solver = BandedCholesky(a)
        np.testing.assert_allclose(solver.solve(rhs), expected, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(solver.solve(rhs[:, 0]), expected[:, 0], rtol=1e-10, atol=1e-12)


def test_mesh_heat_operator_matches_superlu():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    mesh = intrinsic_delaunay(IntrinsicMesh.from_mesh(sphere.vertices, sphere.faces))
    ops = fem_operators(mesh)
    a = (sp.diags(ops.vertex_areas) + mesh.mean_edge_length**2 * ops.stiffness).tocsc()
    rhs = np.eye(a.shape[0])[:, :200]
    solver = BandedCholesky(a)
    assert solver.bandwidth < a.shape[0] // 4  # RCM made it banded
    np.testing.assert_allclose(solver.solve(rhs), sla.splu(a).solve(rhs), rtol=1e-9, atol=1e-12)


def test_single_precision_solves_agree_to_single_precision():
    a = _random_spd(200, 0.05, 9)
    rhs = np.random.default_rng(9).standard_normal((200, 5))
    solver = BandedCholesky(a, dtype=np.float32)
    x = solver.solve(rhs)
    assert x.dtype == np.float32
    np.testing.assert_allclose(x, sla.splu(a).solve(rhs), rtol=1e-4, atol=1e-5)


def test_a_given_ordering_is_used_and_solves_the_same():
    a = _random_spd(300, 0.02, 4)
    rhs = np.random.default_rng(4).standard_normal((300, 3))
    reverse = np.arange(300)[::-1]
    solver = BandedCholesky(a, order=reverse)
    np.testing.assert_array_equal(solver.perm, reverse)
    np.testing.assert_allclose(solver.solve(rhs), sla.splu(a).solve(rhs), rtol=1e-10, atol=1e-12)
    # The heat step's two systems share their sparsity, so the heat factor's ordering
    # is the Poisson one's own.
    sphere = trimesh.creation.icosphere(subdivisions=3)
    mesh = intrinsic_delaunay(IntrinsicMesh.from_mesh(sphere.vertices, sphere.faces))
    ops = fem_operators(mesh)
    mass = sp.diags(ops.vertex_areas)
    heat = BandedCholesky((mass + 0.01 * ops.stiffness).tocsc())
    poisson = BandedCholesky((ops.stiffness + 1e-6 * mass).tocsc())
    np.testing.assert_array_equal(heat.perm, poisson.perm)


def test_band_ordering_is_the_factors_and_a_fan_keeps_the_band_wide():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    mesh = intrinsic_delaunay(IntrinsicMesh.from_mesh(sphere.vertices, sphere.faces))
    a = fem_operators(mesh).stiffness + sp.identity(sphere.vertices.shape[0])
    order, width = band_ordering(a)
    solver = BandedCholesky(a)
    np.testing.assert_array_equal(order, solver.perm)
    assert width == solver.bandwidth
    # A centre joined to every vertex of a ring (a CAD cap's fan) sits in the middle
    # of any ordering: its row spans half the matrix whatever RCM does.
    n = 401
    ring = np.arange(1, n)
    rows = np.r_[np.zeros(n - 1, int), ring, ring[:-1]]
    cols = np.r_[ring, np.zeros(n - 1, int), ring[1:]]
    fan = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, fan_width = band_ordering(fan + fan.T + 4 * n * sp.identity(n))
    assert fan_width >= (n - 1) // 2
