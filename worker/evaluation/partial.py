"""Partial copies of a mesh, as a scan or a query meets them (the partiality protocol).

A real query is rarely a complete copy of an enrolled surface: a scanner misses the
underside, an occluded side, the parts it could not see, and leaves holes. Each variant
here keeps a part of the surface, its largest connected piece:

* ``cut-5``, ``cut-15``, ``cut-30``: every face with a vertex beyond a plane is removed,
  the plane cutting the given share of the vertices off along a random direction (the
  query loses its "top");
* ``holes-10``, ``holes-25``: geodesic discs around five random vertices removed until
  the share of the area is gone (graph distances along the edges);
* ``view``: a single-view scan, the faces seen from one random direction: facing it and
  not hidden behind another face (orthographic rays through each face's centroid).

Seeded like the tessellation variants (:func:`.variants.variant_seed`), so a rerun cuts
the same way.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from worker.engine.errors import MeshError
from worker.engine.mesh_io import Mesh, clean_mesh, face_areas

#: Number of discs the ``holes-*`` variants remove.
HOLE_COUNT = 5


def largest_piece(mesh: Mesh, keep: np.ndarray) -> Mesh:
    """The connected piece of largest area among the faces ``keep`` ((f,) bool)."""
    faces = mesh.faces[keep]
    if not len(faces):
        raise MeshError("the partial copy kept no face")
    n = mesh.n_vertices
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    graph = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    piece = component[faces[:, 0]]
    areas = np.bincount(piece, weights=face_areas(mesh.vertices, faces))
    return clean_mesh(mesh.vertices, faces[piece == np.argmax(areas)])


def random_direction(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random unit vector (3,)."""
    direction = rng.normal(size=3)
    unit: np.ndarray = direction / np.linalg.norm(direction)
    return unit


def planar_cut(mesh: Mesh, share: float, direction: np.ndarray) -> Mesh:
    """Remove every face with a vertex among the ``share`` of the vertices highest along
    ``direction`` (3,); the largest remaining piece."""
    height = mesh.vertices @ direction
    below = height <= np.quantile(height, 1.0 - share)
    return largest_piece(mesh, below[mesh.faces].all(axis=1))


def geodesic_holes(mesh: Mesh, share: float, rng: np.random.Generator) -> Mesh:
    """Remove discs around ``HOLE_COUNT`` random vertices, nearest faces first (by the
    graph distance along the edges to the nearest centre, a face as far as its farthest
    corner), until ``share`` of the area is gone; the largest remaining piece."""
    vertices, faces = mesh.vertices, mesh.faces
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    lengths = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    n = len(vertices)
    graph = sp.coo_matrix((lengths, (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    centres = rng.choice(n, size=min(HOLE_COUNT, n), replace=False)
    distance = dijkstra(graph, directed=False, indices=centres).min(axis=0)
    areas = face_areas(vertices, faces)
    order = np.argsort(distance[faces].max(axis=1), kind="stable")
    removed = order[np.cumsum(areas[order]) <= share * areas.sum()]
    keep = np.ones(len(faces), dtype=bool)
    keep[removed] = False
    return largest_piece(mesh, keep)


def single_view(mesh: Mesh, direction: np.ndarray) -> Mesh:
    """The faces a scanner looking along ``-direction`` (3,) sees: facing it, and with no
    other face in front of their centroid on the ray through it (orthographic rays;
    triangles found through a uniform grid of their projected bounding boxes)."""
    vertices, faces = mesh.vertices, mesh.faces
    view = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(view[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    across = np.cross(view, helper)
    across /= np.linalg.norm(across)
    plane = np.stack([vertices @ across, vertices @ np.cross(view, across)], axis=1)
    depth = vertices @ view  # larger is nearer the scanner
    corners, corner_depth = plane[faces], depth[faces]
    centroid, centroid_depth = corners.mean(axis=1), corner_depth.mean(axis=1)
    normals = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    facing = normals @ view > 0.0

    # Each triangle in every grid cell its projected bounding box touches.
    low, high = corners.min(axis=1), corners.max(axis=1)
    cell = 2.0 * float(np.median(np.max(high - low, axis=1)))
    origin = plane.min(axis=0)
    first = np.floor((low - origin) / cell).astype(np.int64)
    span = np.floor((high - origin) / cell).astype(np.int64) - first + 1
    width = int((first[:, 0] + span[:, 0]).max()) + 1
    count = span[:, 0] * span[:, 1]
    triangle = np.repeat(np.arange(len(faces)), count)
    offset = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    x = first[triangle, 0] + offset % span[triangle, 0]
    y = first[triangle, 1] + offset // span[triangle, 0]
    order = np.argsort(y * width + x, kind="stable")
    cells, triangles = (y * width + x)[order], triangle[order]

    # Each centroid against the triangles of its cell: inside, and nearer the scanner?
    own = np.floor((centroid - origin) / cell).astype(np.int64)
    key = own[:, 1] * width + own[:, 0]
    start, stop = np.searchsorted(cells, key, "left"), np.searchsorted(cells, key, "right")
    pairs = stop - start
    face = np.repeat(np.arange(len(faces)), pairs)
    other = triangles[
        np.repeat(start, pairs)
        + np.arange(pairs.sum())
        - np.repeat(np.cumsum(pairs) - pairs, pairs)
    ]
    a, b, c = corners[other, 0], corners[other, 1], corners[other, 2]
    e1, e2, p = b - a, c - a, centroid[face] - a
    det = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
    usable = np.abs(det) > 0.0
    safe = np.where(usable, det, 1.0)
    u = (p[:, 0] * e2[:, 1] - e2[:, 0] * p[:, 1]) / safe
    v = (e1[:, 0] * p[:, 1] - p[:, 0] * e1[:, 1]) / safe
    inside = usable & (u >= 0) & (v >= 0) & (u + v <= 1) & (other != face)
    d = corner_depth[other]
    at_centroid = d[:, 0] + u * (d[:, 1] - d[:, 0]) + v * (d[:, 2] - d[:, 0])
    margin = 1e-6 * float(np.ptp(depth))
    hidden = np.zeros(len(faces), dtype=bool)
    hidden[face[inside & (at_centroid > centroid_depth[face] + margin)]] = True
    return largest_piece(mesh, facing & ~hidden)


#: name -> how to make it from a mesh and a random generator, in report order.
PARTIAL_VARIANTS: dict[str, Callable[[Mesh, np.random.Generator], Mesh]] = {
    "cut-5": lambda mesh, rng: planar_cut(mesh, 0.05, random_direction(rng)),
    "cut-15": lambda mesh, rng: planar_cut(mesh, 0.15, random_direction(rng)),
    "cut-30": lambda mesh, rng: planar_cut(mesh, 0.30, random_direction(rng)),
    "holes-10": lambda mesh, rng: geodesic_holes(mesh, 0.10, rng),
    "holes-25": lambda mesh, rng: geodesic_holes(mesh, 0.25, rng),
    "view": lambda mesh, rng: single_view(mesh, random_direction(rng)),
}
