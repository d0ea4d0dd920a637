"""Eq. (3) eigenpairs against a dense solve; eq. (4) truncation; the paper's A and L."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse.linalg as sla
import trimesh
from conftest import example

from worker.engine import diffusion
from worker.engine.diffusion import (
    LaplaceBeltrami,
    averaged_mass_eigenpairs,
    diffusion_distance_tensor,
    laplace_beltrami_eigenpairs,
    normalized_spectrum,
    surface_eigenpairs,
)
from worker.engine.intrinsic import (
    IntrinsicMesh,
    averaged_mass,
    fem_operators,
    intrinsic_delaunay,
    surface_operators,
)
from worker.engine.mesh_io import load_mesh
from worker.engine.modal import core_diagonal, ddt_core
from worker.engine.presets import get_preset
from worker.engine.resample import resample_mesh
from worker.evaluation.datasets import shared_dataset


def _operator(vertices, faces) -> LaplaceBeltrami:
    return LaplaceBeltrami.from_fem(
        fem_operators(intrinsic_delaunay(IntrinsicMesh.from_mesh(vertices, faces)))
    )


def test_mass_and_weights_follow_the_paper():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    op = _operator(sphere.vertices, sphere.faces)
    mean_area = sphere.area / len(sphere.faces)
    # a_i = 5 / mean area * (sum of the areas of the triangles at i): sum = 15 F.
    assert op.mass.sum() == pytest.approx(15 * len(sphere.faces))
    ring = np.bincount(sphere.faces.ravel(), weights=np.repeat(sphere.area_faces, 3))
    np.testing.assert_allclose(op.mass, 5.0 / mean_area * ring)
    # L = diag(sum w) - w, rows sum to zero.
    assert np.abs(op.laplacian.sum(axis=1)).max() < 1e-10


def test_eigenpairs_match_dense_generalized_solve():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    noisy = sphere.vertices * (1 + 0.1 * np.random.default_rng(3).random((162, 1)))
    op = _operator(noisy, sphere.faces)
    values, vectors = laplace_beltrami_eigenpairs(op, 40)
    dense_values, dense_vectors = la.eigh(op.laplacian.toarray(), np.diag(op.mass))
    np.testing.assert_allclose(values, dense_values[:40], rtol=1e-8, atol=1e-12)
    # A-orthonormal, and the same eigenspaces (compare projectors, robust to signs).
    np.testing.assert_allclose(vectors.T @ (op.mass[:, None] * vectors), np.eye(40), atol=1e-8)
    for i in range(1, 40):
        if (
            min(
                abs(dense_values[i] - dense_values[i - 1]),
                abs(dense_values[i + 1] - dense_values[i]),
            )
            < 1e-6 * dense_values[i]
        ):
            continue  # degenerate eigenvalue: only the eigenspace is defined
        overlap = abs(vectors[:, i] @ (op.mass * dense_vectors[:, i]))
        assert overlap == pytest.approx(1.0, abs=1e-6)


@pytest.mark.slow  # a dense 1,000 x 1,000 generalized eigenproblem
def test_eigenpairs_and_ddt_of_a_figure_match_the_dense_solve():
    """The default preset's k on a resampled example: the sparse path (Lanczos on
    A^-1/2 L A^-1/2) against eq. (3) solved densely as written, and the DDT core made
    from each."""
    preset = get_preset("smeets2010-surface")
    mesh = resample_mesh(load_mesh(example("quadruped-0")), 1000)
    op = _operator(mesh.vertices, mesh.faces)
    k = preset.n_eigenpairs
    values, vectors = laplace_beltrami_eigenpairs(op, k)
    dense_values, dense_vectors = la.eigh(
        op.laplacian.toarray(), np.diag(op.mass), subset_by_index=[0, k - 1]
    )
    np.testing.assert_allclose(values[1:], dense_values[1:], rtol=1e-9)
    np.testing.assert_allclose(vectors.T @ (op.mass[:, None] * vectors), np.eye(k), atol=1e-9)
    # The same eigenspaces: every sparse eigenvector lies in the span of the dense ones.
    inside = dense_vectors.T @ (op.mass[:, None] * vectors)
    np.testing.assert_allclose(np.linalg.norm(inside, axis=0), 1.0, atol=1e-9)
    cores = [
        core_diagonal(
            ddt_core(
                *surface_eigenpairs(op, v, f, preset.n_vertices),
                preset.diffusion_times,
                preset.ddt_core_shape,
                op.mass,
            )
        )
        for v, f in ((values, vectors), (dense_values, dense_vectors))
    ]
    np.testing.assert_allclose(cores[0], cores[1], rtol=1e-8)


@pytest.mark.slow  # 400 eigenpairs of a figure
def test_enough_eigenpairs_for_the_shortest_diffusion_time():
    """Truncating eq. (4) at the preset's k changes the DDT by < 1e-3 at t_D = 100
    (measured on the biped: 1.3e-4)."""
    preset = get_preset("smeets2010-shrec")
    mesh = resample_mesh(load_mesh(example("biped-0")), preset.n_vertices)
    op = _operator(mesh.vertices, mesh.faces)
    values, vectors = laplace_beltrami_eigenpairs(op, 2 * preset.n_eigenpairs)
    t = (min(preset.diffusion_times),)
    full = diffusion_distance_tensor(values, vectors, t)
    k = preset.n_eigenpairs
    truncated = diffusion_distance_tensor(values[:k], vectors[:, :k], t)
    assert np.linalg.norm(truncated - full) / np.linalg.norm(full) < 1e-3


def test_spectrum_is_scale_invariant_and_matches_sphere():
    sphere = trimesh.creation.icosphere(subdivisions=4)
    spectra = []
    for scale in (0.2, 5.0):
        op = _operator(scale * sphere.vertices, sphere.faces)
        values, _ = laplace_beltrami_eigenpairs(op, 12)
        spectra.append(normalized_spectrum(op, values, 8))
    np.testing.assert_allclose(spectra[0], spectra[1], rtol=1e-8)
    # Unit sphere: eigenvalues l(l+1) with multiplicity 2l+1, area 4 pi.
    expected = np.array([2.0] * 3 + [6.0] * 5) * 4 * np.pi
    np.testing.assert_allclose(spectra[0], expected, rtol=0.01)


def test_averaged_mass_is_the_mean_of_lumped_and_consistent():
    """Against the consistent mass assembled face by face from its textbook element
    matrix area/12 * [[2, 1, 1], [1, 2, 1], [1, 1, 2]]."""
    sphere = trimesh.creation.icosphere(subdivisions=1)
    noisy = sphere.vertices * (1 + 0.2 * np.random.default_rng(5).random((len(sphere.vertices), 1)))
    mesh, ops = surface_operators(noisy, sphere.faces)
    consistent = np.zeros((mesh.n_vertices, mesh.n_vertices))
    element = (np.ones((3, 3)) + np.eye(3)) / 12.0
    for face, area in zip(mesh.faces, ops.face_areas, strict=True):
        consistent[np.ix_(face, face)] += area * element
    mass = averaged_mass(mesh, ops.face_areas).toarray()
    np.testing.assert_allclose(mass, 0.5 * (np.diag(ops.vertex_areas) + consistent), atol=1e-15)
    np.testing.assert_allclose(mass.sum(axis=1), ops.vertex_areas, rtol=1e-12)
    assert np.linalg.eigvalsh(mass).min() > 0


def test_averaged_mass_spectrum_is_the_sphere_where_the_lumped_is_not():
    """Unit sphere at the default's 2,500 vertices: the first 48 eigenvalues
    (l = 1..6) within 0.4% of l(l+1) with the averaged mass; the lumped mass is
    more than 1% off at the top."""
    sphere = trimesh.creation.icosphere(subdivisions=4)
    mesh, ops = surface_operators(sphere.vertices, sphere.faces)
    op = LaplaceBeltrami.from_fem(ops)
    values, vectors = laplace_beltrami_eigenpairs(op, 100)
    degrees = np.repeat(np.arange(1, 7), 2 * np.arange(1, 7) + 1)
    exact = degrees * (degrees + 1) * 4 * np.pi
    averaged = averaged_mass_eigenpairs(op, mesh, ops, values, vectors)[0][1:49] * op.total_area
    lumped = normalized_spectrum(op, values, 48)
    assert np.abs(averaged / exact - 1).max() < 0.004
    assert np.abs(lumped / exact - 1).max() > 0.01


def _averaged_mass_full_solve(mesh, ops, count: int) -> np.ndarray:
    """The plain reference: ``K phi = lambda M phi`` with the averaged mass solved
    as written (shift-invert Lanczos on the generalized problem)."""
    area = float(ops.face_areas.sum())
    values = sla.eigsh(
        ops.stiffness.tocsc(),
        k=count + 1,
        M=averaged_mass(mesh, ops.face_areas).tocsc(),
        sigma=-1e-3 * 4 * np.pi / area,
        v0=np.random.default_rng(0).standard_normal(mesh.n_vertices),
    )[0]
    return np.sort(values)[1:] * area


def _ritz_reference(stiffness, mass, basis) -> np.ndarray:
    """Rayleigh-Ritz values as written: both small matrices formed from ``basis``."""
    small_stiffness = basis.T @ (stiffness @ basis)
    small_mass = basis.T @ (mass @ basis)
    return la.eigh(
        0.5 * (small_stiffness + small_stiffness.T),
        0.5 * (small_mass + small_mass.T),
        eigvals_only=True,
    )


def test_ritz_reference_is_the_dense_solve_on_the_whole_space():
    """With a basis of every vertex the Ritz values are the problem's eigenvalues."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    noisy = sphere.vertices * (1 + 0.1 * np.random.default_rng(3).random((162, 1)))
    mesh, ops = surface_operators(noisy, sphere.faces)
    mass = averaged_mass(mesh, ops.face_areas)
    basis = np.random.default_rng(4).standard_normal((mesh.n_vertices, mesh.n_vertices))
    dense = la.eigh(ops.stiffness.toarray(), mass.toarray(), eigvals_only=True)
    ritz = _ritz_reference(ops.stiffness, mass, basis)
    np.testing.assert_allclose(ritz, dense, rtol=1e-7, atol=1e-10)


@pytest.mark.parametrize(
    "source",
    [
        pytest.param(None, id="noisy sphere"),
        pytest.param(example("spider-0"), id="spider-0"),
        *(
            pytest.param(
                shared_dataset("tosca") / name, id=name, marks=pytest.mark.dataset("tosca")
            )
            for name in ("centaur3.off.gz", "david0.off.gz")
        ),
    ],
)
def test_averaged_mass_eigenpairs_match_their_full_solve(source):
    """The default's optimized path (Ritz pairs in the span of eq. (3)'s 100
    eigenvectors) against the full averaged-mass eigenproblem: within 0.5% for the
    50 eigenvalues the spectrum keeps (measured 0.13% at the 50th on a TOSCA cat);
    the vectors orthonormal in the averaged mass and Ritz vectors of the pair. On an
    example (the spider's thin legs) and on two TOSCA files."""
    preset = get_preset("smeets2010-surface")
    if source is None:
        sphere = trimesh.creation.icosphere(subdivisions=4)
        rng = np.random.default_rng(6)
        vertices = sphere.vertices * (1 + 0.05 * rng.random((len(sphere.vertices), 1)))
        faces = sphere.faces
    else:
        resampled = resample_mesh(load_mesh(source), preset.n_vertices)
        vertices, faces = resampled.vertices, resampled.faces
    mesh, ops = surface_operators(vertices, faces)
    op = LaplaceBeltrami.from_fem(ops)
    values, vectors = laplace_beltrami_eigenpairs(op, preset.n_eigenpairs)
    ritz_values, coordinates = averaged_mass_eigenpairs(op, mesh, ops, values, vectors)
    ritz_vectors = np.sqrt(op.fem_scale) * vectors @ coordinates
    spectrum = ritz_values[1 : preset.spectrum_size + 1] * op.total_area
    mass = averaged_mass(mesh, ops.face_areas)
    gram = ritz_vectors.T @ (mass @ ritz_vectors)
    np.testing.assert_allclose(gram, np.eye(len(gram)), atol=1e-10)
    # Galerkin orthogonality: the residual K v - mu M v is orthogonal to the span.
    residual = ops.stiffness @ ritz_vectors - (mass @ ritz_vectors) * ritz_values
    scale = np.abs(ops.stiffness @ ritz_vectors).max()
    assert np.abs(vectors.T @ residual).max() < 1e-8 * scale * np.abs(vectors).max()
    assert ritz_values[0] == pytest.approx(0.0, abs=1e-10 * ritz_values[1])
    np.testing.assert_allclose(np.ptp(ritz_vectors[:, 0]), 0.0, atol=1e-10)  # constant
    # Eq. (3) makes the small stiffness matrix diagonal: the same as forming it.
    ritz = _ritz_reference(ops.stiffness, mass, vectors)
    np.testing.assert_allclose(
        spectrum, ritz[1 : preset.spectrum_size + 1] * op.total_area, rtol=1e-9
    )
    reference = _averaged_mass_full_solve(mesh, ops, preset.spectrum_size)
    np.testing.assert_allclose(spectrum, reference, rtol=5e-3)
    assert np.all(spectrum >= reference * (1 - 1e-9))  # Ritz values bound from above


def test_diffusion_distances_are_symmetric_and_shrink_with_time():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    op = _operator(sphere.vertices, sphere.faces)
    values, vectors = laplace_beltrami_eigenpairs(op, 60)
    ddt = diffusion_distance_tensor(values, vectors, (100.0, 400.0, 1500.0))
    assert ddt.shape == (162, 162, 3)
    np.testing.assert_allclose(ddt, ddt.transpose(1, 0, 2), atol=1e-15)
    assert np.all(ddt[:, :, 0].sum() > ddt[:, :, 1].sum() > ddt[:, :, 2].sum())


def test_dense_solver_answers_when_arpack_gives_up(monkeypatch):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    op = _operator(sphere.vertices, sphere.faces)
    expected, _ = laplace_beltrami_eigenpairs(op, 30)

    def give_up(*args, **kwargs):
        raise sla.ArpackError(-9999)

    monkeypatch.setattr(diffusion.sla, "eigsh", give_up)
    values, vectors = laplace_beltrami_eigenpairs(op, 30)
    assert abs(values[0]) < 1e-9 * values[1]
    np.testing.assert_allclose(values[1:], expected[1:], rtol=1e-8)
    gram = vectors.T @ (op.mass[:, None] * vectors)
    np.testing.assert_allclose(gram, np.eye(30), atol=1e-8)


def test_shift_sits_below_the_spectrum_at_any_scale():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    small = _operator(1e-3 * sphere.vertices, sphere.faces)
    large = _operator(1e3 * sphere.vertices, sphere.faces)
    values, _ = laplace_beltrami_eigenpairs(large, 5)
    # The paper's (L, A) is scale-free (A's constant is 5 / mean triangle area).
    assert small.shift() == pytest.approx(large.shift())
    assert -1e-2 * values[1] < large.shift() < 0.0
