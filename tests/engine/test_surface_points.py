"""The gridded surface rigid verification compares: averaged per cell, the same however
the surface is triangulated or wound, in units of its area."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from worker.engine.mesh_io import Mesh
from worker.engine.rigid import rigid_fit, stored_anchors
from worker.engine.surface_points import ANCHOR_VOXEL, gridded_surface, voxel_points
from worker.evaluation.samples import sample_mesh


def test_voxel_points_average_each_cell():
    points = np.array([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.5, 0.2, 0.2]])
    normals = np.array([[0.0, 0.0, 2.0], [0.0, 1.0, 1.0], [1.0, 0.0, 0.0]])
    kept, unit = voxel_points(points, normals, 1.0)
    order = np.argsort(kept[:, 0])
    np.testing.assert_allclose(kept[order], [[0.2, 0.2, 0.2], [1.5, 0.2, 0.2]])
    # each normal counts as a unit vector: (0, 0, 1) + (0, 1, 1) / sqrt(2), then unit
    summed = np.array([0.0, 1 / np.sqrt(2), 1 + 1 / np.sqrt(2)])
    np.testing.assert_allclose(unit[order], [summed / np.linalg.norm(summed), [1, 0, 0]])


def test_the_grid_does_not_care_how_the_surface_is_triangulated_or_wound():
    """The quadruped and its midpoint subdivision (four times the faces) give grids whose
    points lie within a voxel of each other and that hold each other whole; wound inward,
    its normals are turned out again."""
    mesh = sample_mesh("quadruped", 0)
    finer = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).subdivide()
    grid, unit = gridded_surface(mesh, 1, ANCHOR_VOXEL, wound=False)
    other, other_unit = gridded_surface(
        Mesh(np.asarray(finer.vertices), np.asarray(finer.faces)), 1, ANCHOR_VOXEL, wound=False
    )
    area = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).area
    assert unit == other_unit == np.sqrt(area)
    # about 1 / ANCHOR_VOXEL^2 cells of an area of one unit, at half precision
    assert 2000 < len(grid) < 4000 and grid.dtype == np.float16
    gap = cKDTree(other[:, :3].astype(float)).query(grid[:, :3].astype(float))[0]
    assert np.quantile(gap, 0.99) < ANCHOR_VOXEL
    held = rigid_fit(stored_anchors(grid, ANCHOR_VOXEL), stored_anchors(other, ANCHOR_VOXEL), 0.02)
    assert held.fitness > 0.99
    np.testing.assert_allclose(held.rotation, np.eye(3), atol=0.01)

    inward, _ = gridded_surface(Mesh(mesh.vertices, mesh.faces[:, ::-1]), 1, ANCHOR_VOXEL, False)
    nearest = cKDTree(inward[:, :3].astype(float)).query(grid[:, :3].astype(float))[1]
    agree = (inward[nearest, 3:].astype(float) * grid[:, 3:].astype(float)).sum(axis=1)
    assert np.median(agree) > 0.99
    # a view keeps its winding (toward its sensor): both sides are counted in its unit
    seen, view_unit = gridded_surface(Mesh(mesh.vertices, mesh.faces[:, ::-1]), 2, 0.01, True)
    assert view_unit == np.sqrt(2 * area)
    nearest = cKDTree(seen[:, :3].astype(float)).query(grid[:, :3].astype(float) / np.sqrt(2))[1]
    assert np.median((seen[nearest, 3:].astype(float) * grid[:, 3:].astype(float)).sum(1)) < -0.99
