"""Resampling to the preset's vertex count: near the target, same surface, clean result."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from worker.engine.mesh_io import Mesh, clean_mesh
from worker.engine.resample import resample_mesh
from worker.engine.topology import euler_and_boundary, unique_rows


def area(mesh: Mesh) -> float:
    return float(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).area)


def assert_clean(mesh: Mesh) -> None:
    """Every vertex used, no degenerate or repeated face, finite coordinates."""
    assert np.isfinite(mesh.vertices).all()
    assert np.array_equal(np.unique(mesh.faces), np.arange(mesh.n_vertices))
    assert (mesh.faces[:, 0] != mesh.faces[:, 1]).all()
    assert (mesh.faces[:, 1] != mesh.faces[:, 2]).all()
    assert (mesh.faces[:, 2] != mesh.faces[:, 0]).all()
    first, _ = unique_rows(np.sort(mesh.faces, axis=1))
    assert len(first) == mesh.n_faces


@pytest.fixture(scope="module")
def sphere() -> Mesh:
    s = trimesh.creation.icosphere(subdivisions=5)  # 10,242 vertices
    return clean_mesh(s.vertices, s.faces)


@pytest.mark.parametrize("target", [500, 2500])
def test_decimation_lands_near_the_target(sphere, target):
    out = resample_mesh(sphere, target)
    # quadric decimation stops on a face budget: a few percent at most
    assert abs(out.n_vertices - target) <= 0.03 * target, out.n_vertices
    assert_clean(out)
    # a closed sphere stays a closed sphere, of about the same area
    assert euler_and_boundary(out.faces, out.n_vertices) == (2, 0)
    assert area(out) == pytest.approx(area(sphere), rel=0.02)


def test_a_small_mesh_is_subdivided_without_changing_its_surface():
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))  # 8 vertices, 18 edges, 12 faces
    mesh = clean_mesh(box.vertices, box.faces)
    out = resample_mesh(mesh, 8 + 18)  # one midpoint subdivision is exactly the target
    assert out.n_vertices == 26 and out.n_faces == 4 * 12
    assert area(out) == pytest.approx(area(mesh), rel=1e-12)
    assert_clean(out)
    # past one subdivision, decimation brings the refined box to the target
    refined = resample_mesh(mesh, 60)
    assert abs(refined.n_vertices - 60) <= 3
    assert area(refined) == pytest.approx(22.0, rel=1e-9)  # a box's faces stay flat
    assert_clean(refined)
