"""A surface as points with normals on a voxel grid: what rigid verification
(:mod:`.rigid`) compares, kept with each descriptor
(:attr:`~.descriptor.ShapeDescriptor.surface`).

The points are drawn uniformly by area (seeded) rather than taken from the vertices, so
that a surface gives the same grid however it is triangulated, and averaged per cell of a
grid whose spacing is a share of the surface's *unit*: the square root of its area (of
both sides of a single view, as the parts modality describes one, so that the parts'
scale relates two units as it relates two surfaces). Coordinates are divided by the unit
and stored at half precision (under 0.002 of a unit for an object a few units long, a
tenth of a voxel).
"""

from __future__ import annotations

import numpy as np

from .mesh_io import Mesh, cross_areas, face_crosses
from .tol import TOL

#: The anchors' voxel in units (:mod:`.rigid`): about 2,500 cells on a whole.
ANCHOR_VOXEL = 0.02
#: A single view's grid is finer, so that it can be re-gridded at ``ANCHOR_VOXEL`` of a
#: candidate's unit once the parts' scale between them is known (at least ``ANCHOR_VOXEL``
#: of its own unit: a view is at most its object's size).
VIEW_VOXEL = ANCHOR_VOXEL / 2
#: Points drawn per cell of the grid.
SAMPLES_PER_CELL = 8


def voxel_points(
    points: np.ndarray, normals: np.ndarray, voxel: float
) -> tuple[np.ndarray, np.ndarray]:
    """The mean point and normal of each occupied cell of a grid of ``voxel`` spacing.

    Parameters
    ----------
    points, normals : (n, 3) float; normals need not be unit.
    voxel : the cells' edge, in the points' units.

    Returns
    -------
    (m, 3) points and (m, 3) unit normals, in the order of their cells; a cell whose
    normals cancel is left out.
    """
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    cells = np.floor((points - points.min(axis=0)) / voxel).astype(np.int64)
    # one integer per cell, in the order of (x, y, z): np.unique on rows, without its sort
    # of rows
    span = cells.max(axis=0) + 1
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    _, cell, counts = np.unique(keys, return_inverse=True, return_counts=True)
    mean = np.stack([np.bincount(cell, points[:, a]) for a in range(3)], axis=1) / counts[:, None]
    unit = np.linalg.norm(normals, axis=1, keepdims=True)
    unit[unit == 0] = 1.0
    direction = np.stack([np.bincount(cell, normals[:, a] / unit[:, 0]) for a in range(3)], axis=1)
    length = np.linalg.norm(direction, axis=1)
    kept = length > TOL.cancelled_normals * counts
    return mean[kept], direction[kept] / length[kept, None]


def _outward(corner: np.ndarray, cross: np.ndarray, areas: np.ndarray) -> bool:
    """Whether faces are wound out of the object: the volume they enclose about their
    area centroid ``p`` is positive (on a closed surface its volume; on a cut or holed
    one, the sign of most of it). Six times a face's share is ``(a - p) . n`` with ``n``
    its edges' cross product (``det(a - p, b - p, c - p)``, the first column subtracted
    from the others).

    Parameters
    ----------
    corner : (3, 3, m) the faces' corners, coordinate by coordinate.
    cross : (3, m) each face's ``(b - a) x (c - a)``.
    areas : (m,) the faces' areas.
    """
    centre = corner.sum(axis=0) @ areas / (3.0 * max(float(areas.sum()), np.finfo(float).tiny))
    volume = np.einsum("im,im->", corner[0], cross) - centre @ cross.sum(axis=1)
    return float(volume) >= 0.0


def gridded_surface(mesh: Mesh, sides: int, voxel: float, wound: bool) -> tuple[np.ndarray, float]:
    """A mesh's surface on a grid (module docstring).

    Parameters
    ----------
    mesh : in the file's units.
    sides : 2 for a single view described two-sided (its unit counts both), else 1.
    voxel : the grid's spacing in units.
    wound : the normals follow the faces' winding (a view's, toward its sensor); else
        they are turned out of the object (:func:`_outward`).

    Returns
    -------
    surface : (m, 6) float16, each cell's mean point (in units, about the file's origin
        moved to the surface's mean) and unit normal.
    unit : the unit, in the file's length unit.
    """
    corner, cross = face_crosses(mesh.vertices, mesh.faces)
    u, v = corner[1] - corner[0], corner[2] - corner[0]
    areas = cross_areas(cross)
    total = float(areas.sum())
    unit = float(np.sqrt(sides * total))
    rng = np.random.default_rng(0)
    count = int(np.ceil(SAMPLES_PER_CELL * total / (voxel * unit) ** 2))
    chosen = rng.choice(len(areas), size=count, p=areas / total)
    s, t = rng.random((2, count))
    flip = s + t > 1.0
    s, t = np.where(flip, 1.0 - s, s), np.where(flip, 1.0 - t, t)
    points = (corner[0][:, chosen] + s * u[:, chosen] + t * v[:, chosen]).T
    normals = cross[:, chosen].T
    if not wound and not _outward(corner, cross, areas):
        normals = -normals
    points = (points - points.mean(axis=0)) / unit
    kept, directions = voxel_points(points, normals, voxel)
    return np.hstack([kept, directions]).astype(np.float16), unit
