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
  not hidden behind another face (orthographic rays through each face's centroid);
* ``range``: SHREC'17's range scans (Rodola et al., "Deformable shape retrieval with
  missing parts", 3DOR 2017): an orthographic depth grid shot by a camera orbiting the
  shape's up axis at a random azimuth and elevation (within 25 degrees of the horizon),
  at a random resolution (300 vertices .. as many as the mesh has), triangulated as a
  grid, so that occlusion edges become shortcuts (those longer than a random 4 to 33 of
  the whole's median edges, or of the grid's pixels if wider, left out), in a random
  similarity transform;
* ``range-cloud``: scans drawn as ``range``'s, read as the service reads a depth camera's
  organized cloud (:mod:`worker.engine.scans`): the grid's triangles along a viewing ray
  left out, so occlusion edges stay open;
* ``view-points``: ``range-cloud``'s very scans (drawn from its seed, :data:`DRAWN_AS`)
  without their grid, their points in another order, read as the service reads one
  view's points (:func:`worker.engine.scans.viewed_surface`, from the camera);
* ``view-voxels``: the same scans' points thinned by a voxel filter of two pixels (on no
  pixel lattice), read as ``view-points``;
* ``range-floor``: ``range-cloud``'s scans (drawn from its seed) of the whole standing
  on a floor, the camera above it, the frame cropped so that the floor runs out of it,
  read as the service reads a depth camera's organized cloud (the floor left out first);
* ``floor-voxels``: ``range-floor``'s very frames without their grid, thinned by
  ``view-voxels``' filter, read as ``view-voxels`` (the floor left out of their binned
  image);
* ``points``: the whole surface as a point cloud, its vertices in a random similarity and
  order without their faces, read as the service reads points that are not one view (the
  view that sees most of them, :func:`worker.engine.scans.one_view`);
* ``shrec-holes``: SHREC'17's holes: geodesic discs of random radius (up to 20% of the
  diameter) eroded around some of 70 farthest samples, the rest decimated to a random
  resolution (300 vertices .. as many as the mesh has), in a random similarity transform;
* ``noise-0.25``, ``noise-0.5``, ``noise-1``: the whole surface, every vertex displaced
  by Gaussian noise of that percentage of the bounding box's diagonal;
* ``view-noise-0.25``, ``view-noise-0.5``: ``view``'s very views (drawn from its seed),
  every vertex moved along the viewing ray by Gaussian noise of that percentage of the
  whole's diagonal, as a depth camera errs in depth;
* ``points-noise-0.25``, ``points-noise-0.5``: ``points``' very clouds (drawn from its
  seed), every point displaced by Gaussian noise of that percentage of their diagonal,
  as a scanner's merged cloud is.

Seeded like the tessellation variants (:func:`.variants.variant_seed`), so a rerun cuts
the same way.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from worker.engine.errors import MeshError
from worker.engine.geodesic import farthest_point_samples
from worker.engine.mesh_io import Mesh, cell_means, clean_mesh, face_areas
from worker.engine.scans import (
    grid_faces,
    one_view,
    organized_scan,
    organized_surface,
    view_frame,
    viewed_surface,
)
from worker.engine.topology import edge_keys

#: Number of discs the ``holes-*`` variants remove.
HOLE_COUNT = 5
#: SHREC'17's holes: the farthest samples hole centres are drawn among, the largest
#: radius as a share of the diameter, the fewest vertices a copy is decimated to.
SHREC_CENTRES = 70
SHREC_MAX_RADIUS = 0.2
SHREC_MIN_VERTICES = 300
#: SHREC'17's range camera (its generating script): it orbits the shape's up axis at
#: most this many degrees above or below the horizon, and a grid triangle is kept while
#: its longest edge is under a random whole number in this range (both ends included)
#: of the whole's median edges (of the grid's pixels where those are wider).
RANGE_ELEVATION = 25.0
RANGE_LONGEST_EDGES = (4, 33)
#: Similarity transforms scale by 10**u, u uniform in this range.
LOG10_SCALE_RANGE = (-2.0, 2.0)


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


def orbit_direction(up: str, rng: np.random.Generator) -> np.ndarray:
    """A unit vector (3,) at a uniformly random azimuth around the coordinate axis ``up``
    (``"x"``, ``"y"`` or ``"z"``) and an elevation uniform within ``RANGE_ELEVATION`` degrees
    of the horizon: where SHREC'17's range camera stands."""
    azimuth = rng.uniform(0.0, 2.0 * np.pi)
    elevation = np.radians(rng.uniform(-RANGE_ELEVATION, RANGE_ELEVATION))
    axis = "xyz".index(up)
    direction = np.empty(3)
    direction[[(axis + 1) % 3, (axis + 2) % 3, axis]] = (
        np.cos(elevation) * np.cos(azimuth),
        np.cos(elevation) * np.sin(azimuth),
        np.sin(elevation),
    )
    return direction


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (3, 3) (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def similarity(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """``mesh`` in a random rotation, scaled by ``10**u`` (u in ``LOG10_SCALE_RANGE``) and
    moved by up to its size."""
    scale = 10.0 ** rng.uniform(*LOG10_SCALE_RANGE)
    size = float(np.ptp(mesh.vertices, axis=0).max())
    moved = mesh.vertices @ random_rotation(rng).T + rng.uniform(-size, size, 3)
    return Mesh(vertices=moved * scale, faces=mesh.faces)


def decimated(mesh: Mesh, fraction: float) -> Mesh:
    """Quadric error decimation to ``fraction`` of the faces (Garland-Heckbert)."""
    import fast_simplification

    vertices, faces = fast_simplification.simplify(
        mesh.vertices, mesh.faces.astype(np.int32), target_reduction=1.0 - fraction
    )
    return clean_mesh(vertices, faces)


def random_resolution(mesh: Mesh, rng: np.random.Generator) -> int:
    """A vertex count uniform in ``SHREC_MIN_VERTICES`` .. the mesh's."""
    return int(rng.integers(min(SHREC_MIN_VERTICES, mesh.n_vertices), mesh.n_vertices + 1))


def _noise_sigma(mesh: Mesh, percent: float) -> float:
    """``percent``% of ``mesh``'s bounding box's diagonal."""
    return percent / 100.0 * float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))


def noisy_surface(mesh: Mesh, percent: float, rng: np.random.Generator) -> Mesh:
    """Every vertex displaced by isotropic Gaussian noise of sigma ``percent``% of the
    bounding box's diagonal."""
    sigma = _noise_sigma(mesh, percent)
    return Mesh(mesh.vertices + rng.normal(scale=sigma, size=mesh.vertices.shape), mesh.faces)


def noisy_view(mesh: Mesh, percent: float, rng: np.random.Generator) -> Mesh:
    """:func:`single_view` along a random direction, every vertex then moved along that
    direction by Gaussian noise of sigma ``percent``% of ``mesh``'s bounding box's
    diagonal (a depth camera's error lies along its rays)."""
    direction = random_direction(rng)
    return with_depth_noise(single_view(mesh, direction), mesh, direction, percent, rng)


def with_depth_noise(
    view: Mesh, whole: Mesh, direction: np.ndarray, percent: float, rng: np.random.Generator
) -> Mesh:
    """``view`` (of ``whole``, seen along ``direction``) with every vertex moved along the
    ray by Gaussian noise of sigma ``percent``% of ``whole``'s bounding box's diagonal."""
    depth = rng.normal(scale=_noise_sigma(whole, percent), size=view.n_vertices)
    return Mesh(view.vertices + depth[:, None] * direction, view.faces)


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
    faces, n = mesh.faces, mesh.n_vertices
    centres = rng.choice(n, size=min(HOLE_COUNT, n), replace=False)
    distance = dijkstra(edge_graph(mesh), directed=False, indices=centres).min(axis=0)
    areas = face_areas(mesh.vertices, faces)
    order = np.argsort(distance[faces].max(axis=1), kind="stable")
    removed = order[np.cumsum(areas[order]) <= share * areas.sum()]
    keep = np.ones(len(faces), dtype=bool)
    keep[removed] = False
    return largest_piece(mesh, keep)


def edge_graph(mesh: Mesh) -> sp.csr_matrix:
    """The mesh's edges, each once, as a graph weighted by their lengths (for an
    undirected shortest-path search)."""
    n = mesh.n_vertices
    start, end = np.divmod(np.unique(edge_keys(mesh.faces, n).ravel()), n)
    lengths = np.linalg.norm(mesh.vertices[start] - mesh.vertices[end], axis=1)
    return sp.csr_matrix((lengths, (start, end)), shape=(n, n))


def shrec_holes(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """SHREC'17's holes (module docstring): a random number of the ``SHREC_CENTRES``
    farthest samples, each eroding the faces within a graph distance along the edges
    uniform in (0, ``SHREC_MAX_RADIUS`` x the diameter); the largest remaining piece
    decimated to :func:`random_resolution`, in a random :func:`similarity`. The
    diameter is the double sweep's (the farthest vertex from the farthest vertex of a
    random one)."""
    graph = edge_graph(mesh)
    areas = np.bincount(
        mesh.faces.ravel(), np.repeat(face_areas(mesh.vertices, mesh.faces), 3), mesh.n_vertices
    )
    centres = farthest_point_samples(mesh.vertices, SHREC_CENTRES, areas)
    start = rng.integers(mesh.n_vertices, size=1)
    far = np.argmax(dijkstra(graph, directed=False, indices=start), axis=1)
    diameter = float(np.max(dijkstra(graph, directed=False, indices=far)))
    chosen = rng.choice(centres, size=int(rng.integers(1, len(centres) + 1)), replace=False)
    radii = rng.uniform(0.0, SHREC_MAX_RADIUS * diameter, size=len(chosen))
    reached = dijkstra(graph, directed=False, indices=chosen, limit=float(radii.max()))
    inside: np.ndarray = np.any(reached < radii[:, None], axis=0)
    piece = largest_piece(mesh, ~inside[mesh.faces].any(axis=1))
    target = random_resolution(piece, rng)
    if target < piece.n_vertices:
        piece = decimated(piece, target / piece.n_vertices)
    return similarity(piece, rng)


def _box_cells(first: np.ndarray, span: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every integer cell of boxes ``first`` (b, 2) .. ``first + span - 1``: (box, x, y)."""
    count = span[:, 0] * span[:, 1]
    box = np.repeat(np.arange(len(first)), count)
    offset = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    return box, first[box, 0] + offset % span[box, 0], first[box, 1] + offset // span[box, 0]


def _inside_at(
    corners: np.ndarray, depths: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Whether each point (p, 2) lies in its triangle ``corners`` (p, 3, 2) (a degenerate
    one contains none), and the triangle's ``depths`` (p, 3) interpolated there."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    e1, e2, p = b - a, c - a, points - a
    det = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
    safe = np.where(det != 0.0, det, 1.0)
    u = (p[:, 0] * e2[:, 1] - e2[:, 0] * p[:, 1]) / safe
    v = (e1[:, 0] * p[:, 1] - p[:, 0] * e1[:, 1]) / safe
    inside = (det != 0.0) & (u >= 0) & (v >= 0) & (u + v <= 1)
    at = depths[:, 0] + u * (depths[:, 1] - depths[:, 0]) + v * (depths[:, 2] - depths[:, 0])
    return inside, at


def depth_grid(mesh: Mesh, direction: np.ndarray, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """An orthographic depth image of ``mesh`` seen along ``-direction`` (a z-buffer:
    every triangle against the pixel centres of its bounding box).

    Returns
    -------
    image : (h, w) the height along ``direction`` of the nearest surface at each pixel
        centre, ``nan`` where the ray misses; pixels ``pitch`` apart.
    origin : (2,) the image's corner in the plane across the view.
    """
    local = mesh.vertices @ view_frame(direction).T
    origin = local[:, :2].min(axis=0)
    corners = (local[:, :2] - origin)[mesh.faces] / pitch  # in pixels
    depth = local[mesh.faces, 2]
    width, height = np.ceil((local[:, :2].max(axis=0) - origin) / pitch).astype(int) + 1
    low = np.ceil(corners.min(axis=1) - 0.5).astype(np.int64)
    span = np.maximum(np.floor(corners.max(axis=1) - 0.5).astype(np.int64) - low + 1, 0)
    tri, x, y = _box_cells(low, span)
    centres = np.stack([x + 0.5, y + 0.5], axis=1)
    hit, z = _inside_at(corners[tri], depth[tri], centres)
    image = np.full(height * width, -np.inf)
    np.maximum.at(image, (y * width + x)[hit], z[hit])
    image[np.isinf(image)] = np.nan
    return image.reshape(height, width), origin


def grid_points(
    image: np.ndarray, origin: np.ndarray, direction: np.ndarray, pitch: float
) -> np.ndarray:
    """(h, w, 3) the points a depth image (:func:`depth_grid`) saw, ``nan`` where its ray
    missed: the organized cloud a depth camera writes."""
    height, width = image.shape
    ys, xs = np.mgrid[0:height, 0:width]
    plane = origin + (np.stack([xs, ys], axis=-1) + 0.5) * pitch
    local = np.concatenate([plane, image[..., None]], axis=-1)
    points: np.ndarray = local @ view_frame(direction)
    return points


def far_viewpoint(mesh: Mesh, direction: np.ndarray) -> np.ndarray:
    """(3,) where an orthographic camera looking along ``-direction`` would stand as a
    depth camera: a thousand times ``mesh``'s extent away, its rays all but parallel."""
    extent = float(np.ptp(mesh.vertices, axis=0).max())
    viewpoint: np.ndarray = mesh.vertices.mean(axis=0) + 1e3 * extent * direction
    return viewpoint


def grid_mesh(points: np.ndarray, longest: float = np.inf) -> Mesh:
    """An organized cloud (:func:`grid_points`) triangulated as a grid, as SHREC'17's range
    scans were: two triangles per square of four hit pixels, one per square of three,
    with no test of the depths (an occlusion edge becomes a shortcut), but for triangles
    with an edge of at least ``longest``."""
    faces = grid_faces(np.isfinite(points).all(axis=2))
    corners = np.nan_to_num(points.reshape(-1, 3))[faces]
    sides = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    return clean_mesh(np.nan_to_num(points.reshape(-1, 3)), faces[sides.max(axis=1) < longest])


def median_edge(mesh: Mesh) -> float:
    """The median length of ``mesh``'s triangle sides (an inner edge counted twice)."""
    corners = mesh.vertices[mesh.faces]
    return float(np.median(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)))


def range_image(
    mesh: Mesh, rng: np.random.Generator, up: str = "z"
) -> tuple[np.ndarray, np.ndarray, float]:
    """SHREC'17's range scan (module docstring): the organized cloud (:func:`grid_points`)
    of a depth grid (:func:`depth_grid`) seen from :func:`orbit_direction` around ``up``
    with about :func:`random_resolution` pixels hit, the direction (3,) and the pixels'
    pitch."""
    direction = orbit_direction(up, rng)
    target = random_resolution(mesh, rng)
    extent = np.ptp(mesh.vertices @ view_frame(direction).T, axis=0)
    pitch = float(np.sqrt(extent[0] * extent[1] / target))
    image, origin = depth_grid(mesh, direction, pitch)
    for _ in range(2):  # the silhouette's share of the box decides the pixels hit
        pitch *= float(np.sqrt(max(int(np.count_nonzero(~np.isnan(image))), 1) / target))
        image, origin = depth_grid(mesh, direction, pitch)
    return grid_points(image, origin, direction, pitch), direction, pitch


def range_scan(mesh: Mesh, rng: np.random.Generator, up: str = "z") -> Mesh:
    """SHREC'17's range scan: :func:`range_image` triangulated with its shortcuts
    (:func:`grid_mesh`) shorter than a random number in ``RANGE_LONGEST_EDGES`` of
    ``mesh``'s median edges, or of the grid's pixels where those are wider (SHREC's grid
    and the whole's edges were of a size; a coarse scan of a fine whole would lose every
    triangle), its largest piece in a random :func:`similarity`."""
    points, _, pitch = range_image(mesh, rng, up)
    longest = int(rng.integers(RANGE_LONGEST_EDGES[0], RANGE_LONGEST_EDGES[1] + 1))
    return similarity(grid_mesh(points, longest * max(median_edge(mesh), pitch)), rng)


def range_cloud(mesh: Mesh, rng: np.random.Generator, up: str = "z") -> Mesh:
    """A scan drawn as :func:`range_scan`'s (from the variant's own seed) read as the
    service reads a depth camera's organized cloud: triangulated without the edges along
    the viewing ray (:func:`worker.engine.scans.organized_surface`, an orthographic
    camera's rays from a viewpoint far along the direction), its largest piece in a random
    similarity."""
    points, direction, _ = range_image(mesh, rng, up)
    vertices, faces = organized_surface(points, far_viewpoint(mesh, direction))
    return similarity(clean_mesh(vertices, faces), rng)


#: ``range-floor``: the frame's margin around the whole, in its size in the image.
FLOOR_MARGIN = 0.25


def floor_frame(
    mesh: Mesh,
    direction: np.ndarray,
    pitch: float,
    up: str = "z",
    walls: Sequence[tuple[str, float]] = (),
) -> np.ndarray:
    """(h, w, 3) the organized cloud a depth camera looking along ``-direction`` (its
    pixels ``pitch`` apart; from above the floor) sees of ``mesh`` standing on a floor
    (the plane across ``up`` at its lowest point) and before ``walls`` (each the plane
    across an axis at a value), the frame ``FLOOR_MARGIN`` around the whole: each plane
    is the quadrilateral the frame's corner rays meet it in, so that it runs out of the
    frame on every side it reaches (a plane the rays run along is not seen)."""
    frame = view_frame(direction)
    seen = mesh.vertices @ frame.T
    low, high = seen[:, :2].min(axis=0), seen[:, :2].max(axis=0)
    # A pixel beyond the margin, so that the planes cover the frame's every pixel.
    margin = FLOOR_MARGIN * (high - low) + pitch
    low, high = low - margin, high + margin
    corners = np.array([[low[0], low[1]], [high[0], low[1]], [high[0], high[1]], [low[0], high[1]]])
    on_plane = corners @ frame[:2]  # (4, 3) on the image plane, depth 0
    vertices, faces = [mesh.vertices], [mesh.faces]
    n = mesh.n_vertices
    for axis, value in ((up, float(mesh.vertices[:, "xyz".index(up)].min())), *walls):
        k = "xyz".index(axis)
        if abs(frame[2, k]) < 1e-6:
            continue
        depth = (value - on_plane[:, k]) / frame[2, k]
        vertices.append(on_plane + depth[:, None] * frame[2])
        faces.append(np.array([[n, n + 1, n + 2], [n, n + 2, n + 3]]))
        n += 4
    image, origin = depth_grid(Mesh(np.vstack(vertices), np.vstack(faces)), direction, pitch)
    points: np.ndarray = grid_points(image, origin, direction, pitch)
    # The pixels whose centres lie within half a pixel of the frame: on every plane.
    first = np.maximum(np.floor((low + pitch - origin) / pitch).astype(int), 0)
    last = np.floor((high - pitch - origin) / pitch).astype(int)
    return points[first[1] : last[1] + 1, first[0] : last[0] + 1]


def floor_shot(
    mesh: Mesh, rng: np.random.Generator, up: str = "z"
) -> tuple[np.ndarray, np.ndarray, float]:
    """:func:`range_cloud`'s scan (drawn from ``rng``) of the whole standing on a floor,
    the camera above it (the elevation's sign made positive; :func:`floor_frame`): the
    organized cloud (h, w, 3), the camera's far viewpoint (3,) and the pixels' pitch."""
    _, direction, pitch = range_image(mesh, rng, up)
    direction["xyz".index(up)] = abs(direction["xyz".index(up)])
    return floor_frame(mesh, direction, pitch, up), far_viewpoint(mesh, direction), pitch


def range_floor(mesh: Mesh, rng: np.random.Generator, up: str = "z") -> Mesh:
    """:func:`floor_shot`'s frame (its generator drawn from ``range-cloud``'s seed), read
    as the service reads a depth camera's organized cloud: the floor left out, then
    triangulated (:func:`worker.engine.scans.organized_scan`), its largest piece in the
    same random similarity."""
    points, viewpoint, _ = floor_shot(mesh, rng, up)
    vertices, faces, _ = organized_scan(points, viewpoint)
    return similarity(clean_mesh(vertices, faces), rng)


def view_points(mesh: Mesh, rng: np.random.Generator, up: str = "z") -> Mesh:
    """:func:`range_cloud`'s scan (its generator drawn from that variant's seed) read
    without its grid: the points that saw the surface in a fixed random order, triangulated
    as seen from the camera (:func:`worker.engine.scans.viewed_surface`), the largest
    piece in the same random similarity."""
    points, direction, _ = range_image(mesh, rng, up)
    seen = points.reshape(-1, 3)[np.isfinite(points).all(axis=2).ravel()]
    shuffled = seen[np.random.default_rng(0).permutation(len(seen))]
    vertices, faces, _ = viewed_surface(shuffled, far_viewpoint(mesh, direction))
    return similarity(clean_mesh(vertices, faces), rng)


def whole_points(mesh: Mesh, rng: np.random.Generator, percent: float = 0.0) -> Mesh:
    """The whole's vertices in a random :func:`similarity` and a random order, without
    their faces, each displaced by isotropic Gaussian noise of sigma ``percent``% of
    their bounding box's diagonal, read as the service reads such a file (the sensor at
    the origin, :func:`worker.engine.scans.one_view`)."""
    moved = similarity(mesh, rng)
    points = moved.vertices[rng.permutation(moved.n_vertices)]
    if percent:  # drawn last: the same similarity and order as without noise
        points = points + rng.normal(scale=_noise_sigma(moved, percent), size=points.shape)
    vertices, faces, _ = one_view(points, np.zeros(3))
    return clean_mesh(vertices, faces)


#: ``view-voxels``: the voxel's edge, in pixels of the scan.
VOXEL_PIXELS = 2.0


def voxel_means(points: np.ndarray, size: float) -> np.ndarray:
    """(k, 3) the mean of ``points`` (n, 3) in each cube of edge ``size`` that holds any
    (:func:`worker.engine.mesh_io.cell_means`), as a voxel filter thins a cloud."""
    return cell_means(points, size)[0]


def view_voxels(mesh: Mesh, rng: np.random.Generator, up: str = "z") -> Mesh:
    """:func:`range_cloud`'s scan (its generator drawn from that variant's seed) thinned
    as point-cloud tools thin a scan (a voxel filter: the mean of the points in each
    cube of :data:`VOXEL_PIXELS` pixels, the cubes aligned with the mesh's frame), read as
    :func:`view_points` reads its points: on no pixel lattice, by the Delaunay
    triangulation of their image from the camera."""
    points, direction, pitch = range_image(mesh, rng, up)
    seen = points.reshape(-1, 3)[np.isfinite(points).all(axis=2).ravel()]
    means = voxel_means(seen, VOXEL_PIXELS * pitch)
    shuffled = means[np.random.default_rng(0).permutation(len(means))]
    vertices, faces, _ = viewed_surface(shuffled, far_viewpoint(mesh, direction))
    return similarity(clean_mesh(vertices, faces), rng)


def floor_voxels(mesh: Mesh, rng: np.random.Generator, up: str = "z") -> Mesh:
    """:func:`floor_shot`'s frame (its generator drawn from ``range-cloud``'s seed)
    without its grid, thinned by :func:`view_voxels`' filter and read as the service
    reads a PCD of such points with its camera's ``VIEWPOINT``
    (:func:`worker.engine.scans.one_view`: on no lattice, the floor left out of their
    binned image; not one view from the camera, as a floor seen at a grazing angle and so
    filtered may be, seen once more from afar, the floor kept), its largest piece in the
    same random similarity."""
    vertices, faces, _ = one_view(*floor_voxel_points(mesh, rng, up))
    return similarity(clean_mesh(vertices, faces), rng)


def floor_voxel_points(
    mesh: Mesh, rng: np.random.Generator, up: str = "z"
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`floor_voxels`' points (k, 3), its frame's finite points thinned by
    ``view-voxels``' filter in a fixed random order, and its camera's viewpoint (3,)."""
    points, viewpoint, pitch = floor_shot(mesh, rng, up)
    seen = points.reshape(-1, 3)[np.isfinite(points).all(axis=2).ravel()]
    means = voxel_means(seen, VOXEL_PIXELS * pitch)
    return means[np.random.default_rng(0).permutation(len(means))], viewpoint


def single_view(mesh: Mesh, direction: np.ndarray) -> Mesh:
    """The faces a scanner looking along ``-direction`` (3,) sees: facing it, and with no
    other face in front of their centroid on the ray through it (orthographic rays;
    triangles found through a uniform grid of their projected bounding boxes)."""
    vertices, faces = mesh.vertices, mesh.faces
    frame = view_frame(direction)
    local = vertices @ frame.T
    plane, depth = local[:, :2], local[:, 2]  # larger depth is nearer the scanner
    corners, corner_depth = plane[faces], depth[faces]
    centroid, centroid_depth = corners.mean(axis=1), corner_depth.mean(axis=1)
    normals = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    facing = normals @ frame[2] > 0.0

    # Each triangle in every grid cell its projected bounding box touches.
    low, high = corners.min(axis=1), corners.max(axis=1)
    cell = 2.0 * float(np.median(np.max(high - low, axis=1)))
    origin = plane.min(axis=0)
    first = np.floor((low - origin) / cell).astype(np.int64)
    span = np.floor((high - origin) / cell).astype(np.int64) - first + 1
    width = int((first[:, 0] + span[:, 0]).max()) + 1
    triangle, x, y = _box_cells(first, span)
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
    inside, at_centroid = _inside_at(corners[other], corner_depth[other], centroid[face])
    inside &= other != face
    margin = 1e-6 * float(np.ptp(depth))
    hidden = np.zeros(len(faces), dtype=bool)
    hidden[face[inside & (at_centroid > centroid_depth[face] + margin)]] = True
    return largest_piece(mesh, facing & ~hidden)


#: A variant drawn from another's seed (:func:`.variants.make_variant`): the same scans,
#: read another way.
DRAWN_AS = {
    "view-points": "range-cloud",
    "view-voxels": "range-cloud",
    "range-floor": "range-cloud",
    "floor-voxels": "range-cloud",
    "view-noise-0.25": "view",
    "view-noise-0.5": "view",
    "points-noise-0.25": "points",
    "points-noise-0.5": "points",
}

#: The variants shot by the range camera: made with the axis their whole stands on
#: (:data:`.datasets.UP_AXES`; z when not told) as well.
ORBITING: dict[str, Callable[[Mesh, np.random.Generator, str], Mesh]] = {
    "range": range_scan,
    "range-cloud": range_cloud,
    "view-points": view_points,
    "view-voxels": view_voxels,
    "range-floor": range_floor,
    "floor-voxels": floor_voxels,
}

#: name -> how to make it from a mesh and a random generator, in report order.
PARTIAL_VARIANTS: dict[str, Callable[[Mesh, np.random.Generator], Mesh]] = {
    "cut-5": lambda mesh, rng: planar_cut(mesh, 0.05, random_direction(rng)),
    "cut-15": lambda mesh, rng: planar_cut(mesh, 0.15, random_direction(rng)),
    "cut-30": lambda mesh, rng: planar_cut(mesh, 0.30, random_direction(rng)),
    "holes-10": lambda mesh, rng: geodesic_holes(mesh, 0.10, rng),
    "holes-25": lambda mesh, rng: geodesic_holes(mesh, 0.25, rng),
    "view": lambda mesh, rng: single_view(mesh, random_direction(rng)),
    "range": range_scan,
    "range-cloud": range_cloud,
    "view-points": view_points,
    "view-voxels": view_voxels,
    "range-floor": range_floor,
    "floor-voxels": floor_voxels,
    "points": whole_points,
    "shrec-holes": shrec_holes,
    "noise-0.25": lambda mesh, rng: noisy_surface(mesh, 0.25, rng),
    "noise-0.5": lambda mesh, rng: noisy_surface(mesh, 0.5, rng),
    "noise-1": lambda mesh, rng: noisy_surface(mesh, 1.0, rng),
    "view-noise-0.25": lambda mesh, rng: noisy_view(mesh, 0.25, rng),
    "view-noise-0.5": lambda mesh, rng: noisy_view(mesh, 0.5, rng),
    "points-noise-0.25": lambda mesh, rng: whole_points(mesh, rng, 0.25),
    "points-noise-0.5": lambda mesh, rng: whole_points(mesh, rng, 0.5),
}
