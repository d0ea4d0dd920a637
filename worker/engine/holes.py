"""Closing the small holes of a surface before it is described.

A scan leaves gaps where the scanner did not see (armpits, the soles of feet), and
every descriptor here is an operator of the surface with its boundary: the heat
method's geodesics go around a hole, and the Laplace-Beltrami operator of eq. (3)
has Neumann conditions on it, so a hole of 0.1% of the area moves the spectrum of
the full-resolution surface itself (measured: ``python -m experiments.scan_gaps``). The same body
scanned with and without a gap is one shape; closing the gap makes it one surface.

Which openings are holes: a boundary loop of length ``p`` spans a surface of area at
most ``p^2 / (4 pi)`` (the isoperimetric inequality, which holds for minimal surfaces
spanning a space curve), so a loop shorter than ``max_perimeter * sqrt(area)`` with
``max_perimeter = 0.5`` closes a gap of at most 2% of the surface. Genuine openings
are longer: the rim of a cup as deep as it is wide has ``p = 2.05 sqrt(area)``, the
border of a face scan about ``3.5 sqrt(area)``; they are left as they are.

Each hole is closed by a fan of triangles from its boundary edges to its boundary's
centroid (weighted by edge length), oriented like the faces along its boundary. The
resampling that follows decimates the fan with the rest, and the operators are built
on the intrinsic Delaunay triangulation, so the fan's long triangles do not matter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .mesh_io import Mesh, face_areas
from .topology import edge_keys, keys_seen_once


@dataclass(frozen=True)
class BoundaryLoops:
    """The boundary of a surface as loops of boundary edges.

    Attributes
    ----------
    start, end : (e,) int, each boundary edge as the face along it runs (``start`` ->
        ``end``), so a triangle ``(end, start, x)`` has the neighbouring face's
        orientation.
    loop : (e,) int, the loop of each edge, in ``0 .. len(perimeter) - 1``.
    perimeter : (l,) float, each loop's length.
    simple : (l,) bool, whether the loop is a simple cycle (two loops touching at a
        vertex are one component that is not).
    """

    start: np.ndarray
    end: np.ndarray
    loop: np.ndarray
    perimeter: np.ndarray
    simple: np.ndarray


def boundary_loops(mesh: Mesh) -> BoundaryLoops:
    """The boundary edges of ``mesh`` grouped into loops (none for a closed surface).

    Parameters
    ----------
    mesh : a cleaned mesh.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    n = len(vertices)
    keys = edge_keys(faces, n).ravel()
    boundary_keys = keys_seen_once(keys)
    if len(boundary_keys) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return BoundaryLoops(empty, empty, empty, np.zeros(0), np.zeros(0, dtype=bool))
    # The corners that face a boundary edge, in the order of their keys.
    corners = np.flatnonzero(np.isin(keys, boundary_keys))
    boundary = corners[np.argsort(keys[corners])]
    face, corner = np.divmod(boundary, 3)
    a = faces[face, (corner + 1) % 3]
    b = faces[face, (corner + 2) % 3]

    graph = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    loops, loop_of_edge = np.unique(component[a], return_inverse=True)
    degree = np.bincount(np.concatenate([a, b]), minlength=n)
    simple = np.ones(len(loops), dtype=bool)
    simple[loop_of_edge[degree[a] != 2]] = False
    simple[loop_of_edge[degree[b] != 2]] = False
    lengths = np.linalg.norm(vertices[a] - vertices[b], axis=1)
    perimeter = np.bincount(loop_of_edge, weights=lengths, minlength=len(loops))
    return BoundaryLoops(a, b, loop_of_edge, perimeter, simple)


def longest_open_loop(mesh: Mesh, area: float | None = None) -> float:
    """The longest boundary loop of ``mesh`` in units of the square root of its area:
    0 for a closed surface; a scan's small gaps stay well below 0.1, a cut through a
    limb of a figure is 0.1 to 0.5, through its body 1 or more.

    Parameters
    ----------
    mesh : a cleaned mesh.
    area : its area when the caller knows it; computed otherwise.
    """
    loops = boundary_loops(mesh)
    if len(loops.perimeter) == 0:
        return 0.0
    if area is None:
        area = float(face_areas(mesh.vertices, mesh.faces).sum())
    return float(loops.perimeter.max()) / float(np.sqrt(area))


def close_small_holes(mesh: Mesh, max_perimeter: float, area: float | None = None) -> Mesh:
    """Close every boundary loop shorter than ``max_perimeter * sqrt(area)``.

    Parameters
    ----------
    mesh : a cleaned mesh.
    max_perimeter : longest loop closed, in units of the square root of the
        surface's area.
    area : the surface's area when the caller knows it (the canonical frame's is
        :data:`~worker.engine.mesh_io.CANONICAL_AREA`); computed otherwise.

    Returns
    -------
    Mesh with one new vertex (the loop's centroid) and one new triangle per
    boundary edge for every loop closed; ``mesh`` itself when there is none.
    Boundary components that are not a simple loop (two loops touching at a vertex)
    are left open.
    """
    loops = boundary_loops(mesh)
    if len(loops.perimeter) == 0:
        return mesh
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    n = len(vertices)
    a, b, loop_of_edge, perimeter = loops.start, loops.end, loops.loop, loops.perimeter
    if area is None:
        area = float(face_areas(vertices, faces).sum())
    # A loop of no length (its edges' ends merged) spans nothing and has no centroid.
    closed = loops.simple & (perimeter > 0.0) & (perimeter <= max_perimeter * np.sqrt(area))
    if not closed.any():
        return mesh

    lengths = np.linalg.norm(vertices[a] - vertices[b], axis=1)
    # Centroid of each loop as a curve: edge midpoints weighted by edge length.
    centroids = np.zeros((len(perimeter), 3))
    np.add.at(centroids, loop_of_edge, 0.5 * (vertices[a] + vertices[b]) * lengths[:, None])
    centroids /= perimeter[:, None]
    new_index = np.full(len(perimeter), -1, dtype=np.int64)
    new_index[closed] = n + np.arange(np.count_nonzero(closed))
    fan = closed[loop_of_edge]
    fan_faces = np.stack([b[fan], a[fan], new_index[loop_of_edge[fan]]], axis=1)
    return Mesh(
        vertices=np.concatenate([vertices, centroids[closed]]),
        faces=np.concatenate([faces, fan_faces]),
    )
