"""Modal representations: fast paths against plain ones, and their invariances."""

from __future__ import annotations

import numpy as np
import pytest
import tensorly as tl
import trimesh
from scipy.integrate import quad
from scipy.special import eval_legendre
from tensorly.decomposition import partial_tucker, tucker

from worker.engine.diffusion import (
    LaplaceBeltrami,
    averaged_mass_eigenpairs,
    diffusion_distance_tensor,
    in_diffusion_time_units,
    laplace_beltrami_eigenpairs,
    surface_eigenpairs,
)
from worker.engine.geodesic import farthest_point_samples, sample_distances
from worker.engine.intrinsic import (
    IntrinsicMesh,
    fem_operators,
    intrinsic_delaunay,
    surface_operators,
)
from worker.engine.modal import (
    core_diagonal,
    ddt_core,
    extended_basis,
    hosvd_core,
    modal_gdm,
    modal_gdm_reference,
    normalize_slices,
    orthonormal_basis,
    slice_singular_values,
    small_ddt,
    vertex_modes_core,
    voronoi_areas,
)
from worker.engine.tol import TOL

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


@pytest.mark.parametrize("count", [19, 38, 60, 400])  # LAPACK up to 2k samples, Lanczos above
def test_sampled_gdm_equals_full_svd_and_ignores_order_and_scale(count):
    rng = np.random.default_rng(5)
    points = rng.random((400, 3))
    samples = rng.choice(400, count, replace=False)
    distances = np.linalg.norm(points[:, None] - points[None, samples], axis=2)
    mass = rng.uniform(0.5, 2.0, 400)
    areas = voronoi_areas(distances, mass)
    fast = modal_gdm(distances, 19, mass, areas)
    np.testing.assert_allclose(fast, modal_gdm_reference(distances, 19, mass, areas), rtol=1e-9)
    assert np.all(np.diff(fast) <= 0)
    rows, columns = rng.permutation(400), rng.permutation(count)
    moved = 3.0 * distances[rows][:, columns]
    np.testing.assert_allclose(
        modal_gdm(moved, 19, 9.0 * mass[rows], 9.0 * areas[columns]), fast, rtol=1e-9
    )


def test_voronoi_areas_give_each_vertex_area_to_its_nearest_sample():
    distances = np.array([[0.0, 2.0], [1.0, 3.0], [2.5, 0.5], [4.0, 0.0]])
    np.testing.assert_allclose(voronoi_areas(distances, np.array([1.0, 2.0, 3.0, 4.0])), [3.0, 7.0])


def _funk_hecke_singular_values(k):
    """The geodesic distance operator of the unit sphere, ``arccos(x . y)``, divided by
    area^(3/2): a zonal kernel, so its eigenvalues are ``2 pi int arccos(t) P_l(t) dt``
    with multiplicity ``2 l + 1`` (Funk-Hecke)."""
    values = []
    for degree in range(12):
        integral, _ = quad(
            lambda t, n=degree: np.arccos(t) * eval_legendre(n, t), -1.0, 1.0, limit=200
        )
        values += [abs(2.0 * np.pi * integral)] * (2 * degree + 1)
    return np.sort(values)[::-1][:k] / (4.0 * np.pi) ** 1.5


@pytest.mark.parametrize(
    "sphere",
    [trimesh.creation.icosphere(subdivisions=4), trimesh.creation.uv_sphere(count=[48, 64])],
    ids=["icosphere", "uv-sphere"],
)
def test_sampled_gdm_is_the_spheres_distance_operator_whatever_its_triangles(sphere):
    # The icosphere's triangles are all alike; the UV sphere's crowd at the poles
    # (5,890 vertices). Both give the surface's operator within the quadrature error
    # of 500 samples.
    mesh, ops = surface_operators(sphere.vertices, sphere.faces)
    samples = farthest_point_samples(sphere.vertices, 500, ops.vertex_areas)
    distances = sample_distances(mesh, ops, samples, 12.0, 2500)
    areas = voronoi_areas(distances, ops.vertex_areas)
    np.testing.assert_allclose(areas.sum(), ops.vertex_areas.sum())
    values = modal_gdm(distances, 19, ops.vertex_areas, areas)
    exact = _funk_hecke_singular_values(19)
    assert np.abs(values / exact - 1).max() < 0.03


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


def test_extended_basis_spans_both_blocks_as_the_pivoted_qr_does():
    rng = np.random.default_rng(6)
    first, _ = np.linalg.qr(rng.standard_normal((200, 30)))
    extra = rng.standard_normal((200, 3))
    # A column inside the first block and a repeated one add no direction.
    more = np.column_stack([extra, first @ rng.standard_normal(30), extra[:, 0]])
    q = extended_basis(first, more)
    reference = orthonormal_basis(np.column_stack([first, more]))
    assert q.shape == reference.shape == (200, 33)
    np.testing.assert_array_equal(q[:, :30], first)
    np.testing.assert_allclose(q.T @ q, np.eye(33), atol=1e-13)
    np.testing.assert_allclose(q @ q.T, reference @ reference.T, atol=1e-12)


def _weighted_eigenpairs(k=80):
    """Eigenpairs orthonormal in the lumped-area inner product, and the areas."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    rng = np.random.default_rng(7)
    v = sphere.vertices * (1 + 0.2 * rng.random((len(sphere.vertices), 1)))
    mesh, ops = surface_operators(v, sphere.faces)
    op = LaplaceBeltrami.from_fem(ops)
    values, vectors = laplace_beltrami_eigenpairs(op, k)
    values, functions = surface_eigenpairs(op, values, vectors, 2500)
    return values, functions, ops.vertex_areas


def _dense_weighted_ddt(values, functions, mass) -> np.ndarray:
    """The dense DDT weighted ``M^1/2 D_t M^1/2``, each slice divided by its
    area-weighted mean times the area (what ``ddt_core`` decomposes with ``mass``)."""
    dense = diffusion_distance_tensor(values, functions, TIMES)
    root = np.sqrt(mass)
    weighted = dense * (root[:, None] * root[None, :])[:, :, None]
    weighted *= mass.sum() / np.einsum("i,ijs,j->s", mass, dense, mass)
    return weighted


@pytest.mark.slow  # dense DDTs
def test_area_weighted_core_equals_the_hosvd_of_the_dense_weighted_tensor():
    values, functions, mass = _weighted_eigenpairs()
    # Orthonormal in the areas to ddt_core's tolerance: its basis is the eigenvectors.
    gram = functions.T @ (mass[:, None] * functions)
    np.testing.assert_allclose(gram, np.eye(80), atol=TOL.orthonormal)
    weighted = _dense_weighted_ddt(values, functions, mass)
    expected = hosvd_core(weighted, (20, 20, 5))
    fast = ddt_core(values, functions, TIMES, (20, 20, 5), mass)
    np.testing.assert_allclose(fast, expected, atol=1e-9 * expected.max())


def _vertex_modes_reference(tensor: np.ndarray, rank: int) -> np.ndarray:
    """The partial Tucker in plain numpy: the mode-1 unfolding's leading left singular
    vectors on both vertex modes of every slice (the tensor is symmetric in them)."""
    u = np.linalg.svd(tensor.reshape(len(tensor), -1), full_matrices=False)[0][:, :rank]
    return np.abs(np.einsum("ai,abt,bj->ijt", u, tensor, u))


@pytest.mark.slow  # dense DDTs
def test_vertex_modes_core_of_the_weighted_ddt_equals_the_plain_one():
    values, functions, mass = _weighted_eigenpairs()
    weighted = _dense_weighted_ddt(values, functions, mass)
    expected = _vertex_modes_reference(weighted, 20)
    fast = ddt_core(values, functions, TIMES, (20, 20, 5), mass, mix_times=False)
    assert fast.shape == (20, 20, 5)
    np.testing.assert_allclose(fast, expected, atol=1e-9 * expected.max())
    direct = vertex_modes_core(weighted, (20, 20))
    np.testing.assert_allclose(direct, expected, atol=1e-9 * expected.max())
    # One SVD for both vertex modes: tensorly's partial Tucker takes one per mode.
    (library, _), _ = partial_tucker(
        tl.tensor(weighted), rank=[20, 12], modes=[0, 1], n_iter_max=0, init="svd"
    )
    np.testing.assert_allclose(
        vertex_modes_core(weighted, (20, 12)), np.abs(library), atol=1e-9 * expected.max()
    )
    # Vertex order and eigenvector signs do not move it.
    perm = np.random.default_rng(3).permutation(len(functions))
    flipped = functions * np.where(np.arange(functions.shape[1]) % 2, -1.0, 1.0)
    again = ddt_core(values, flipped[perm], TIMES, (20, 20, 5), mass[perm], mix_times=False)
    np.testing.assert_allclose(again, fast, atol=1e-9 * fast.max())


@pytest.mark.slow  # dense DDTs
def test_slice_values_of_the_small_ddt_are_the_dense_slices_singular_values():
    """Against a plain SVD of every slice of the dense DDT, weighted by area (the
    default's) and as the paper's vertex matrices; vertex order and eigenvector signs
    do not move them."""
    values, functions, mass = _weighted_eigenpairs()
    weighted = _dense_weighted_ddt(values, functions, mass)
    kept = slice_singular_values(small_ddt(values, functions, TIMES, mass), 20)
    paper_values, paper_vectors = _eigenpairs()
    paper = normalize_slices(diffusion_distance_tensor(paper_values, paper_vectors, TIMES))
    for dense, fast in (
        (weighted, kept),
        (paper, slice_singular_values(small_ddt(paper_values, paper_vectors, TIMES), 20)),
    ):
        expected = np.column_stack(
            [np.linalg.svd(dense[:, :, t], compute_uv=False)[:20] for t in range(len(TIMES))]
        )
        assert fast.shape == (20, 5)
        np.testing.assert_allclose(fast, expected, atol=1e-9 * expected.max())
    perm = np.random.default_rng(3).permutation(len(functions))
    flipped = functions * np.where(np.arange(functions.shape[1]) % 2, -1.0, 1.0)
    again = slice_singular_values(small_ddt(values, flipped[perm], TIMES, mass[perm]), 20)
    np.testing.assert_allclose(again, kept, rtol=1e-9)


@pytest.mark.slow  # dense DDTs
def test_slice_values_with_the_averaged_mass_are_the_dense_slices_singular_values():
    """The averaged mass's Ritz vectors, given as coordinates in eq. (3)'s
    eigenfunctions (orthonormal in that mass, not in the lumped areas that weight the
    DDT): the small DDT reuses eq. (3)'s basis, and must give what the dense weighted
    tensor of the Ritz pairs themselves gives, and what the pivoted QR of all the
    columns gives (the path for columns that are not orthonormal)."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    v = sphere.vertices * (1 + 0.2 * np.random.default_rng(7).random((len(sphere.vertices), 1)))
    mesh, ops = surface_operators(v, sphere.faces)
    op = LaplaceBeltrami.from_fem(ops)
    eigenvalues, eigenvectors = laplace_beltrami_eigenpairs(op, 80)
    ritz_values, coordinates = averaged_mass_eigenpairs(op, mesh, ops, eigenvalues, eigenvectors)
    _, basis = surface_eigenpairs(op, eigenvalues, eigenvectors, 2500)
    values = in_diffusion_time_units(ritz_values * op.total_area, 2500)
    functions = basis @ coordinates
    mass = ops.vertex_areas
    lumped_gram = functions.T @ (mass[:, None] * functions)
    assert np.abs(lumped_gram - np.eye(80)).max() > 1e3 * TOL.orthonormal  # not orthonormal
    kept = slice_singular_values(small_ddt(values, basis, TIMES, mass, coordinates), 20)
    dense = _dense_weighted_ddt(values, functions, mass)
    expected = np.column_stack(
        [np.linalg.svd(dense[:, :, t], compute_uv=False)[:20] for t in range(len(TIMES))]
    )
    np.testing.assert_allclose(kept, expected, atol=1e-9 * expected.max())
    fallback = slice_singular_values(small_ddt(values, functions, TIMES, mass), 20)
    np.testing.assert_allclose(fallback, kept, atol=1e-9 * expected.max())


def test_slice_values_do_not_swap_where_the_core_diagonal_does():
    """Two modes whose norms over all times are equal (one larger early, the other
    late, as the two sides of a figure can be): the HOSVD may take any mixture of the
    pair as its factor, and a perturbation of 1e-9 decides which. Tipped towards one
    mode, the core's diagonal holds the slices' own values; tipped towards their
    45-degree mixture, both elements are the mean, a third of the larger one away.
    Each slice's singular values move by the perturbation."""
    basis = np.linalg.qr(np.random.default_rng(11).standard_normal((60, 6)))[0]
    spectra = np.array([[9.0, 1.0, 3.0, 0.5, 0.2, 0.1], [9.0, 3.0, 1.0, 0.4, 0.2, 0.1]])
    tensor = np.stack([basis @ np.diag(d) @ basis.T for d in spectra], axis=2)
    pure, mixed = basis[:, 1], (basis[:, 1] + basis[:, 2]) / np.sqrt(2.0)
    tipped = [tensor + 1e-9 * np.outer(v, v)[:, :, None] for v in (pure, mixed)]
    diagonals = [core_diagonal(vertex_modes_core(t, (4, 4))) for t in tipped]
    np.testing.assert_allclose(diagonals[0][1:3], [[1.0, 3.0], [3.0, 1.0]], atol=1e-6)
    np.testing.assert_allclose(diagonals[1][1:3], [[2.0, 2.0], [2.0, 2.0]], atol=1e-6)
    values = [slice_singular_values(t, 4) for t in tipped]
    np.testing.assert_allclose(values[0], [[9.0, 9.0], [3.0, 3.0], [1.0, 1.0], [0.5, 0.4]])
    np.testing.assert_allclose(values[1], values[0], atol=1e-8)


def test_slice_values_under_rounding_are_raised_to_the_floor():
    """Eigenvalues of 1e-17 and 1e-20 of the largest are whatever rounding makes them;
    both copies of the slice give the floor, so eq. (8) sees no difference."""
    basis = np.linalg.qr(np.random.default_rng(5).standard_normal((30, 4)))[0]
    slice_ = basis @ np.diag([2.0, 1e-3, 1e-17, 1e-20]) @ basis.T
    noise = np.random.default_rng(6).standard_normal((30, 30))
    rounded = slice_ + 1e-16 * (noise + noise.T)
    values = [slice_singular_values(t[:, :, None], 4)[:, 0] for t in (slice_, rounded)]
    floor = 2.0 * TOL.slice_value_floor
    np.testing.assert_allclose(values[0], [2.0, 1e-3, floor, floor], rtol=1e-9)
    np.testing.assert_allclose(values[1][2:], [floor, floor], rtol=1e-12)


def test_vertex_modes_core_keeps_each_time_its_own_slice():
    """Reordering the times reorders the slices of the core and changes nothing else;
    the full HOSVD mixes them, so its slices are other numbers."""
    values, functions, mass = _weighted_eigenpairs(40)
    order = [3, 0, 4, 1, 2]
    shuffled = tuple(TIMES[i] for i in order)
    kept = ddt_core(values, functions, TIMES, (10, 10, 5), mass, mix_times=False)
    again = ddt_core(values, functions, shuffled, (10, 10, 5), mass, mix_times=False)
    np.testing.assert_allclose(again, kept[:, :, order], atol=1e-10 * kept.max())
    mixed = ddt_core(values, functions, TIMES, (10, 10, 5), mass)
    assert not np.allclose(core_diagonal(mixed), core_diagonal(kept), rtol=0.1)


def test_unit_weights_give_the_papers_core():
    # The paper's eigenvectors are orthonormal in its A, not in unit weights: ddt_core
    # must see that and take the pivoted QR, whose core is the paper's.
    values, vectors = _eigenpairs(40)
    assert np.abs(vectors.T @ vectors - np.eye(40)).max() > TOL.orthonormal
    paper = ddt_core(values, vectors, TIMES, (10, 10, 5))
    ones = ddt_core(values, vectors, TIMES, (10, 10, 5), np.ones(len(vectors)))
    np.testing.assert_allclose(ones, paper, atol=1e-10 * paper.max())


def test_area_weighted_gdm_is_the_integral_operator_and_scale_free():
    rng = np.random.default_rng(4)
    points = rng.random((300, 3))
    gdm = np.linalg.norm(points[:, None] - points[None], axis=2)
    mass = rng.uniform(0.5, 2.0, 300)
    fast = modal_gdm(gdm, 19, mass)
    np.testing.assert_allclose(fast, modal_gdm_reference(gdm, 19, mass), rtol=1e-9)
    # Lengths x s and areas x s^2: the same descriptor.
    np.testing.assert_allclose(modal_gdm(3.0 * gdm, 19, 9.0 * mass), fast, rtol=1e-9)
    # Sampling one half of the points twice as densely (each of them split into two
    # half-weight copies) leaves the operator's non-zero eigenvalues unchanged...
    split = np.r_[np.arange(300), np.arange(150)]
    denser = gdm[np.ix_(split, split)]
    weights = np.r_[mass[:150] / 2, mass[150:], mass[:150] / 2]
    np.testing.assert_allclose(modal_gdm(denser, 19, weights), fast, rtol=1e-8)
    # ... while the paper's vertex matrix follows the sampling.
    paper, resampled = modal_gdm(gdm, 19), modal_gdm(denser, 19)
    assert np.abs(resampled / paper - 1).max() > 0.02


def test_core_diagonal_takes_the_elements_on_the_first_two_modes_diagonal():
    core = np.arange(4 * 4 * 3, dtype=float).reshape(4, 4, 3)
    diagonal = core_diagonal(core)
    assert diagonal.shape == (4, 3)
    np.testing.assert_array_equal(diagonal[2], core[2, 2])
