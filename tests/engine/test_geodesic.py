"""GDM accuracy against exact geodesics, and the fast path against the plain one.

Target (issue 2): median relative error <= 2% against exact geodesics.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as sla
import trimesh
from conftest import example, swept_tube

from worker.engine.geodesic import (
    MAX_BANDWIDTH,
    HeatMethod,
    farthest_point_samples,
    geodesic_distance_matrix,
    geodesic_distances_reference,
    heat_time,
    sample_distances,
)
from worker.engine.intrinsic import (
    IntrinsicMesh,
    fem_operators,
    intrinsic_delaunay,
    surface_operators,
)
from worker.engine.linalg import BandedCholesky
from worker.engine.mesh_io import clean_mesh, load_mesh
from worker.engine.resample import resample_mesh

MEDIAN_RELATIVE_ERROR = 0.02


def _gdm(vertices, faces):
    mesh = intrinsic_delaunay(IntrinsicMesh.from_mesh(vertices, faces))
    ops = fem_operators(mesh)
    return mesh, ops, geodesic_distance_matrix(mesh, ops)


def _relative_errors(estimate, exact):
    mask = exact > 1e-9
    return np.abs(estimate[mask] - exact[mask]) / exact[mask]


@pytest.mark.slow  # all-source geodesics
def test_sphere_great_circle_distances():
    sphere = trimesh.creation.icosphere(subdivisions=4)  # 2,562 vertices
    _, _, gdm = _gdm(sphere.vertices, sphere.faces)
    unit = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    exact = np.arccos(np.clip(unit @ unit.T, -1.0, 1.0))
    errors = _relative_errors(gdm, exact)
    assert np.median(errors) <= MEDIAN_RELATIVE_ERROR
    assert np.percentile(errors, 95) <= 0.05
    assert np.allclose(gdm, gdm.T)
    assert np.all(np.diag(gdm) == 0)


@pytest.mark.slow  # all-source geodesics
def test_tosca_mesh_against_exact_mmp(tosca_dir):
    pygeodesic = pytest.importorskip("pygeodesic.geodesic")
    mesh = resample_mesh(load_mesh(tosca_dir / "centaur0.off.gz"), 2500)
    _, _, gdm = _gdm(mesh.vertices, mesh.faces)
    exact_solver = pygeodesic.PyGeodesicAlgorithmExact(mesh.vertices, mesh.faces.astype(np.int32))
    sources = np.random.default_rng(0).choice(mesh.n_vertices, size=12, replace=False)
    errors = []
    for s in sources:
        exact, _ = exact_solver.geodesicDistances(np.array([s]), None)
        errors.append(_relative_errors(gdm[s], exact))
    errors = np.concatenate(errors)
    assert np.median(errors) <= MEDIAN_RELATIVE_ERROR


@pytest.mark.slow  # all-source geodesics
def test_fast_path_equals_per_source_reference():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    noisy = sphere.vertices * (1 + 0.05 * np.random.default_rng(1).random((642, 1)))
    mesh, ops, fast = _gdm(noisy, sphere.faces)
    reference = geodesic_distances_reference(mesh, ops)
    # The fast path's Poisson step runs in single precision (float32 eps 6e-8).
    np.testing.assert_allclose(fast, reference, rtol=1e-5, atol=1e-6 * reference.max())


def test_distances_stay_finite_along_a_long_thin_tube():
    """Issue 9: along a tube about 950 edge lengths long, the heat step with t = h^2
    underflowed to zero halfway, and the distances became NaN and 1e145."""
    length = 12.0
    axis = np.linspace(0.0, length, 956)[:, None] * np.array([[0.0, 0.0, 1.0]])
    vertices, faces = swept_tube(axis, radius=0.01, sides=5)
    mesh, ops = surface_operators(vertices, faces)
    near_cap, far_cap = len(vertices) - 2, len(vertices) - 1
    distances = HeatMethod(mesh, ops).distances_from(np.array([near_cap]))[:, 0]
    assert np.all(np.isfinite(distances))
    assert distances[far_cap] == pytest.approx(length, rel=0.01)
    assert np.all(np.diff(distances[: len(axis) * 5 : 5]) > 0)  # down the axis, ring by ring


def test_heat_time_in_surface_units_ignores_the_triangulation():
    uniform = trimesh.creation.icosphere(subdivisions=4)
    polar = trimesh.creation.uv_sphere(count=[48, 48])  # dense at the poles
    times, mesh_times = [], []
    for sphere in (uniform, polar):
        mesh, ops = surface_operators(sphere.vertices, sphere.faces)
        times.append(heat_time(mesh, ops, 12.0, n_reference=2500))
        mesh_times.append(heat_time(mesh, ops, 12.0))
    assert times[0] == pytest.approx(times[1], rel=0.01)
    assert abs(mesh_times[0] / mesh_times[1] - 1) > 0.1


def test_sample_distances_are_the_gdms_columns():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    noisy = sphere.vertices * (1 + 0.05 * np.random.default_rng(2).random((642, 1)))
    mesh, ops = surface_operators(noisy, sphere.faces)
    samples = farthest_point_samples(noisy, 50, ops.vertex_areas)
    columns = sample_distances(mesh, ops, samples, 12.0, 2500)
    assert columns.shape == (642, 50)
    np.testing.assert_array_equal(columns[samples, np.arange(50)], 0.0)
    # The plain solver (SuperLU, double precision), one source at a time.
    plain = HeatMethod(mesh, ops, 12.0, 2500, reference=True)
    reference = np.column_stack([plain.distances_from(np.array([c]))[:, 0] for c in samples])
    np.testing.assert_allclose(columns, reference, rtol=1e-5, atol=1e-6 * reference.max())


def test_farthest_point_samples_cover_the_surface_whatever_the_vertex_order():
    sphere = trimesh.creation.uv_sphere(count=[48, 64])  # vertices crowd at the poles
    mesh, ops = surface_operators(sphere.vertices, sphere.faces)
    samples = farthest_point_samples(sphere.vertices, 200, ops.vertex_areas)
    assert len(np.unique(samples)) == 200
    # Evenly spread: every vertex is near a sample, at about the spacing of 200 points
    # on the unit sphere (sqrt(4 pi / 200) = 0.25), and so are the crowded poles.
    unit = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    gaps = np.arccos(np.clip(unit @ unit[samples].T, -1.0, 1.0)).min(axis=1)
    assert gaps.max() < 0.25
    # A surface without symmetries (a sphere's points tie for the farthest): the same
    # samples whatever the vertex order.
    rng = np.random.default_rng(3)
    bumpy = sphere.vertices * (1 + 0.05 * rng.random((len(sphere.vertices), 1)))
    first = farthest_point_samples(bumpy, 200, ops.vertex_areas)
    order = rng.permutation(len(bumpy))
    moved = farthest_point_samples(bumpy[order], 200, ops.vertex_areas[order])
    np.testing.assert_array_equal(order[moved], first)
    assert np.array_equal(
        farthest_point_samples(sphere.vertices, 10**6, ops.vertex_areas),
        np.arange(len(sphere.vertices)),
    )
    # The definition, plainly: each next sample is the vertex farthest from all before.
    distances = np.linalg.norm(bumpy[:, None] - bumpy[None, first], axis=2)
    for i in range(1, len(first)):
        assert first[i] == np.argmax(distances[:, :i].min(axis=1))


def test_a_wide_band_takes_superlu_and_a_resampled_figure_the_banded_factor():
    """A CAD cylinder's cap fans (512 triangles round one vertex) leave the heat
    system's band wider than MAX_BANDWIDTH, where the banded factor costs far more
    than SuperLU (docs/benchmarks.md); the distances are then the reference path's."""
    c = trimesh.creation.cylinder(radius=0.5, height=2.0, sections=512)
    fan = clean_mesh(c.vertices, c.faces)
    figure = resample_mesh(load_mesh(example("quadruped-0")), 2500)
    for mesh, wide in ((fan, True), (figure, False)):
        intrinsic, ops = surface_operators(mesh.vertices, mesh.faces)
        solver = HeatMethod(intrinsic, ops, 12.0, 2500)
        assert isinstance(solver._heat, sla.SuperLU if wide else BandedCholesky)
        sources = np.array([0, 7, mesh.n_vertices - 1])
        expected = HeatMethod(intrinsic, ops, 12.0, 2500, reference=True).distances_from(sources)
        got = solver.distances_from(sources)
        if wide:
            np.testing.assert_array_equal(got, expected)
        else:
            assert solver._heat.bandwidth <= MAX_BANDWIDTH
            np.testing.assert_allclose(got, expected, rtol=1e-3, atol=1e-3 * expected.max())
