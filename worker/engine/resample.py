"""Resampling a surface to a fixed number of vertices.

The modal representation compares matrices of the same size, so every mesh is
brought to the preset's vertex count first (sec. 4.2: 2,500 points for SHREC).

Method: quadric error decimation (Garland-Heckbert, via ``fast_simplification``).
It keeps the shape's features at this density (an isotropic remesh to 2,500
vertices, MeshLab's, took TOSCA's DDT EER from 6.46 to 8.77%: docs/evaluation.md,
sec. "CAD-style files"), at the price of badly shaped triangles; the operators
built on the result therefore use its intrinsic Delaunay triangulation
(:mod:`worker.engine.intrinsic`), which makes them insensitive to triangle shape
(measured: docs/engine.md). Meshes with fewer vertices than the target are first
refined by midpoint subdivision, which does not change the surface.

Decimation measures only how far the surface moves, so where a file is flat or
ruled (a CAD cylinder's strips, a box's faces) it leaves triangles that span the
whole part: nothing there holds a vertex. The operators cannot resolve a function
across such an element, so a preset can bound the edge length afterwards
(:func:`split_long_edges`), again by midpoints, which keeps the surface. The
vertices it adds are taken out of the decimation's (:func:`resample_mesh`), so the
operators' cost stays the target's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .intrinsic import IntrinsicMesh
from .mesh_io import Mesh, canonical_frame, cell_means, clean_mesh, face_areas, tiling_edge
from .topology import edge_keys, euler_and_boundary

#: The edge-length bound stops refining before a mesh would pass this many times the
#: resampling target (a file of long thin strips, such as a finely faceted long
#: cylinder, would otherwise grow without bound); the longest edges go first.
MAX_REFINED_VERTICES = 4

#: Quadric decimation has stalled when it leaves more than this many times its target.
#: It refuses every collapse that would give a triangle a needle corner (under 2.6
#: degrees), so a surface made of slivers (a finely faceted CAD cylinder's strips and
#: fans) keeps nearly every vertex; any other file lands within a few percent.
STALLED_DECIMATION = 1.25

#: A corner whose cosine is past this (under 2.56 degrees, or over 177.44) is a needle to
#: the decimation: it refuses a collapse that leaves one at the moved vertex.
NEEDLE_COSINE = 0.999

#: The decimation stalls on a surface with more than this share of its vertices at a needle
#: corner (:func:`needle_vertices`): a finely faceted CAD file's 0.98-1.0, the voxel-filtered
#: scans of slivers in the partiality protocol 0.82-0.89, while every one of that
#: protocol's decimations that did not stall had at most 0.43 (docs/engine.md).
STALLING_NEEDLES = 0.7

#: The share of its area a stalled surface's clustered vertices must keep to be decimated
#: instead (a CAD cylinder's keep 0.998-1.0 in cubes of one tiling edge; a wire about two
#: tiling edges thick, 0.93 in those and 0.99 in cubes of half one).
CLUSTERED_AREA = 0.95

#: About this many faces, evenly spread, are looked at for needles before they are
#: counted; a surface with no more than :data:`NEEDLE_FACES` of them at a needle has too few
#: needle vertices to stall (a needle vertex is in one of its six or so faces, so 70% of
#: them put a needle in at least 0.12 of the faces; TOSCA's files have 0.0005).
NEEDLE_SAMPLE = 2000
NEEDLE_FACES = 0.1

#: The cubes' edges tried, in tiling edges, coarsest first: the first whose clustering keeps
#: :data:`CLUSTERED_AREA` is decimated.
CLUSTER_CELLS: tuple[float, ...] = (1.0, 0.5, 0.25)


def split_edges(
    vertices: np.ndarray, faces: np.ndarray, keys: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Split the edges ``keys`` (sorted unique :func:`~worker.engine.topology.edge_keys`)
    at their midpoints; the surface is unchanged.

    A face with one split edge becomes two triangles, with two it becomes three (its
    quadrilateral cut along the shorter diagonal), with three it becomes four (the
    midpoint subdivision, faces in the order corner a, b, c, middle). New vertices
    are appended in the order of ``keys``.
    """
    n = len(vertices)
    corner_keys = edge_keys(faces, n)  # [f, c]: the edge opposite corner c
    position = np.minimum(np.searchsorted(keys, corner_keys), len(keys) - 1)
    split = keys[position] == corner_keys
    mid = np.where(split, n + position, -1)
    vertices = np.concatenate([vertices, 0.5 * (vertices[keys // n] + vertices[keys % n])])
    count = split.sum(axis=1)
    rows = np.arange(len(faces))
    out = [faces[count == 0]]

    one = rows[count == 1]  # corner c opposite the split edge: (c, c+1, m), (c, m, c+2)
    c = np.argmax(split[one], axis=1)
    a, b, d = faces[one, c], faces[one, (c + 1) % 3], faces[one, (c + 2) % 3]
    m = mid[one, c]
    out += [np.stack([a, b, m], axis=1), np.stack([a, m, d], axis=1)]

    two = rows[count == 2]  # corner c opposite the kept edge b-d
    c = np.argmin(split[two], axis=1)
    a, b, d = faces[two, c], faces[two, (c + 1) % 3], faces[two, (c + 2) % 3]
    mab, mda = mid[two, (c + 2) % 3], mid[two, (c + 1) % 3]
    out.append(np.stack([a, mab, mda], axis=1))
    short = np.linalg.norm(vertices[mab] - vertices[d], axis=1) <= np.linalg.norm(
        vertices[b] - vertices[mda], axis=1
    )
    out += [
        np.stack([mab[short], b[short], d[short]], axis=1),
        np.stack([mab[short], d[short], mda[short]], axis=1),
        np.stack([mab[~short], b[~short], mda[~short]], axis=1),
        np.stack([b[~short], d[~short], mda[~short]], axis=1),
    ]

    three = rows[count == 3]
    a, b, d = faces[three].T
    mbd, mda, mab = mid[three].T
    out += [
        np.stack([a, mab, mda], axis=1),
        np.stack([mab, b, mbd], axis=1),
        np.stack([mda, mbd, d], axis=1),
        np.stack([mab, mbd, mda], axis=1),
    ]
    return vertices, np.concatenate(out).astype(faces.dtype)


def _subdivide(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split every triangle into four at its edge midpoints; the surface is unchanged."""
    return split_edges(vertices, faces, np.unique(edge_keys(faces, len(vertices))))


def split_long_edges(mesh: Mesh, max_length: float, max_vertices: int) -> Mesh:
    """Split every edge longer than ``max_length`` at its midpoint, in rounds, until
    none is left or the mesh reaches ``max_vertices`` (the longest edges first)."""
    vertices, faces = mesh.vertices, mesh.faces
    while len(vertices) < max_vertices:
        lengths = IntrinsicMesh.from_mesh(vertices, faces).lengths
        long_ = lengths > max_length
        keys, first = np.unique(edge_keys(faces, len(vertices))[long_], return_index=True)
        if len(keys) == 0:
            break
        room = max_vertices - len(vertices)
        if len(keys) > room:
            longest = np.argsort(-lengths[long_][first], kind="stable")[:room]
            keys = np.sort(keys[longest])
        vertices, faces = split_edges(vertices, faces, keys)
    return Mesh(vertices=vertices, faces=faces)


def _quadric(vertices: np.ndarray, faces: np.ndarray, n_vertices: int) -> Mesh:
    """Quadric decimation (``fast_simplification``) to the face count that gives about
    ``n_vertices``: by Euler, ``F = 2V - 2chi`` for a closed surface, so the target is
    reckoned for this surface's own characteristic and boundary."""
    import fast_simplification

    euler, boundary = euler_and_boundary(faces, len(vertices))
    target_faces = max(2 * n_vertices - 2 * euler - boundary, 4)
    reduced_vertices, reduced_faces = fast_simplification.simplify(
        vertices, faces.astype(np.int32), target_count=int(target_faces)
    )
    return clean_mesh(reduced_vertices, reduced_faces)


def _decimate(mesh: Mesh, n_vertices: int, *, unsliver: bool = True) -> Mesh:
    """Quadric decimation to about ``n_vertices`` (midpoint subdivision first below it).

    A surface of slivers, which the decimation cannot thin
    (:data:`STALLED_DECIMATION`), is decimated again from its vertices clustered in
    cubes (:func:`clustered_vertices`): a finely faceted CAD cylinder becomes the few
    dozen strips a coarse export of it has, and is resampled as such a file is. The
    cubes are of one tiling edge, or half or a quarter of one when a coarser clustering
    loses more of the area than :data:`CLUSTERED_AREA` allows (a finely faceted wire
    about two tiling edges thick); when every one does (a wire under one tiling edge
    thick), the decimation's result stands.

    The decimation is not even tried when most vertices hold a needle corner
    (:data:`STALLING_NEEDLES`), more than it may leave: it would stall, after a pass that
    takes 20-30 s on 220,000 vertices.
    """
    vertices, faces = mesh.vertices, mesh.faces
    while len(vertices) < n_vertices:
        vertices, faces = _subdivide(vertices, faces)
    if len(vertices) == n_vertices:
        return Mesh(vertices=vertices, faces=faces)
    if not unsliver:
        return _quadric(vertices, faces, n_vertices)
    out = (
        None
        if _stall_foreseen(vertices, faces, n_vertices)
        else _quadric(vertices, faces, n_vertices)
    )
    if out is not None and out.n_vertices <= STALLED_DECIMATION * n_vertices:
        return out
    area = float(face_areas(mesh.vertices, mesh.faces).sum())
    for cell in CLUSTER_CELLS:
        clustered = clustered_vertices(mesh, cell * tiling_edge(area, n_vertices))
        if face_areas(clustered.vertices, clustered.faces).sum() >= CLUSTERED_AREA * area:
            return _decimate(clustered, n_vertices, unsliver=False)
    return out if out is not None else _quadric(vertices, faces, n_vertices)


def needle_vertices(vertices: np.ndarray, faces: np.ndarray) -> int:
    """How many vertices are the corner of a needle or a cap (:data:`NEEDLE_COSINE`)."""
    needle = np.zeros(len(vertices), dtype=bool)
    needle[faces[_needle_corners(vertices, faces)]] = True
    return int(needle.sum())


def _needle_corners(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 3) bool: which corners of ``faces`` are a needle's or a cap's."""
    corners = np.zeros(faces.shape, dtype=bool)
    for corner in range(3):
        at = faces[:, corner]
        u = vertices[faces[:, (corner + 1) % 3]] - vertices[at]
        w = vertices[faces[:, (corner + 2) % 3]] - vertices[at]
        lengths = np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1)
        cosine = np.einsum("ij,ij->i", u, w) / np.maximum(lengths, np.finfo(float).tiny)
        corners[:, corner] = np.abs(cosine) > NEEDLE_COSINE
    return corners


def _stall_foreseen(vertices: np.ndarray, faces: np.ndarray, n_vertices: int) -> bool:
    """Whether more vertices than :data:`STALLING_NEEDLES` of them, and than the
    decimation may leave, are at a needle corner. A sample of the faces is looked at
    first (:data:`NEEDLE_SAMPLE`): an ordinary file has next to none, and is not counted."""
    sample = faces[:: max(1, len(faces) // NEEDLE_SAMPLE)]
    if _needle_corners(vertices, sample).any(axis=1).mean() <= NEEDLE_FACES:
        return False
    return needle_vertices(vertices, faces) > max(
        STALLED_DECIMATION * n_vertices, STALLING_NEEDLES * len(vertices)
    )


def clustered_vertices(mesh: Mesh, cell: float) -> Mesh:
    """Vertex clustering (Rossignac and Borrel 1993): the vertices in one cube of side
    ``cell`` (a grid from the mesh's lowest corner) merged at their mean
    (:func:`cell_means`), the triangles that lose a corner dropped, the largest connected
    piece kept (:func:`~worker.engine.mesh_io.clean_mesh`)."""
    means, cube = cell_means(mesh.vertices, cell, mesh.vertices.min(axis=0))
    return clean_mesh(means, cube[mesh.faces])


def resample_mesh(mesh: Mesh, n_vertices: int, max_edge: float | None = None) -> Mesh:
    """Return a mesh of the same surface with about ``n_vertices`` vertices.

    Parameters
    ----------
    mesh : a cleaned, connected mesh.
    n_vertices : target vertex count. Quadric decimation stops on a face budget,
        so the result can differ from the target by a few vertices on surfaces
        with boundaries or handles; the descriptors are normalized to be
        insensitive to that (see :func:`worker.engine.modal.normalize_slices`).
    max_edge : if given, no edge of the result is longer than this many
        :func:`tiling_edge` of its area for ``n_vertices`` (:func:`split_long_edges`,
        up to :data:`MAX_REFINED_VERTICES` times ``n_vertices``). The vertices the
        bound adds are taken from the decimation's: the decimated mesh is decimated
        further by as many (to no fewer than half the target) and bounded again, so
        a file the bound barely touches keeps about ``n_vertices`` (an organic file
        lands within a few percent) while one of long strips keeps what its strips
        need.

    Returns
    -------
    Mesh, cleaned again (decimation can leave unreferenced or merged vertices).
    """
    out = _decimate(mesh, n_vertices)
    if max_edge is None:
        return out
    limit = max_edge * tiling_edge(float(face_areas(out.vertices, out.faces).sum()), n_vertices)
    budget = MAX_REFINED_VERTICES * n_vertices
    bounded = split_long_edges(out, limit, budget)
    added = bounded.n_vertices - out.n_vertices
    if added == 0:
        return bounded
    coarser = _decimate(out, max(out.n_vertices - added, n_vertices // 2))
    return split_long_edges(coarser, limit, budget)


@dataclass(frozen=True)
class SharedResampling:
    """One resampling of a figure, made on one of its poses and carried to the others
    through their shared vertex ids (:func:`shared_resampling`).

    Attributes
    ----------
    corners : (k, 3) int, for each vertex of the resampling the file's ids of the
        corners of the triangle of the pose it lies on.
    weights : (k, 3) float, its barycentric coordinates in that triangle.
    faces : (m, 3) int, the resampling's triangles, indices into its ``k`` vertices.
    source_vertices : how many vertices the file it was made on has (a pose it is
        carried to has as many, numbered alike).
    """

    corners: np.ndarray
    weights: np.ndarray
    faces: np.ndarray
    source_vertices: int


#: Nearest vertices whose triangles are searched for the one a point lies on: the
#: decimation's vertices are within an edge or so of the surface they came from.
NEAREST_VERTICES = 16


def shared_resampling(reference: Mesh, n_vertices: int) -> SharedResampling:
    """The resampling of a figure by one of its poses: quadric decimation of the pose to
    about ``n_vertices`` (as :func:`resample_mesh` decimates, in the canonical frame),
    each of its vertices put as a point of the pose's surface (the barycentric
    coordinates of the nearest point of the pose's triangles).

    Those coordinates on the same vertex ids place the resampling on every pose of the
    figure whose file numbers its vertices alike (TOSCA's poses of one figure, SCAPE's):
    one triangulation for all of them, as the paper's TOSCA subset had (sec. 4.1).

    Parameters
    ----------
    reference : the pose, its vertices and faces numbered as in its file (not cleaned,
        which renumbers them: :func:`~worker.engine.mesh_io.read_numbered_mesh`).
    n_vertices : target vertex count; a pose with no more vertices keeps them all.
    """
    vertices, faces = reference.vertices, np.asarray(reference.faces, dtype=np.int64)
    n = len(vertices)
    if n <= n_vertices:
        corners = np.repeat(np.arange(n)[:, None], 3, axis=1)
        weights = np.tile([1.0, 0.0, 0.0], (n, 1))
        return SharedResampling(corners, weights, faces, n)
    surface = canonical_frame(reference)  # the decimation's thresholds are absolute
    reduced = _quadric(surface.vertices, faces, n_vertices)
    face, weights = _nearest_surface_points(reduced.vertices, surface.vertices, faces)
    return SharedResampling(faces[face], weights, reduced.faces, n)


def carry_resampling(pose: Mesh, resampling: SharedResampling) -> Mesh:
    """The resampling of a figure (:func:`shared_resampling`) on one of its poses: each
    vertex at its barycentric coordinates in the pose's triangle of the same corner ids,
    joined by the shared triangles (the same ``faces`` for every pose: one triangulation,
    vertex ``i`` the same point of the figure in each).

    Parameters
    ----------
    pose : numbered as in its file, as the pose the resampling was made on.

    Raises
    ------
    ValueError
        The pose has another number of vertices than the one it was made on.
    """
    if pose.n_vertices != resampling.source_vertices:
        raise ValueError(
            f"a pose of {pose.n_vertices} vertices cannot take a resampling made on "
            f"{resampling.source_vertices}"
        )
    corners = np.asarray(pose.vertices, dtype=np.float64)[resampling.corners]  # (k, 3, 3)
    vertices = np.einsum("kc,kcx->kx", resampling.weights, corners)
    return Mesh(vertices=vertices, faces=resampling.faces)


def _nearest_surface_points(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """For each point, the triangle of the surface nearest to it and the barycentric
    coordinates of its nearest point there, among the triangles at the point's
    :data:`NEAREST_VERTICES` nearest vertices.

    Returns
    -------
    face : (p,) int, indices into ``faces``.
    weights : (p, 3) float, non-negative, summing to 1.
    """
    from scipy.spatial import cKDTree

    nearest = cKDTree(vertices).query(points, k=min(NEAREST_VERTICES, len(vertices)))[1]
    # The triangles at each vertex, as a CSR of the faces sorted by corner.
    by_vertex = np.argsort(faces.ravel(), kind="stable") // 3
    starts = np.searchsorted(np.sort(faces.ravel()), np.arange(len(vertices) + 1))
    counts = (starts[1:] - starts[:-1])[nearest]  # (p, k)
    point = np.repeat(np.arange(len(points)), counts.sum(axis=1))
    first = np.repeat(starts[:-1][nearest].ravel(), counts.ravel())
    offset = np.arange(len(first)) - np.repeat(
        np.cumsum(counts.ravel()) - counts.ravel(), counts.ravel()
    )
    face = by_vertex[first + offset]
    weights = _closest_on_triangles(points[point], *(vertices[faces[face, c]] for c in range(3)))
    corners = vertices[faces[face]]
    gap = np.linalg.norm(points[point] - np.einsum("pc,pcx->px", weights, corners), axis=1)
    order = np.lexsort((gap, point))
    best = order[np.searchsorted(point[order], np.arange(len(points)))]
    return face[best], weights[best]


def _closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(m, 3) barycentric coordinates of the point of each triangle ``abc`` nearest to
    ``p`` (all (m, 3) float): Ericson's regions (Real-Time Collision Detection, 5.1.5),
    a vertex's before an edge's before the face's, as there."""
    ab, ac = b - a, c - a
    d1, d2 = np.einsum("ij,ij->i", ab, p - a), np.einsum("ij,ij->i", ac, p - a)
    d3, d4 = np.einsum("ij,ij->i", ab, p - b), np.einsum("ij,ij->i", ac, p - b)
    d5, d6 = np.einsum("ij,ij->i", ab, p - c), np.einsum("ij,ij->i", ac, p - c)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2

    def ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
        safe = np.where(den != 0.0, den, 1.0)
        return np.clip(np.where(den != 0.0, num / safe, 0.0), 0.0, 1.0)

    zero = np.zeros_like(d1)
    v, w = ratio(vb, va + vb + vc), ratio(vc, va + vb + vc)
    out = np.stack([1.0 - v - w, v, w], axis=1)  # inside the face
    # Each region overwrites the ones of lower precedence before it.
    t = ratio(d4 - d3, (d4 - d3) + (d5 - d6))
    on_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
    out = np.where(on_bc[:, None], np.stack([zero, 1.0 - t, t], axis=1), out)
    t = ratio(d2, d2 - d6)
    on_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    out = np.where(on_ac[:, None], np.stack([1.0 - t, zero, t], axis=1), out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[:, None], [0.0, 0.0, 1.0], out)
    t = ratio(d1, d1 - d3)
    on_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    out = np.where(on_ab[:, None], np.stack([1.0 - t, t, zero], axis=1), out)
    out = np.where(((d3 >= 0) & (d4 <= d3))[:, None], [0.0, 1.0, 0.0], out)
    out = np.where(((d1 <= 0) & (d2 <= 0))[:, None], [1.0, 0.0, 0.0], out)
    weights: np.ndarray = np.clip(out, 0.0, 1.0)
    normalized: np.ndarray = weights / weights.sum(axis=1, keepdims=True)
    return normalized
