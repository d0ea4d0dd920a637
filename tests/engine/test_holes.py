"""Closing small holes: which loops close, and the closed surface is a clean one; how
much of a surface faces one way (one view of a scanner); a view glued to its image."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from tests.conftest import example
from worker.engine.descriptor import ONE_VIEW_FACING
from worker.engine.geodesic import farthest_point_samples
from worker.engine.holes import (
    close_small_holes,
    facing_share,
    fibonacci_directions,
    sheets_apart,
    two_sided,
)
from worker.engine.mesh_io import Mesh, clean_mesh, face_areas, load_mesh
from worker.engine.topology import euler_and_boundary
from worker.evaluation.partial import planar_cut, random_direction, single_view


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


# ------------------------------------------------------------ facing one way


def facing_share_reference(mesh: Mesh, directions: int = 20_000) -> float:
    """The largest area share facing one of ``directions`` spread over the sphere, by
    direct sums."""
    v, f = mesh.vertices, mesh.faces
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    weights = np.linalg.norm(normals, axis=1)
    lattice = fibonacci_directions(directions)
    best = 0.0
    for start in range(0, directions, 500):
        facing = normals @ lattice[start : start + 500].T > 0.0
        best = max(best, float((weights @ facing).max() / weights.sum()))
    return best


def height_field(rng: np.random.Generator, size: int = 30) -> Mesh:
    """A rough grid of heights, its squares cut in two: every face faces up."""
    x, y = np.meshgrid(np.arange(size, dtype=float), np.arange(size, dtype=float))
    z = rng.normal(scale=2.0, size=x.shape)
    vertices = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    corner = (np.arange(size - 1)[:, None] * size + np.arange(size - 1)[None, :]).ravel()
    faces = np.concatenate(
        [
            np.column_stack([corner, corner + 1, corner + size + 1]),
            np.column_stack([corner, corner + size + 1, corner + size]),
        ]
    )
    return clean_mesh(vertices, faces)


def test_a_height_field_faces_one_way_and_a_closed_surface_half():
    rng = np.random.default_rng(3)
    field = height_field(rng)
    assert facing_share(field) == 1.0
    assert facing_share_reference(field) == pytest.approx(1.0)
    # Wound every other way, half of it faces the other way: the winding is read as it is.
    flipped = Mesh(
        field.vertices,
        np.where((np.arange(field.n_faces) % 2)[:, None] == 1, field.faces[:, ::-1], field.faces),
    )
    assert facing_share(flipped) < 0.75
    s = trimesh.creation.icosphere(subdivisions=3)
    bumpy = clean_mesh(s.vertices * rng.uniform(0.8, 1.2, size=(len(s.vertices), 1)), s.faces)
    share = facing_share(bumpy)
    assert facing_share_reference(bumpy) - 0.05 <= share < 0.6


@pytest.mark.slow
def test_a_view_of_a_figure_faces_one_way_and_its_cuts_do_not():
    """One view (the faces a camera sees) is called one view, the whole and its cuts are
    not; the search finds a view's direction within 0.01 of the direct search's best (or
    better: it refines past the lattice's spacing), a cut's within 0.05."""
    figure = load_mesh(example("quadruped-0"))
    assert facing_share(figure) < 0.6
    rng = np.random.default_rng(0)
    for _ in range(3):
        view = single_view(figure, random_direction(rng))
        share = facing_share(view)
        assert share >= ONE_VIEW_FACING
        assert share >= facing_share_reference(view) - 0.01
        cut = planar_cut(figure, 0.3, random_direction(rng))
        assert facing_share_reference(cut) - 0.05 <= facing_share(cut) < ONE_VIEW_FACING


def test_a_view_glued_to_its_image_is_a_closed_surface_of_twice_its_area(sphere):
    """The upper half of a sphere, two-sided: every edge between two faces wound opposite
    ways, the topology of a sphere, twice the area, the boundary's vertices shared."""
    upper = sphere.vertices[sphere.faces].mean(axis=1)[:, 2] > 0.0
    half = clean_mesh(sphere.vertices, sphere.faces[upper])
    euler, boundary_edges = topology(half)
    assert (euler, boundary_edges > 0) == (1, True)

    closed = two_sided(half)

    assert topology(closed) == (2, 0)
    assert consistently_oriented(closed)
    assert area(closed) == pytest.approx(2.0 * area(half), rel=1e-12)
    assert closed.n_vertices == 2 * half.n_vertices - boundary_edges  # a loop: as many
    assert np.array_equal(closed.vertices[: half.n_vertices], half.vertices)
    assert two_sided(sphere) is sphere


def test_samples_spread_over_both_sheets_of_a_two_sided_view(sphere):
    """In place, farthest-point sampling would reach a vertex's twin only once every
    other vertex is as near a sample as it: with the sheets apart, each gets half."""
    upper = sphere.vertices[sphere.faces].mean(axis=1)[:, 2] > 0.0
    closed = two_sided(clean_mesh(sphere.vertices, sphere.faces[upper]))
    front = np.zeros(closed.n_vertices, dtype=bool)
    front[closed.faces[: closed.n_faces // 2].ravel()] = True
    mass = np.ones(closed.n_vertices)

    in_place = farthest_point_samples(closed.vertices, 200, mass)
    apart = farthest_point_samples(sheets_apart(closed), 200, mass)

    assert np.count_nonzero(~front[in_place]) == 0
    assert 80 <= np.count_nonzero(~front[apart]) <= 120
