"""A depth camera's frame holds the floor, table or wall its object stands on or against:
those planes are left out of an organized cloud, and an object's own flat faces are not
(:func:`worker.engine.scans.without_support`)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
import trimesh
from conftest import e57_scan

from worker.engine.mesh_io import Mesh, read_mesh
from worker.engine.scans import Cloud, organized_surface, read_e57, read_pcd, without_support
from worker.evaluation.partial import (
    depth_grid,
    far_viewpoint,
    floor_frame,
    grid_points,
)
from worker.evaluation.samples import pcd_bytes, seen_from_left
from worker.evaluation.samples import sample_mesh as made_sample

FIGURES = [("quadruped", 3), ("biped", 1), ("hand", 2), ("spider", 0)]


@cache
def sample_mesh(name: str, pose: int) -> Mesh:
    """The walk-through's figure, made once for the module's tests."""
    return made_sample(name, pose)


def scene_frame(
    name: str, pose: int, elevation: float, wall: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A figure on a floor (and against a wall) seen from ``elevation``: the organized
    cloud, its viewpoint, and which of its pixels saw the figure."""
    mesh = sample_mesh(name, pose)
    direction = seen_from_left(elevation)
    pitch = float(np.ptp(mesh.vertices, axis=0).max()) / 40
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
