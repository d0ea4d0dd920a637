"""Eq. (3) eigenpairs against a dense solve; eq. (4) truncation; the paper's A and L."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse.linalg as sla
import trimesh

from worker.engine import diffusion
from worker.engine.diffusion import (
    LaplaceBeltrami,
    diffusion_distance_tensor,
    laplace_beltrami_eigenpairs,
    normalized_spectrum,
    surface_eigenpairs,
)
from worker.engine.intrinsic import IntrinsicMesh, fem_operators, intrinsic_delaunay
from worker.engine.mesh_io import load_mesh
from worker.engine.modal import core_diagonal, ddt_core
from worker.engine.presets import get_preset
from worker.engine.resample import resample_mesh


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
def test_eigenpairs_and_ddt_of_a_real_mesh_match_the_dense_solve(tosca_dir):
    """The default preset's k on a resampled TOSCA mesh: the sparse path (Lanczos on
    A^-1/2 L A^-1/2) against eq. (3) solved densely as written, and the DDT core made
    from each."""
    preset = get_preset("smeets2010-surface")
    mesh = resample_mesh(load_mesh(tosca_dir / "dog0.off.gz"), 1000)
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


@pytest.mark.slow  # 400 eigenpairs of a TOSCA mesh
def test_enough_eigenpairs_for_the_shortest_diffusion_time(tosca_dir):
    """Truncating eq. (4) at the preset's k changes the DDT by < 1e-3 at t_D = 100."""
    preset = get_preset("smeets2010-shrec")
    mesh = resample_mesh(load_mesh(tosca_dir / "centaur0.off.gz"), preset.n_vertices)
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
