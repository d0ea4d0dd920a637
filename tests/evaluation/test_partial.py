"""Partial copies as scanners make them (the partiality protocol's SHREC'17 variants)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from worker.engine import scans
from worker.engine.holes import boundary_loops
from worker.engine.mesh_io import Mesh, clean_mesh, face_areas
from worker.evaluation import partial
from worker.evaluation.partial import (
    PARTIAL_VARIANTS,
    RANGE_ELEVATION,
    SHREC_MIN_VERTICES,
    depth_grid,
    grid_mesh,
    grid_points,
    noisy_surface,
    orbit_direction,
)
from worker.evaluation.variants import make_variant, standing_name


@pytest.fixture(scope="module")
def sphere() -> Mesh:
    ball = trimesh.creation.icosphere(subdivisions=5)  # 10,242 vertices, radius 1
    return clean_mesh(ball.vertices, ball.faces)


def _scan(mesh: Mesh, direction: np.ndarray, pitch: float, longest: float = np.inf) -> Mesh:
    return grid_mesh(grid_points(*depth_grid(mesh, direction, pitch), direction, pitch), longest)


def test_a_range_scan_samples_the_visible_side_on_a_grid(sphere):
    view = np.array([0.0, 0.0, 1.0])
    scan = _scan(sphere, view, 0.05)
    radius = np.linalg.norm(scan.vertices, axis=1)
    # On the sphere's facets (inside the unit sphere, by less than a facet's sag), on the
    # side facing the scanner, and about as many as pixels fit in its disc.
    assert np.all(radius <= 1.0 + 1e-9) and np.all(radius > 0.998)
    assert np.all(scan.vertices[:, 2] > -1e-9)
    assert scan.n_vertices == pytest.approx(np.pi / 0.05**2, rel=0.05)
    # Triangulated as a grid: seen from the scanner, every edge is a pixel's side or diagonal.
    corners = scan.vertices[scan.faces][..., :2]
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2) / 0.05
    assert np.allclose(np.minimum(np.abs(edges - 1), np.abs(edges - np.sqrt(2))), 0, atol=1e-6)


def test_the_grid_joins_what_occludes_to_what_it_hides():
    # A near square half over a far one: the scan is one piece across the depth jump.
    square = trimesh.creation.box(extents=[2.0, 2.0, 0.01])
    near = trimesh.Trimesh(square.vertices + [1.0, 0.0, 1.0], square.faces)
    both = trimesh.util.concatenate([square, near])
    mesh = Mesh(np.asarray(both.vertices, dtype=float), np.asarray(both.faces, dtype=np.int64))
    scan = _scan(mesh, np.array([0.0, 0.0, 1.0]), 0.1)
    depths = np.unique(np.round(scan.vertices[:, 2], 3))
    assert set(depths) == {0.005, 1.005}  # clean_mesh kept the largest piece: both depths
    assert scan.vertices[:, 0].min() < -0.9 and scan.vertices[:, 0].max() > 1.9


def test_a_range_scan_leaves_out_shortcuts_as_long_as_it_was_told():
    # The occluding square's edge joins the far one across a depth jump of 1: kept under
    # a longest edge of 2, left out under 0.5 (the near square, larger, is what is left).
    square = trimesh.creation.box(extents=[2.0, 2.0, 0.01])
    near = trimesh.Trimesh(square.vertices * [1.5, 1.0, 1.0] + [1.0, 0.0, 1.0], square.faces)
    both = trimesh.util.concatenate([square, near])
    mesh = Mesh(np.asarray(both.vertices, dtype=float), np.asarray(both.faces, dtype=np.int64))
    view = np.array([0.0, 0.0, 1.0])
    joined, parted = _scan(mesh, view, 0.1, longest=2.0), _scan(mesh, view, 0.1, longest=0.5)
    assert set(np.unique(np.round(joined.vertices[:, 2], 3))) == {0.005, 1.005}
    assert set(np.unique(np.round(parted.vertices[:, 2], 3))) == {1.005}


def test_a_coarse_range_scan_of_a_fine_whole_keeps_its_grid(sphere, monkeypatch):
    """100 pixels on a sphere of 10,242 vertices: a pixel is about five median edges
    wide, so the shortcut rule counts pixels there and the smooth cap keeps its squares
    (at four median edges every diagonal would go)."""
    monkeypatch.setattr(partial, "random_resolution", lambda mesh, rng: 100)
    monkeypatch.setattr(partial, "RANGE_LONGEST_EDGES", (4, 4))
    for name in ("a.off", "b.off", "c.off"):
        made = make_variant(sphere, "range", name)
        assert made.n_vertices == pytest.approx(100, rel=0.15)
        assert len(boundary_loops(made).perimeter) == 1  # its rim, no square lost inside


@pytest.mark.parametrize("up", ["x", "y", "z"])
def test_the_range_camera_orbits_the_up_axis_near_the_horizon(up):
    """SHREC'17's camera: any azimuth around the axis the shape stands on, within 25
    degrees above or below the horizon, never from above or below."""
    rng = np.random.default_rng(0)
    directions = np.array([orbit_direction(up, rng) for _ in range(400)])
    axis = "xyz".index(up)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0)
    height = np.abs(directions[:, axis])
    limit = np.sin(np.radians(RANGE_ELEVATION))
    assert height.max() <= limit + 1e-12 and height.max() > 0.9 * limit
    across = np.delete(directions, axis, axis=1)
    assert len({(a > 0, b > 0) for a, b in across}) == 4  # every side of the shape


def test_a_copy_of_a_whole_standing_on_another_axis_is_shot_around_it(sphere, monkeypatch):
    """``range@x`` is ``range``'s copy (the same seed) shot around x: the camera, seen as
    the middle of the visible cap, stays near the horizon of the axis asked for."""
    monkeypatch.setattr(partial, "similarity", lambda mesh, rng: mesh)
    limit = np.sin(np.radians(RANGE_ELEVATION)) + 0.05  # the cap's middle, not the ray
    for name in ("sphere.off", "other.off", "third.off"):
        for up in ("x", "z"):
            scan = make_variant(sphere, standing_name("range", up), name)
            seen = scan.vertices.mean(axis=0)
            assert abs(seen["xyz".index(up)]) / np.linalg.norm(seen) <= limit
    assert standing_name("range#3", "x") == "range#3@x" and standing_name("range", "z") == "range"
    assert standing_name("cut-5", "x") == "cut-5"  # the camera shoots only the range copies


@pytest.mark.parametrize("variant", ["range", "shrec-holes"])
def test_shrec_copies_are_partial_at_a_random_resolution_and_reproducible(sphere, variant):
    made = make_variant(sphere, variant, "sphere.off")
    again = make_variant(sphere, variant, "sphere.off")
    np.testing.assert_array_equal(made.vertices, again.vertices)
    assert SHREC_MIN_VERTICES * 0.8 <= made.n_vertices <= sphere.n_vertices
    assert len(boundary_loops(made).start) > 0  # open: something is missing
    others = [make_variant(sphere, variant, f"other-{i}.off").n_vertices for i in range(4)]
    assert len(set(others)) > 1  # the resolution varies from copy to copy


def test_noise_is_a_share_of_the_bounding_box_diagonal(sphere):
    noisy = noisy_surface(sphere, 0.5, np.random.default_rng(0))
    moved = noisy.vertices - sphere.vertices
    diagonal = np.linalg.norm(np.ptp(sphere.vertices, axis=0))
    assert moved.std() == pytest.approx(0.005 * diagonal, rel=0.05)
    np.testing.assert_array_equal(noisy.faces, sphere.faces)
    assert {"noise-0.25", "noise-0.5", "noise-1", "range", "shrec-holes"} <= set(PARTIAL_VARIANTS)


def test_view_points_are_the_range_cloud_s_scans_read_without_their_grid(sphere, monkeypatch):
    """``view-points`` draws ``range-cloud``'s scans (its seed) and reads their points as
    a cloud without a grid: the same points (the random similarity left out to compare
    them), and their surface as the grid's but for the diagonals of some squares (at the
    rim, one diagonal along the rays, the other not), so within a percent of its points
    and area."""
    monkeypatch.setattr(partial, "similarity", lambda mesh, rng: mesh)
    for name in ("sphere.off", "other.off"):
        grid = make_variant(sphere, "range-cloud", name)
        points = make_variant(sphere, "view-points", name)
        on_grid = {tuple(v) for v in grid.vertices.tolist()}
        shared = sum(tuple(v) in on_grid for v in points.vertices.tolist())
        assert shared >= 0.99 * max(grid.n_vertices, points.n_vertices)
        area = face_areas(points.vertices, points.faces).sum()
        assert area == pytest.approx(face_areas(grid.vertices, grid.faces).sum(), rel=0.01)


def test_view_voxels_are_the_range_cloud_s_scans_thinned(sphere, monkeypatch):
    """``view-voxels`` draws ``range-cloud``'s scans (its seed) and keeps the mean of the
    points in each voxel of two pixels: a quarter to a half of the points, on no pixel
    lattice, read by Delaunay's triangulation of their image, which covers the grid's
    surface to within 5% of its area."""
    monkeypatch.setattr(partial, "similarity", lambda mesh, rng: mesh)
    lattices = []
    search = scans.sensor_grid
    monkeypatch.setattr(
        scans, "sensor_grid", lambda *a, **k: lattices.append(search(*a, **k)) or lattices[-1]
    )
    for name in ("sphere.off", "other.off"):
        grid = make_variant(sphere, "range-cloud", name)
        lattices.clear()
        thinned = make_variant(sphere, "view-voxels", name)
        assert lattices and all(lattice is None for lattice in lattices)
        assert 0.25 * grid.n_vertices < thinned.n_vertices < 0.5 * grid.n_vertices
        area = face_areas(thinned.vertices, thinned.faces).sum()
        assert area == pytest.approx(face_areas(grid.vertices, grid.faces).sum(), rel=0.05)


def test_a_noisy_view_is_the_view_moved_along_its_rays(sphere):
    """``view-noise-s`` draws ``view``'s very views (its seed) and moves each vertex along
    the viewing direction only, by s% of the whole's diagonal: the faces are the view's,
    every displacement is parallel to one direction, and its spread is the noise's."""
    for name in ("sphere.off", "other.off"):
        view = make_variant(sphere, "view", name)
        noisy = make_variant(sphere, "view-noise-0.5", name)
        np.testing.assert_array_equal(noisy.faces, view.faces)
        moved = noisy.vertices - view.vertices
        largest = moved[np.argmax(np.linalg.norm(moved, axis=1))]
        ray = largest / np.linalg.norm(largest)
        np.testing.assert_allclose(np.abs(moved @ ray), np.linalg.norm(moved, axis=1), atol=1e-9)
        diagonal = np.linalg.norm(np.ptp(sphere.vertices, axis=0))
        assert (moved @ ray).std() == pytest.approx(0.005 * diagonal, rel=0.05)
        # The view faces the scanner: the ray is the direction it was seen along.
        corners = view.vertices[view.faces]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        assert abs(np.mean(np.sign(normals @ ray))) > 0.95


def test_a_noisy_whole_s_points_are_the_whole_s_points_moved(sphere, monkeypatch):
    """``points-noise-s`` draws ``points``' very clouds (its seed: the same similarity and
    order) and moves each point by isotropic Gaussian noise of s% of their diagonal; both
    are read as the service reads points (what reaches the reader is compared)."""
    read: list[np.ndarray] = []
    reader = partial.one_view

    def recorded(
        points: np.ndarray, viewpoint: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, scans.Cloud]:
        read.append(points)
        return reader(points, viewpoint)

    monkeypatch.setattr(partial, "one_view", recorded)
    for name in ("sphere.off", "other.off"):
        read.clear()
        make_variant(sphere, "points", name)
        make_variant(sphere, "points-noise-0.5", name)
        clean, noisy = read
        moved = noisy - clean
        diagonal = np.linalg.norm(np.ptp(clean, axis=0))
        assert moved.std(axis=0) == pytest.approx(np.full(3, 0.005 * diagonal), rel=0.1)
        assert np.abs(moved.mean(axis=0)).max() < 0.001 * diagonal


@pytest.mark.parametrize(
    "variant, alone, within",
    [("range-floor", "range-cloud", 0.02), ("floor-voxels", "view-voxels", 0.05)],
)
def test_a_floor_frame_is_read_without_its_floor(sphere, monkeypatch, variant, alone, within):
    """``range-floor`` shoots ``range-cloud``'s scans (its seed) of the whole on a floor
    from above it, the frame cut so that the floor runs out of it, and reads them as the
    service reads a depth camera's organized cloud; ``floor-voxels`` thins those very
    frames by ``view-voxels``' filter and reads their points as the service reads a PCD
    of them with its camera's viewpoint (on no lattice: their image binned). No floor
    point is left (none at its height), and the sphere's view is the same scan's without
    a floor: ``range-cloud``'s within 2% of its area, ``view-voxels``' within 5% (the
    cells it shares with the floor go too)."""
    monkeypatch.setattr(partial, "similarity", lambda mesh, rng: mesh)
    supports = []
    found = scans.support_planes

    def counted(*args):
        support, planes = found(*args)
        supports.append(int(np.count_nonzero(support)))
        return support, planes

    monkeypatch.setattr(scans, "support_planes", counted)
    low = float(sphere.vertices[:, 2].min())
    for name in ("sphere.off", "other.off"):
        supports.clear()
        floor = make_variant(sphere, variant, name)
        assert len(supports) == 1 and supports[0] > 0  # the floor's points, or cells
        assert floor.vertices[:, 2].min() > low + 1e-9
        without = make_variant(sphere, alone, name)
        area = face_areas(floor.vertices, floor.faces).sum()
        assert area == pytest.approx(face_areas(without.vertices, without.faces).sum(), rel=within)
