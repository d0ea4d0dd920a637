"""Modal representations: fast paths against plain ones, and their invariances."""

from __future__ import annotations

import numpy as np
import pytest
import tensorly as tl
import trimesh
from tensorly.decomposition import tucker

from worker.engine.diffusion import (
    LaplaceBeltrami,
    diffusion_distance_tensor,
    laplace_beltrami_eigenpairs,
)
from worker.engine.intrinsic import IntrinsicMesh, fem_operators, intrinsic_delaunay
from worker.engine.modal import (
    ddt_core,
    hosvd_core,
    modal_gdm,
    modal_gdm_reference,
    normalize_slices,
    orthonormal_basis,
)

TIMES = (100.0, 200.0, 400.0, 800.0, 1500.0)


def _eigenpairs(k=80):
    sphere = trimesh.creation.icosphere(subdivisions=3)
    rng = np.random.default_rng(7)
    v = sphere.vertices * (1 + 0.2 * rng.random((len(sphere.vertices), 1)))
    mesh = intrinsic_delaunay(IntrinsicMesh.from_mesh(v, sphere.faces))
    return laplace_beltrami_eigenpairs(LaplaceBeltrami.from_fem(fem_operators(mesh)), k)


@pytest.mark.slow  # dense DDTs
def test_low_rank_ddt_core_equals_tensorly_tucker_on_the_full_tensor():
    values, vectors = _eigenpairs()
    full = normalize_slices(diffusion_distance_tensor(values, vectors, TIMES))
    core, _ = tucker(tl.tensor(full), rank=[20, 20, 5], n_iter_max=0, init="svd")
    fast = ddt_core(values, vectors, TIMES, (20, 20, 5))
    assert fast.shape == (20, 20, 5)
    scale = np.abs(core).max()
    # Tiny elements carry no sign information worth comparing.
    np.testing.assert_allclose(fast, np.abs(tl.to_numpy(core)), atol=1e-9 * scale)


@pytest.mark.slow  # dense DDTs
def test_core_is_invariant_to_vertex_order_and_singular_vector_signs():
    values, vectors = _eigenpairs()
    perm = np.random.default_rng(0).permutation(len(vectors))
    flipped = vectors * np.where(np.arange(vectors.shape[1]) % 2, -1.0, 1.0)
    a = ddt_core(values, vectors, TIMES, (20, 20, 5))
    b = ddt_core(values, flipped[perm], TIMES, (20, 20, 5))
    np.testing.assert_allclose(a, b, atol=1e-9 * a.max())
    # Flipping singular vectors of the full tensor flips core slices; |core| does not move.
    full = normalize_slices(diffusion_distance_tensor(values, vectors, TIMES))
    c1 = hosvd_core(full, (6, 6, 3))
    core, factors = tucker(tl.tensor(full), rank=[6, 6, 3], n_iter_max=0, init="svd")
    signs = np.array([1, -1, 1, -1, -1, 1])
    resigned = tl.tenalg.multi_mode_dot(
        tl.tensor(full), [factors[0] * signs, factors[1] * signs, factors[2]], transpose=True
    )
    np.testing.assert_allclose(np.abs(tl.to_numpy(resigned)), c1, atol=1e-10 * c1.max())


def test_modal_gdm_equals_full_svd_and_ignores_order_and_scale():
    rng = np.random.default_rng(1)
    points = rng.random((300, 3))
    gdm = np.linalg.norm(points[:, None] - points[None], axis=2)
    fast = modal_gdm(gdm, 19)
    np.testing.assert_allclose(fast, modal_gdm_reference(gdm, 19), rtol=1e-9)
    assert np.all(np.diff(fast) <= 0)
    perm = rng.permutation(300)
    np.testing.assert_allclose(modal_gdm(7.5 * gdm[perm][:, perm], 19), fast, rtol=1e-9)


def test_normalization_divides_each_slice_by_its_sum_times_n():
    t = np.random.default_rng(2).random((10, 10, 3))
    out = normalize_slices(t)
    np.testing.assert_allclose(out.sum(axis=(0, 1)), [10.0, 10.0, 10.0])
    np.testing.assert_allclose(out[:, :, 1] / t[:, :, 1], 10.0 / t[:, :, 1].sum())


def test_orthonormal_basis_drops_dependent_columns():
    rng = np.random.default_rng(3)
    a = rng.standard_normal((100, 4))
    columns = np.column_stack([a, a[:, 0] + a[:, 1], np.ones(100), np.ones(100)])
    q = orthonormal_basis(columns)
    assert q.shape == (100, 5)
    np.testing.assert_allclose(q.T @ q, np.eye(5), atol=1e-12)
    np.testing.assert_allclose(q @ (q.T @ columns), columns, atol=1e-10)
