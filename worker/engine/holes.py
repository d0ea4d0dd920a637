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


#: :func:`facing_share`'s search, on at most ``FACING_SAMPLES`` faces drawn by area
#: (seeded): a lattice of ``FACING_DIRECTIONS`` directions over the sphere (about 0.14
#: radians apart), its best ``FACING_STARTS`` and the mean normal each refined by
#: ``FACING_MOVES`` moves to the best of its 3 x 3 neighbours at every step from half the
#: lattice's spacing down to ``FACING_FINEST`` radians.
FACING_SAMPLES = 4000
FACING_DIRECTIONS = 600
FACING_STARTS = 8
FACING_MOVES = 2
FACING_FINEST = 0.002


def facing_share(mesh: Mesh) -> float:
    """The largest share of the surface's area whose faces all face one direction ``d``
    (``n . d > 0``, by the faces' winding): about a half for a closed surface, a cut or
    holed copy of one, and 1 for a height field, such as a single view of a scanner (the
    faces a camera sees). Faces wound inconsistently lower it.

    ``d`` is searched on the faces, or ``FACING_SAMPLES`` of them drawn with probability
    proportional to their area: the best directions of a lattice (a Fibonacci lattice)
    and the mean normal, each moved to the best of its neighbours on ever finer steps (a
    pattern search, all starts at once). The share of the best is then measured on every
    face: a lower bound of the largest. Near 1 it is within 0.01 of a lattice of 20,000
    directions (the tests' views, and the partiality protocol's range scans); a cut's best
    directions are scattered, and its share can be a few hundredths under.
    """
    vertices, faces = mesh.vertices, mesh.faces
    normals = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    weights = np.linalg.norm(normals, axis=1)
    total = float(weights.sum())
    if total == 0.0:
        return 0.0
    if len(faces) > FACING_SAMPLES:
        chosen = np.random.default_rng(0).choice(len(faces), FACING_SAMPLES, p=weights / total)
        drawn, mass = normals[chosen], np.full(FACING_SAMPLES, 1.0 / FACING_SAMPLES)
    else:
        drawn, mass = normals, weights / total
    lattice = fibonacci_directions(FACING_DIRECTIONS)
    coarse = mass @ (drawn @ lattice.T > 0.0)
    starts = [lattice[np.argsort(-coarse, kind="stable")[:FACING_STARTS]]]
    mean = normals.sum(axis=0)
    if np.linalg.norm(mean) > 1e-9 * total:
        starts.append(mean[None, :] / np.linalg.norm(mean))
    current = np.concatenate(starts)  # (s, 3) unit
    step = 0.5 * float(np.sqrt(4.0 * np.pi / FACING_DIRECTIONS))
    offsets = np.array([(i, j) for i in (-1.0, 0.0, 1.0) for j in (-1.0, 0.0, 1.0)])
    while step >= FACING_FINEST:
        for _ in range(FACING_MOVES):
            first, second = _across(current)
            tried = (
                current[:, None, :]
                + step * offsets[None, :, 0, None] * first[:, None, :]
                + step * offsets[None, :, 1, None] * second[:, None, :]
            )
            tried /= np.linalg.norm(tried, axis=2, keepdims=True)
            shares = (mass @ (drawn @ tried.reshape(-1, 3).T > 0.0)).reshape(len(current), 9)
            current = tried[np.arange(len(current)), np.argmax(shares, axis=1)]
        step /= 2.0
    best = current[int(np.argmax(mass @ (drawn @ current.T > 0.0)))]
    return float(weights[normals @ best > 0.0].sum()) / total


def _across(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors across each of (s, 3) unit ``directions``, and across each other."""
    helper = np.where(
        np.abs(directions[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])
    )
    first = np.cross(directions, helper)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    return first, np.cross(directions, first)


def fibonacci_directions(count: int) -> np.ndarray:
    """(count, 3) unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    i = np.arange(count) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / count)
    azimuth = np.pi * (1.0 + np.sqrt(5.0)) * i
    return np.stack(
        [np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], axis=1
    )


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


def two_sided(mesh: Mesh) -> Mesh:
    """``mesh`` glued along its open boundary to a copy of itself wound the other way: a
    closed surface, its unseen side taken as the image of the side it has.

    What a single view (:data:`~worker.engine.descriptor.ONE_VIEW_FACING`) misses is
    mostly the side facing away from the camera, and a body's far side is close to the
    near one's mirror image (a limb seen from one side is half of its round section, a
    head's far half its near half's): intrinsically, a hemisphere glued to its copy along
    the equator is the round sphere, the near half of a cylinder so glued the whole
    cylinder. Every operator here is intrinsic, so the two coincident sheets are told
    apart by their connectivity alone.

    Returns
    -------
    Mesh with the vertices of ``mesh`` followed by a copy of those off its boundary, and
    its faces followed by their copies wound the other way (a boundary vertex is shared
    by both sheets); ``mesh`` itself when it is closed.
    """
    loops = boundary_loops(mesh)
    if len(loops.start) == 0:
        return mesh
    n = mesh.n_vertices
    inner = np.ones(n, dtype=bool)
    inner[loops.start] = False
    inner[loops.end] = False
    other = np.arange(n)
    other[inner] = n + np.arange(np.count_nonzero(inner))
    return Mesh(
        vertices=np.concatenate([mesh.vertices, mesh.vertices[inner]]),
        faces=np.concatenate([mesh.faces, other[mesh.faces][:, ::-1]]),
    )


def sheets_apart(mesh: Mesh) -> np.ndarray:
    """(n, 3) the vertices of a :func:`two_sided` surface with its second sheet's own
    vertices moved three extents away: where the two sheets are as far apart as they are
    along the surface, so farthest-point sampling
    (:func:`~worker.engine.geodesic.farthest_point_samples`) spreads its samples over
    both (in place, each vertex's twin would be the last to be chosen)."""
    front = np.zeros(mesh.n_vertices, dtype=bool)
    front[mesh.faces[: mesh.n_faces // 2].ravel()] = True
    apart = np.array(mesh.vertices, dtype=np.float64)
    apart[~front, 0] += 3.0 * float(np.ptp(apart, axis=0).max())
    return apart
