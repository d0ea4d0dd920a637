"""Closing small holes: which loops close, and the closed surface is a clean one."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from worker.engine.holes import close_small_holes
from worker.engine.mesh_io import Mesh, clean_mesh, face_areas
from worker.engine.topology import euler_and_boundary


def area(mesh: Mesh) -> float:
    return float(face_areas(mesh.vertices, mesh.faces).sum())


def topology(mesh: Mesh) -> tuple[int, int]:
    """Euler characteristic and number of boundary edges."""
    return euler_and_boundary(mesh.faces, mesh.n_vertices)


def consistently_oriented(mesh: Mesh) -> bool:
    """Every directed edge is used once, so neighbouring faces agree on orientation."""
    faces = mesh.faces
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return len(np.unique(directed, axis=0)) == len(directed)


@pytest.fixture(scope="module")
def sphere() -> Mesh:
    s = trimesh.creation.icosphere(subdivisions=4)
    return clean_mesh(s.vertices, s.faces)


def without_caps(mesh: Mesh, *centres: np.ndarray, radius: float) -> Mesh:
    """``mesh`` without the faces whose centroid is within ``radius`` of a centre."""
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    keep = np.ones(mesh.n_faces, dtype=bool)
    for centre in centres:
        keep &= np.linalg.norm(centroids - centre, axis=1) > radius
    return clean_mesh(mesh.vertices, mesh.faces[keep])


def test_small_holes_close_into_the_surface_they_cut(sphere):
    north, east = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    holed = without_caps(sphere, north, east, radius=0.15)
    assert topology(holed)[0] == 0  # two boundaries

    closed = close_small_holes(holed, 0.5)

    assert closed.n_vertices == holed.n_vertices + 2
    assert topology(closed) == (2, 0)
    assert consistently_oriented(holed) and consistently_oriented(closed)
    # The fans' apexes are the loops' centroids, on the axes through the caps.
    apexes = closed.vertices[holed.n_vertices :]
    for apex, axis in zip(sorted(apexes, key=lambda p: p[2]), (east, north), strict=True):
        assert np.linalg.norm(np.cross(apex, axis)) < 0.01
    # The fans give back the area the caps took, to 0.3% of the whole.
    assert abs(area(closed) - area(sphere)) < 0.003 * area(sphere)
    assert np.array_equal(closed.vertices[: holed.n_vertices], holed.vertices)


def test_long_openings_stay_open(sphere):
    """A hemisphere (a bowl) and an open tube: their rims are 2.5 and 1.8 square roots
    of their areas long, openings of the object rather than gaps."""
    southern = sphere.vertices[sphere.faces].mean(axis=1)[:, 2] < 0
    bowl = clean_mesh(sphere.vertices, sphere.faces[southern])
    tube = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=48)
    side = np.abs(tube.face_normals[:, 2]) < 0.5
    tube = clean_mesh(tube.vertices, tube.faces[side])
    for mesh in (bowl, tube):
        assert topology(mesh)[1] > 0
        assert close_small_holes(mesh, 0.5) is mesh
    # With a larger bound the tube's two ends close into a capped cylinder.
    capped = close_small_holes(tube, 2.0)
    assert topology(capped) == (2, 0)


def test_only_loops_under_the_bound_close(sphere):
    """A rim 0.2-0.3 square roots of the area long closes, one of 1.1-1.2 does not,
    unless the caller's area makes the bound (0.5 of its square root) longer."""
    small, large = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])
    holed = without_caps(without_caps(sphere, small, radius=0.12), large, radius=0.45)

    closed = close_small_holes(holed, 0.5)

    assert closed.n_vertices == holed.n_vertices + 1
    assert closed.vertices[-1][2] > 0  # the small one's centroid, at the north pole
    large_rim = topology(without_caps(sphere, large, radius=0.45))[1]
    assert topology(closed) == (1, large_rim)
    assert topology(close_small_holes(holed, 0.5, area=9 * area(holed))) == (2, 0)


def test_a_closed_surface_is_returned_as_it_is(sphere):
    assert close_small_holes(sphere, 0.5) is sphere


def test_two_holes_touching_at_a_vertex_stay_open(sphere):
    """A boundary that passes twice through one vertex is not one loop; a single fan
    over it would fold, so it is left open."""
    faces = sphere.faces
    vertex = 0
    around = np.flatnonzero((faces == vertex).any(axis=1))
    first = around[0]
    # A second face at the vertex that shares no edge with the first.
    second = next(f for f in around[1:] if len(set(faces[f]) & set(faces[first])) == 1)
    holed = clean_mesh(sphere.vertices, np.delete(faces, [first, second], axis=0))
    assert close_small_holes(holed, 0.5) is holed
