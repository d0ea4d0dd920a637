"""A depth camera's frame holds the floor, table or wall its object stands on or against:
those planes are left out of an organized cloud, and an object's own flat faces are not
(:func:`worker.engine.scans.without_support`)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
import trimesh
from conftest import e57_scan

from worker.engine import scans
from worker.engine.errors import PointCloudError
from worker.engine.mesh_io import Mesh, face_areas, read_mesh
from worker.engine.pipeline import describe_file
from worker.engine.presets import DEFAULT_PRESET, get_preset
from worker.engine.scans import (
    Cloud,
    one_view,
    organized_scan,
    organized_surface,
    read_e57,
    read_pcd,
    view_frame,
    without_support,
)
from worker.evaluation.partial import (
    depth_grid,
    far_viewpoint,
    floor_frame,
    grid_points,
    voxel_means,
)
from worker.evaluation.samples import PARTIAL_SOURCE, floor_scan, pcd_bytes, seen_from_left
from worker.evaluation.samples import sample_mesh as made_sample

FIGURES = [("quadruped", 3), ("biped", 1), ("hand", 2), ("spider", 0)]


@cache
def sample_mesh(name: str, pose: int) -> Mesh:
    """The walk-through's figure, made once for the module's tests."""
    return made_sample(name, pose)


def scene_frame(
    name: str, pose: int, elevation: float, wall: bool, pixels: int = 40
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A figure on a floor (and against a wall) seen from ``elevation``, its pixels a
    ``pixels``-th of its size apart: the organized cloud, its viewpoint, and which of its
    pixels saw the figure."""
    mesh = sample_mesh(name, pose)
    direction = seen_from_left(elevation)
    pitch = float(np.ptp(mesh.vertices, axis=0).max()) / pixels
    low = mesh.vertices.min(axis=0)
    # A wall behind it, a twentieth of its size away.
    behind = [("y", low[1] - 0.05 * float(np.ptp(mesh.vertices, axis=0).max()))]
    points = floor_frame(mesh, direction, pitch, walls=behind if wall else ())
    margin = 1e-6 * float(np.ptp(mesh.vertices))
    with np.errstate(invalid="ignore"):
        figure = (points[..., 2] > low[2] + margin) & (points[..., 1] > low[1] - margin)
    return points, far_viewpoint(mesh, direction), figure


@pytest.mark.parametrize("wall", [False, True], ids=["floor", "floor and wall"])
@pytest.mark.parametrize("elevation", [20.0, 45.0, 90.0])
@pytest.mark.parametrize("name, pose", FIGURES)
def test_a_floor_and_a_wall_are_left_out_and_the_figure_stays(name, pose, elevation, wall):
    points, viewpoint, figure = scene_frame(name, pose, elevation, wall)
    seen = np.isfinite(points).all(axis=2)
    planes = seen & ~figure
    kept, support = without_support(points, viewpoint)
    left = np.isfinite(kept).all(axis=2)
    # Every pixel of the floor and the wall, and none of the figure's: not even its feet
    # on the floor, once the band around the plane narrows to its own points' spread.
    np.testing.assert_array_equal(left, seen & figure)
    assert support == np.count_nonzero(planes)
    np.testing.assert_array_equal(kept[left], points[left])


@pytest.mark.parametrize("elevation", [0.0, 20.0, 45.0, 90.0])
@pytest.mark.parametrize("name, pose", FIGURES)
def test_a_framed_figure_keeps_every_point(name, pose, elevation):
    """The figure alone, framed by pixels that saw nothing: its own largest planes hold
    most of a coarse view, but none runs out of the frame."""
    mesh = sample_mesh(name, pose)
    direction = seen_from_left(elevation)
    image, origin = depth_grid(mesh, direction, float(np.ptp(mesh.vertices, axis=0).max()) / 40)
    points = grid_points(image, origin, direction, float(np.ptp(mesh.vertices)) / 40)
    kept, support = without_support(points, far_viewpoint(mesh, direction))
    assert support == 0
    np.testing.assert_array_equal(kept, points)


def cropped_view(mesh: trimesh.Trimesh, direction: np.ndarray, keep: float) -> np.ndarray:
    """The middle ``keep`` of each side of an orthographic depth frame of ``mesh`` seen
    along ``-direction``: its faces run out of the frame."""
    pitch = float(np.ptp(mesh.vertices)) / 60
    image, origin = depth_grid(Mesh(mesh.vertices, mesh.faces), direction, pitch)
    points = grid_points(image, origin, direction, pitch)
    height, width = points.shape[:2]
    rows = slice(round(height * (1 - keep) / 2), round(height * (1 + keep) / 2))
    columns = slice(round(width * (1 - keep) / 2), round(width * (1 + keep) / 2))
    return points[rows, columns]


@pytest.mark.parametrize(
    "extents, direction",
    [
        ((4.0, 4.0, 4.0), (1.0, 1.0, 1.0)),  # a box's corner: the rest lies behind each face
        ((4.0, 3.0, 2.0), (0.3, 1.0, 0.6)),  # a box's two faces and its top
        ((10.0, 7.0, 0.3), (0.0, 0.0, 1.0)),  # a tablet filling the frame: nothing else
    ],
    ids=["box corner", "box", "tablet"],
)
def test_an_object_s_own_faces_running_out_of_the_frame_stay(extents, direction):
    box = trimesh.creation.box(extents=extents)
    towards = np.asarray(direction) / np.linalg.norm(direction)
    points = cropped_view(box, towards, 0.6)
    kept, support = without_support(points, 1e3 * float(np.ptp(box.vertices)) * towards)
    assert support == 0
    np.testing.assert_array_equal(kept, points)


@pytest.mark.parametrize("elevation", [20.0, 60.0])
def test_a_noisy_floor_is_left_out(elevation):
    """Depth noise along the rays growing with the square of the depth, as a depth
    camera's does: a sixteenth of a pixel at the frame's nearest point, a pixel at its
    farthest. The band left out follows the noise at each distance from the sensor: the
    floor goes but for a few points in a thousand, the figure keeps all but 3% (where it
    touches the floor, within the noise)."""
    points, viewpoint, figure = scene_frame("quadruped", 3, elevation, False)
    seen = np.isfinite(points).all(axis=2)
    rays = viewpoint - np.nan_to_num(points)
    rays /= np.linalg.norm(rays, axis=2, keepdims=True)
    pitch = float(np.ptp(sample_mesh("quadruped", 3).vertices, axis=0).max()) / 40
    depth = np.nan_to_num(points) @ (viewpoint / np.linalg.norm(viewpoint))
    far = np.clip((depth.max() - depth) / np.ptp(depth[seen]), 0.0, 1.0)
    sigma = pitch / 16 * (1 + 3 * far) ** 2
    noise = np.random.default_rng(1).normal(size=seen.shape) * sigma
    kept, _ = without_support(points + noise[..., None] * rays, viewpoint)
    left = np.isfinite(kept).all(axis=2)
    assert np.count_nonzero(left & seen & ~figure) <= 0.002 * np.count_nonzero(seen & ~figure)
    assert np.count_nonzero(figure & ~left) <= 0.03 * np.count_nonzero(figure)


def test_an_organized_file_is_read_without_its_floor():
    """Through the readers: the PCD's and the structured E57 scan's surface is the figure's
    alone, and the cloud says how many points were left out."""
    points, viewpoint, figure = scene_frame("quadruped", 3, 35.0, True)
    seen = np.isfinite(points).all(axis=2)
    kept, support = without_support(points, viewpoint)
    want_vertices, want_faces = organized_surface(kept, viewpoint)
    height, width = points.shape[:2]
    vertices, faces, cloud = read_pcd(pcd_bytes(points, viewpoint, "binary"))
    assert cloud == Cloud(len(want_vertices), (width, height), support)
    assert support >= np.count_nonzero(seen & ~figure)
    np.testing.assert_array_equal(faces, want_faces)
    # On a grid in the scan's frame: the E57 writer stores points relative to the scanner.
    vertices, faces, cloud = read_e57(e57_scan(points, viewpoint))
    assert cloud == Cloud(len(want_vertices), (width, height), support)
    np.testing.assert_array_equal(faces, want_faces)
    described = read_mesh(pcd_bytes(points, viewpoint, "binary"), "scene.pcd")
    assert described.cloud is not None and described.cloud.support == support
    assert described.mesh.vertices[:, 2].min() > sample_mesh("quadruped", 3).vertices[:, 2].min()


def without_grid(points: np.ndarray, viewpoint: np.ndarray, frame: str) -> np.ndarray:
    """An organized cloud's points that saw something, in another order, without the
    grid: in the camera's frame (the sensor at the origin, looking along z), as a depth
    camera's software exports them, or in the points' own frame (no sensor placed)."""
    seen = points[np.isfinite(points).all(axis=2)]
    seen = seen[np.random.default_rng(0).permutation(len(seen))]
    if frame == "mesh's":
        return seen
    return (seen - viewpoint) @ view_frame(viewpoint).T  # the viewpoint is far along its ray


#: The scenes read without their grid: every figure in the camera's frame; in the mesh's
#: (no sensor placed), the quadruped and the biped on a floor, whose silhouettes say which
#: side their camera stood on (the spider's, and the others' before a wall seen from 20
#: degrees, say the wrong one: seen from there, the floor is no support and stays, and the
#: view is described as its mirror image, as without a floor).
WITHOUT_GRID = [
    *[
        (*figure, "camera's", elevation, wall)
        for figure in FIGURES
        for elevation in (20.0, 90.0)
        for wall in (False, True)
    ],
    *[
        (*figure, "mesh's", elevation, False)
        for figure in FIGURES[:2]
        for elevation in (20.0, 45.0)
    ],
]


@pytest.mark.parametrize("name, pose, frame, elevation, wall", WITHOUT_GRID)
def test_a_view_s_points_without_their_grid_are_read_without_their_floor(
    name, pose, frame, elevation, wall
):
    """The scenes' points without the grid, on the camera's pixel lattice (found directly
    in its frame, found from the points in theirs, the sensor's side the one the object
    stands in front of its support from, where the silhouette may say otherwise): the
    points' rectangle is the frame, the floor and the wall go as from the organized
    cloud, and the figure's every point stays. (Seen from straight above, in the mesh's
    frame the camera looks along one of the file's axes, and the points are taken for
    a view from the file's origin, which is no sensor: the floor stays.)"""
    points, viewpoint, figure = scene_frame(name, pose, elevation, wall)
    seen = np.isfinite(points).all(axis=2)
    cloud_points = without_grid(points, viewpoint, frame)
    vertices, _, cloud = one_view(cloud_points, np.zeros(3))
    assert cloud == Cloud(np.count_nonzero(figure & seen), None, np.count_nonzero(seen & ~figure))
    kept = without_grid(np.where(figure[..., None], points, np.nan), viewpoint, frame)
    assert {tuple(p) for p in vertices.round(6).tolist()} == {
        tuple(p) for p in kept.round(6).tolist()
    }


@pytest.mark.parametrize("elevation", [0.0, 45.0])
@pytest.mark.parametrize("name, pose", FIGURES)
def test_a_framed_figure_s_points_without_their_grid_keep_every_point(name, pose, elevation):
    """The figure alone, its points without the grid: its rectangle hugs it, but none of
    its planes runs along the rectangle's border with everything else in front of it."""
    mesh = sample_mesh(name, pose)
    direction = seen_from_left(elevation)
    pitch = float(np.ptp(mesh.vertices, axis=0).max()) / 40
    image, origin = depth_grid(mesh, direction, pitch)
    points = grid_points(image, origin, direction, pitch)
    viewpoint = far_viewpoint(mesh, direction)
    vertices, _, cloud = one_view(without_grid(points, viewpoint, "camera's"), np.zeros(3))
    assert cloud == Cloud(int(np.isfinite(points).all(axis=2).sum()), None, 0)
    assert len(vertices) == cloud.points


def moved_or_filtered(points: np.ndarray, pitch: float, kind: str) -> np.ndarray:
    """``points`` (n, 3) moved at random by half a pixel ``pitch``, or voxel filtered at two
    pixels (each voxel's mean): on no pixel lattice."""
    if kind == "voxels":
        return voxel_means(points, 2 * pitch)
    moved: np.ndarray = points + np.random.default_rng(2).normal(
        scale=0.5 * pitch / np.sqrt(3), size=points.shape
    )
    return moved


@pytest.mark.parametrize("kind", ["moved", "voxels"])
@pytest.mark.parametrize("wall", [False, True], ids=["floor", "floor and wall"])
@pytest.mark.parametrize("elevation", [20.0, 45.0])
@pytest.mark.parametrize("name, pose", FIGURES[:2])
def test_points_on_no_lattice_are_read_without_most_of_their_floor(
    name, pose, elevation, wall, kind
):
    """The scenes' points (at three times the pixels) in the camera's frame moved half a pixel,
    or voxel filtered, lie on no lattice and are read by Delaunay's triangulation of
    their image; binned in cells of their spacing, the image is searched for the floor
    and the wall as a frame is, and every point as near them as on a frame goes: at most
    0.2% of their points stay (1-4.4% did when only the cells the planes won went: those
    the figure's nearest point held, beside its feet and behind its silhouette), and at
    most 3% of the figure's go (in the floor's cells, where it stands)."""
    points, viewpoint, figure = scene_frame(name, pose, elevation, wall, pixels=120)
    seen = np.isfinite(points).all(axis=2)
    pitch = float(np.ptp(sample_mesh(name, pose).vertices, axis=0).max()) / 120
    camera = view_frame(viewpoint)
    figure_points = moved_or_filtered((points[seen & figure] - viewpoint) @ camera.T, pitch, kind)
    plane_points = moved_or_filtered((points[seen & ~figure] - viewpoint) @ camera.T, pitch, kind)
    cloud_points = np.vstack([figure_points, plane_points])
    assert scans.sensor_grid(cloud_points, np.zeros(3)) is None
    vertices, _, cloud = one_view(cloud_points, np.zeros(3))
    read = {tuple(p) for p in vertices.tolist()}
    stayed = sum(tuple(p) in read for p in plane_points.tolist())
    went = sum(tuple(p) not in read for p in figure_points.tolist())
    assert cloud.grid is None and cloud.support == len(cloud_points) - len(vertices)
    assert stayed <= 0.002 * len(plane_points) and went <= 0.03 * len(figure_points)


def floor_scene_points(kind: str, elevation: float = 20.0) -> np.ndarray:
    """The quadruped on a floor (at three times the pixels), its points in the camera's
    frame moved half a pixel or voxel filtered (:func:`moved_or_filtered`)."""
    points, viewpoint, figure = scene_frame("quadruped", 3, elevation, False, pixels=120)
    seen = np.isfinite(points).all(axis=2)
    pitch = float(np.ptp(sample_mesh("quadruped", 3).vertices, axis=0).max()) / 120
    camera = view_frame(viewpoint)
    return np.vstack(
        [
            moved_or_filtered((points[seen & part] - viewpoint) @ camera.T, pitch, kind)
            for part in (figure, ~figure)
        ]
    )


def seen_image(points: np.ndarray) -> np.ndarray:
    """(n, 2) the image :func:`~worker.engine.scans.viewed_surface` triangulates of
    ``points`` (n, 3) seen from the origin: their central projection on the plane across
    their mean ray."""
    rays = points / np.linalg.norm(points, axis=1)[:, None]
    frame = view_frame(rays.mean(axis=0))
    image: np.ndarray = points @ frame[:2].T / (points @ frame[2])[:, None]
    return image


def triangles(vertices: np.ndarray, faces: np.ndarray) -> set[frozenset[tuple[float, ...]]]:
    """Each triangle as the set of its corners' coordinates."""
    return {frozenset(map(tuple, vertices[face].tolist())) for face in faces}


@pytest.mark.parametrize("windows", [False, True], ids=["whole first", "in windows"])
@pytest.mark.parametrize("kind", ["moved", "voxels"])
def test_points_on_no_lattice_triangulated_without_their_floor_as_with_it(
    kind, windows, monkeypatch
):
    """Only the points left once the floor is out are triangulated: the quadruped's
    triangles are those of every point's triangulation (the reference) that join no floor
    point, but for the few whose corners' median edge changes with their floor neighbours
    (within 1.5% of the triangles, 1.5% of the area); Delaunay's triangles of the rest alone
    bridge where the floor was (2-7% more, 3-9% of the area, before their circles were
    looked in). So whether the view's spacing was measured on its whole triangulation or,
    as a large view's is, in windows of it."""
    from scipy.spatial import Delaunay

    if windows:
        monkeypatch.setattr(scans, "SPACING_EXACT", 0)
    points = floor_scene_points(kind)
    vertices, faces, cloud = scans.viewed_surface(points, np.zeros(3))
    image = seen_image(points)
    every = Delaunay(image)
    edges = scans.median_edges(image, every.vertex_neighbor_vertices)
    spacing = scans.image_spacing(image, None if windows else edges)
    left_out = scans._binned_support(points, image, spacing, np.zeros(3))
    assert left_out is not None and cloud.support == np.count_nonzero(left_out) > 0
    seen = scans._seen_triangles(points, image, np.zeros(3), every)
    reference = seen[~left_out[seen].any(axis=1)]
    assert {tuple(p) for p in vertices.tolist()} == {tuple(p) for p in points[~left_out].tolist()}
    read, expected = triangles(vertices, faces), triangles(points, reference)
    assert len(read ^ expected) <= 0.015 * len(expected)
    area = face_areas(vertices, faces).sum()
    assert area == pytest.approx(face_areas(points, reference).sum(), rel=0.015)


def test_a_triangle_s_circle():
    """The circle through a triangle's corners: a right triangle's centred on its
    hypotenuse; three points on a line have none (an infinite radius)."""
    centre, radius = scans._circumcircles(
        np.array([[[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]], [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]])
    )
    np.testing.assert_allclose(centre[0], [1.0, 1.0])
    assert radius[0] == pytest.approx(np.sqrt(2.0)) and radius[1] == np.inf


def test_a_triangulation_s_edges_are_its_neighbours():
    """The triangles' edges as each point's neighbours (measured once some triangles are
    dropped) are Delaunay's own neighbours when none is: the same median edges."""
    from scipy.spatial import Delaunay

    image = np.random.default_rng(0).random((500, 2))
    triangulation = Delaunay(image)
    indptr, indices = scans._edge_neighbours(triangulation.simplices.astype(np.int64), 500)
    expected_indptr, expected = triangulation.vertex_neighbor_vertices
    np.testing.assert_array_equal(indptr, expected_indptr)
    for point in range(500):
        ours = indices[indptr[point] : indptr[point + 1]]
        theirs = expected[expected_indptr[point] : expected_indptr[point + 1]]
        assert sorted(ours) == sorted(theirs)
    np.testing.assert_array_equal(
        scans.median_edges(image, (indptr, indices)),
        scans.median_edges(image, (expected_indptr, expected)),
    )


@pytest.mark.parametrize("kind", ["grid", "moved", "voxels", "coarse voxels"])
def test_a_view_s_spacing_is_measured_in_windows_as_on_its_triangulation(kind):
    """A large view's spacing, measured in windows of it before it is triangulated, is the
    median of its points' median edges in Delaunay's triangulation within 5%: as shot,
    moved half a pixel, voxel filtered at two pixels, and at three of coarser pixels
    (whose third nearest neighbours lie at two thirds of it: its points lie in rows)."""
    from scipy.spatial import Delaunay

    if kind == "grid":
        frame, viewpoint, _ = scene_frame("quadruped", 3, 20.0, False, pixels=120)
        points = (frame[np.isfinite(frame).all(axis=2)] - viewpoint) @ view_frame(viewpoint).T
    elif kind == "coarse voxels":
        frame, viewpoint, _ = scene_frame("quadruped", 3, 20.0, False, pixels=80)
        seen = (frame[np.isfinite(frame).all(axis=2)] - viewpoint) @ view_frame(viewpoint).T
        pitch = float(np.ptp(sample_mesh("quadruped", 3).vertices, axis=0).max()) / 80
        points = moved_or_filtered(seen, 1.5 * pitch, "voxels")
    else:
        points = floor_scene_points(kind)
    image = seen_image(points)
    triangulation = Delaunay(image)
    edges = scans.median_edges(image, triangulation.vertex_neighbor_vertices)
    exact = float(np.median(edges))
    assert scans.image_spacing(image, edges) == exact
    assert scans.image_spacing(image) == pytest.approx(exact, rel=0.05)


def test_a_grazing_floor_once_left_out_leaves_one_view(monkeypatch):
    """The quadruped on a floor seen from 10 degrees above it, voxel filtered: the far
    floor's voxels, smeared along the rays, join few of their points, so that read whole
    the cloud is refused as no view from its camera; its floor left out, the rest is one
    view, read from the camera (every figure point kept but for 3%)."""
    points, viewpoint, figure = scene_frame("quadruped", 3, 10.0, False, pixels=120)
    seen = np.isfinite(points).all(axis=2)
    pitch = float(np.ptp(sample_mesh("quadruped", 3).vertices, axis=0).max()) / 120
    camera = view_frame(viewpoint)
    figure_points = moved_or_filtered(
        (points[seen & figure] - viewpoint) @ camera.T, pitch, "voxels"
    )
    plane_points = moved_or_filtered(
        (points[seen & ~figure] - viewpoint) @ camera.T, pitch, "voxels"
    )
    cloud_points = np.vstack([figure_points, plane_points])
    vertices, _, cloud = scans.viewed_surface(cloud_points, np.zeros(3))  # from its camera
    read = {tuple(p) for p in vertices.tolist()}
    assert cloud.support == len(cloud_points) - len(vertices)
    assert sum(tuple(p) not in read for p in figure_points.tolist()) <= 0.03 * len(figure_points)
    monkeypatch.setattr(scans, "_binned_support", lambda *args: None)
    with pytest.raises(PointCloudError, match="hide behind others"):
        scans.viewed_surface(cloud_points, np.zeros(3))


def test_a_view_too_coarse_to_tell_a_plane_is_not_looked_at_for_a_floor():
    """The quadruped's scene (its pixels an 80th of its size) seen from 20 degrees, voxel
    filtered at three of its pixels: one view from its camera, but its image fills 704
    cells, fewer than ``SUPPORT_LEAST_CELLS``, too coarse to tell a floor from a curved
    side within the band of two cells: the cloud's support None, every point read. At two
    of its pixels (1,584 cells) its floor goes."""
    points, viewpoint, _ = scene_frame("quadruped", 3, 20.0, False, pixels=80)
    seen = (points[np.isfinite(points).all(axis=2)] - viewpoint) @ view_frame(viewpoint).T
    pitch = float(np.ptp(sample_mesh("quadruped", 3).vertices, axis=0).max()) / 80
    finer = moved_or_filtered(seen, pitch, "voxels")
    assert scans.viewed_surface(finer, np.zeros(3))[2].support
    filtered = moved_or_filtered(seen, 1.5 * pitch, "voxels")
    vertices, _, cloud = scans.viewed_surface(filtered, np.zeros(3))  # from its camera
    assert cloud == Cloud(len(filtered), None, None) and len(vertices) == len(filtered)


def test_a_view_seen_from_a_guessed_sensor_is_not_looked_at_for_a_floor():
    """Points on no lattice written where no sensor is placed (in their mesh's frame) are
    read from afar along the direction they overlap themselves least in: a guess, its side
    unknown, from which an object's own face could pass for a support. Nothing is left out
    (the cloud's support None) and the floor stays."""
    points, viewpoint, figure = scene_frame("hand", 2, 20.0, True)
    seen = np.isfinite(points).all(axis=2)
    vertices, _, cloud = one_view(without_grid(points, viewpoint, "mesh's"), np.zeros(3))
    assert cloud == Cloud(np.count_nonzero(seen), None, None)
    assert len(vertices) == np.count_nonzero(seen) > np.count_nonzero(figure)


def test_points_written_without_their_grid_are_described_without_their_floor():
    """Through the reader and the pipeline: a binary PLY of the floor example's points in
    the camera's frame (float32) says how many were left out."""
    points, viewpoint = floor_scan(sample_mesh(*PARTIAL_SOURCE))
    _, _, organized = organized_scan(points, viewpoint)
    seen = without_grid(points, viewpoint, "camera's")
    data = trimesh.PointCloud(seen).export(file_type="ply")
    assert b"property float x" in data
    read = read_mesh(data, "scene.ply")
    assert read.cloud == Cloud(organized.points, None, organized.support)
    described = describe_file(data, get_preset(DEFAULT_PRESET), "scene.ply")
    assert (described.input_points, described.input_grid, described.input_support) == (
        organized.points,
        None,
        organized.support,
    )
