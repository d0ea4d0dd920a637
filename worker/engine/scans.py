"""Organized point clouds: a depth camera's grid of points, triangulated by its grid.

A depth camera (or a range scanner) measures one point per pixel of its image, so its
cloud comes with the neighbours a surface needs: four pixels that see the surface make
a square of it. PCD files (the Point Cloud Library's format) keep that grid when they
are *organized* (``HEIGHT`` > 1, one point per pixel in row order, ``NaN`` where the
pixel saw nothing) and the sensor's position (``VIEWPOINT``); E57 files (laser
scanners') keep it in a *structured* scan, each point's row and column index on the
scanner's angular grid, and the scanner's position in the scan's pose.

A cloud without its grid (a PCD of ``HEIGHT`` 1, a PLY or OBJ without faces, a text file
of points) is read as one view: its points seen from its sensor (the PCD's
``VIEWPOINT``; the origin of the points' frame otherwise, where a depth camera writes
them) each lie on their own ray, so the rays' directions are the pixels a grid would
have given, and their Delaunay triangulation is the grid's (:func:`viewed_surface`),
gaps left open as the grid leaves them. In the camera's own frame the pixels are a
lattice, and the grid itself is found again (:func:`sensor_grid`); in any other frame the
camera's is found first, from the steps between neighbouring points
(:func:`sensor_axes`), and points moved a little off their pixels after the scan
(smoothed, or written with few decimals) are read on the lattice they lie near
(:func:`snapped_steps`). A view on no lattice written in another frame is seen from afar
along the direction it overlaps itself least in (:func:`unfolded_sight`, :func:`one_view`).
Points of which some hide behind others as seen from there (a whole object's, a scan
merged from several views) are refused: their neighbours are not known, and guessing
them fuses touching sheets (docs/decisions.md, "Point clouds stay refused"). So is an E57
scan without indices.

The grid is triangulated as a scanner's software does: two triangles per square of four
valid pixels, one per square of three (:func:`grid_faces`). Where the surface seen by two
neighbouring pixels is interrupted (an occluding edge, a limb in front of the body),
their triangle runs along the viewing ray over the gap: such a *shadowed* edge, within
``SHADOW_DEGREES`` of the ray from the sensor, leaves its triangles out, the rule of
PCL's ``OrganizedFastMesh`` (Holz and Behnke 2012, "Fast range image segmentation and
smoothing using approximate surface reconstruction and region growing").

A range scan written as a mesh (SHREC'17's range scans) keeps those shortcuts, and has
no viewpoint; when it is an orthographic grid, its line of sight is found from its
triangles (:func:`grid_sight`) and the same rule applies along it.
"""

from __future__ import annotations

import struct
import tempfile
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cache, cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import MeshError, PointCloudError, UnreadableMeshError
from .formats import DEFAULT_MAX_DECOMPRESSED_BYTES
from .topology import edge_keys, keys_seen_once, unique_rows

if TYPE_CHECKING:
    from scipy.spatial import Delaunay, cKDTree

#: An edge closer than this to its sensor's viewing ray crosses a gap, not the surface.
SHADOW_DEGREES = 12.5

#: What a file of points that are not one view is told, after why.
UPLOAD_A_VIEW = (
    "Upload a triangle mesh, or one view's points as its sensor saw them (in the sensor's "
    "frame, or a .pcd with its VIEWPOINT), or its organized cloud (.pcd, one point per "
    "pixel) or structured .e57 scan."
)

#: :func:`viewed_surface`: the share of a cloud's points that must lie on the surface
#: seen from its sensor for it to be one view (92-100% of a range scan's, at most 48% of
#: a whole object's vertices seen from afar: docs/decisions.md), and a triangle's longest
#: edge in the image, in spacings of its corners (the least of their median edges),
#: past which it crosses a gap (a grid's diagonal is 1.41 spacings, the edge across a
#: missing pixel 2; a voxel-filtered or smoothed view's own edges reach past 1.5).
VIEW_SHARE = 0.8
GAP_SPACINGS = 1.9

#: PCD field types (``TYPE`` and ``SIZE``) as numpy's little-endian type letters.
_PCD_TYPES = {"F": "f", "I": "i", "U": "u"}
#: PCL's ``VIEWPOINT`` when a header has none: at the origin, the identity quaternion.
_PCD_VIEWPOINT = ["0", "0", "0", "1", "0", "0", "0"]


@dataclass(frozen=True)
class Cloud:
    """The point cloud a surface was triangulated from: its ``points`` that saw the
    surface, its sensor ``grid``, (width, height) pixels (None: a cloud without one,
    triangulated as seen from its sensor, :func:`viewed_surface`), and the points of the
    floor, table or wall its object stood on or against, left out
    (:func:`without_support`; None: not looked for, :func:`viewed_surface` says when), and
    of points that are not one view, those hidden from where they were seen, left out
    (:func:`whole_view`; None: one view)."""

    points: int
    grid: tuple[int, int] | None = None
    support: int | None = None
    hidden: int | None = None


def grid_faces(valid: np.ndarray) -> np.ndarray:
    """(m, 3) int triangles of an (H, W) grid of pixels, numbered in row order: two per
    square of four ``valid`` pixels (split along the diagonal from its top left), one per
    square of three."""
    height, width = valid.shape
    index = np.arange(height * width).reshape(height, width)
    a, b = index[:-1, :-1].ravel(), index[:-1, 1:].ravel()  # a b
    c, d = index[1:, :-1].ravel(), index[1:, 1:].ravel()  # c d
    hit = valid.ravel()
    ha, hb, hc, hd = hit[a], hit[b], hit[c], hit[d]
    every = ha & hb & hc & hd
    triangles = [
        ((a, b, d), every | (ha & hb & hd & ~hc)),
        ((a, d, c), every | (ha & hd & hc & ~hb)),
        ((a, b, c), ha & hb & hc & ~hd),
        ((b, d, c), hb & hd & hc & ~ha),
    ]
    return np.concatenate([np.stack(t, axis=1)[keep] for t, keep in triangles])


def unshadowed(
    points: np.ndarray,
    faces: np.ndarray,
    viewpoint: np.ndarray | None = None,
    degrees: float = SHADOW_DEGREES,
    *,
    sight: np.ndarray | None = None,
) -> np.ndarray:
    """(m,) bool, the ``faces`` none of whose edges lies within ``degrees`` of the ray from
    ``viewpoint`` (3,) to its first end (:data:`SHADOW_DEGREES`), or of the orthographic
    rays along ``sight`` (3,) (:func:`grid_sight`)."""
    cosine = np.cos(np.radians(degrees))
    kept = np.ones(len(faces), dtype=bool)
    for first, second in ((0, 1), (1, 2), (2, 0)):
        start, end = points[faces[:, first]], points[faces[:, second]]
        edge = end - start
        ray = np.broadcast_to(sight, start.shape) if sight is not None else start - viewpoint
        length = np.linalg.norm(edge, axis=1) * np.linalg.norm(ray, axis=1)
        along = np.abs(np.einsum("ij,ij->i", edge, ray))
        kept &= along < cosine * np.maximum(length, np.finfo(float).tiny)
    return kept


#: :func:`grid_sight`: how far a mesh's triangles' areas along one direction may spread
#: (their standard deviation over their mean) for it to be an orthographic depth grid,
#: and the fewest triangles that can tell (the direction has 3 unknowns: a few triangles
#: fit any).
GRID_SPREAD = 0.01
GRID_MIN_FACES = 20
#: A mesh of more than ``4 GRID_TRIAL`` triangles is first tried on a seeded sample of
#: ``GRID_TRIAL`` of them: most meshes are no grid, and the sample tells in a fraction of
#: the time the whole does (30 ms at 105,000 triangles).
GRID_TRIAL = 256


def grid_sight(points: np.ndarray, faces: np.ndarray) -> np.ndarray | None:
    """The line of sight (3,) of a mesh triangulated as an orthographic depth grid (a range
    scan written as a mesh, as SHREC'17's were), or None for any other mesh.

    Every triangle of such a grid covers half a pixel, so along the scanner's rays ``d``
    each projects to the same area: ``(b - a) x (c - a) . d`` is one constant for every
    face ``abc``, a shortcut across an occlusion gap included (its projection is a
    pixel's too). The least-squares solution of ``N v = 1`` over the faces' doubled area
    vectors ``N`` finds ``d = v / |v|``; the mesh is such a grid when the projected areas
    then spread by at most :data:`GRID_SPREAD` of their mean, all positive, over at least
    :data:`GRID_MIN_FACES` faces (a whole, a cut or a view made of a mesh's own faces
    spread far more). A grid's every triangle projects alike, so a sample of them
    (:data:`GRID_TRIAL`) refuses most other meshes first.
    """
    if len(faces) > 4 * GRID_TRIAL:
        trial = np.random.default_rng(0).choice(len(faces), GRID_TRIAL, replace=False)
        if _sight_of(points, faces[trial]) is None:
            return None
    return _sight_of(points, faces)


def _sight_of(points: np.ndarray, faces: np.ndarray) -> np.ndarray | None:
    """:func:`grid_sight` on every one of ``faces``."""
    corners = points[faces]
    doubled = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    size = np.linalg.norm(doubled, axis=1)
    doubled = doubled[size > 1e-12 * max(float(size.max(initial=0.0)), np.finfo(float).tiny)]
    if len(doubled) < GRID_MIN_FACES:
        return None
    solution = np.linalg.lstsq(doubled, np.ones(len(doubled)), rcond=None)[0]
    projected = doubled @ solution
    mean = float(projected.mean())
    if mean <= 0.0 or projected.min() <= 0.0 or projected.std() > GRID_SPREAD * mean:
        return None
    sight: np.ndarray = solution / np.linalg.norm(solution)
    return sight


#: :func:`support_planes`: a plane is searched for among the points within
#: ``SUPPORT_BAND`` times the grid's spacing of it (the median distance between
#: neighbouring pixels' points, along the finer of its rows and columns); it is the
#: floor, a table or a wall the object stands on or against when it holds at least
#: ``SUPPORT_SHARE`` of the points and leaves as many further than that from it, runs out
#: of the frame along at least ``SUPPORT_BORDER`` of the grid's border, and
#: ``SUPPORT_FRONT`` of those further points lie on the sensor's side of it
#: (docs/decisions.md, "A floor or a wall in the frame is left out": every support of 50
#: views of five figures on a floor or before a wall went, and no point of a figure's,
#: nor of 924 range scans of TOSCA's and SCAPE's wholes). ``SUPPORT_PLANES`` planes are
#: tried, the largest first (a floor and a wall: a corner of a room), each the best of
#: ``SUPPORT_TRIALS`` planes through three points near the frame's border (within
#: ``SUPPORT_RING`` of its size: a support reaches it), scored on ``SUPPORT_SAMPLE``
#: points (RANSAC: Fischler and Bolles 1981), seeded so that a file is always read alike.
SUPPORT_BAND = 2.0
SUPPORT_SHARE = 0.05
SUPPORT_BORDER = 0.15
SUPPORT_FRONT = 0.98
SUPPORT_PLANES = 4
SUPPORT_TRIALS = 256
SUPPORT_SAMPLE = 4000
SUPPORT_RING = 0.05
#: What is left out of a support: its points within ``SUPPORT_SIGMAS`` times their
#: residuals' spread of the plane (their median absolute residual over 0.6745, a
#: Gaussian's sigma), measured in ``SUPPORT_RANGES`` bands of distance from the sensor (a
#: depth camera's noise grows with the square of the depth), at least ``SUPPORT_LEAST``
#: of the search's band (an exact plane's points, and not the object's feet on it) and at
#: most the band; the plane refitted to them ``SUPPORT_REFITS`` times by least squares,
#: so that the object's points near it pull the fit off it no more.
SUPPORT_SIGMAS = 4.0
SUPPORT_RANGES = 8
SUPPORT_LEAST = 0.02
SUPPORT_REFITS = 4


def without_support(points: np.ndarray, viewpoint: np.ndarray) -> tuple[np.ndarray, int]:
    """An organized cloud (H, W, 3) (non-finite where a pixel saw nothing) with the planes
    its object stands on or against left out (:func:`support_planes`): (H, W, 3) those
    pixels made ``nan``, and how many points they were."""
    support, _ = support_planes(points, viewpoint)
    kept = points.copy()
    kept[support] = np.nan
    return kept, int(np.count_nonzero(support))


#: A plane :func:`support_planes` took: its unit normal (3,), offset, and (H, W) how near
#: it each pixel's point must lie to be its own.
Plane = tuple[np.ndarray, float, np.ndarray]


def support_planes(points: np.ndarray, viewpoint: np.ndarray) -> tuple[np.ndarray, list[Plane]]:
    """The planes an organized cloud's (H, W, 3) object stands on or against: (H, W) bool
    the pixels on them, and the planes taken.

    A depth camera's frame nearly always holds the floor or table under its object and
    often a wall behind it; read with them, the object and its support are one piece, and
    the piece matches no enrolled object. What tells a support from the object's own flat
    faces (a box's, a tablet's, an underside seen from below): a support runs out of the
    picture, where a framed object's faces end inside it, and the object stands in front
    of it as the sensor sees it, where the rest of a box lies behind its nearest face
    (:data:`SUPPORT_BAND` .. :data:`SUPPORT_REFITS`)."""
    valid = np.isfinite(points).all(axis=2)
    count = int(np.count_nonzero(valid))
    border = np.zeros(valid.shape, dtype=bool)
    border[[0, -1]] = border[:, [0, -1]] = True
    reaches = SUPPORT_BORDER * np.count_nonzero(border)  # the border's pixels a support holds
    if np.count_nonzero(valid & border) < reaches:
        return np.zeros_like(valid), []  # a framed object: no plane runs out of the frame
    # The finer of the grid's two directions: a floor seen at a slant is coarse along one.
    differences = (points[:, 1:] - points[:, :-1], points[1:] - points[:-1])
    steps = [np.linalg.norm(d[np.isfinite(d).all(axis=-1)], axis=-1) for d in differences]
    if count < 3 or not any(len(s) for s in steps):
        return np.zeros_like(valid), []  # no two neighbouring pixels saw the surface
    band = SUPPORT_BAND * min(float(np.median(s)) for s in steps if len(s))
    width = max(1, round(SUPPORT_RING * min(valid.shape)))
    ring = np.ones_like(valid)
    ring[width:-width, width:-width] = False
    flat = np.nan_to_num(points)
    reach = np.linalg.norm(flat - viewpoint, axis=2)
    rng = np.random.default_rng(0)
    support = np.zeros_like(valid)
    taken: list[Plane] = []
    candidates = valid.copy()
    for _ in range(SUPPORT_PLANES):
        if np.count_nonzero(valid & ~support & border) < reaches:
            break  # no plane left can run out of the frame
        if np.count_nonzero(candidates & ring) < 3:
            break  # none left to search from
        plane = _largest_plane(flat, reach, candidates, ring, band, rng)
        if plane is None:
            break
        normal, offset, within = plane
        distance = flat @ normal - offset
        on = valid & ~support & (np.abs(distance) < within)
        # Clearly not on it: beyond the search's band and twice its own points' band.
        off = valid & ~support & (np.abs(distance) >= np.maximum(band, 2.0 * within))
        side = np.sign(viewpoint @ normal - offset)
        front = np.mean(np.sign(distance[off]) == side) if off.any() else 0.0
        if (
            min(np.count_nonzero(on), np.count_nonzero(off)) >= SUPPORT_SHARE * count
            and front >= SUPPORT_FRONT
            and np.count_nonzero(on & border) >= reaches
        ):
            support |= on
            candidates &= ~on
            taken.append(plane)
        else:  # not tried again, nor anything near it
            candidates &= np.abs(distance) >= band
    return support, taken


def _largest_plane(
    points: np.ndarray,
    reach: np.ndarray,
    candidates: np.ndarray,
    ring: np.ndarray,
    band: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, float, np.ndarray] | None:
    """The plane through three of the ``candidates`` (H, W) bool of ``points`` (H, W, 3) in
    the ``ring`` near the frame's border within ``band`` of which most of
    :data:`SUPPORT_SAMPLE` candidates lie (the best of :data:`SUPPORT_TRIALS`), refitted to
    that sample's points near it: its unit normal (3,) and offset, and (H, W) how near it
    each pixel must lie to be its own, from the spread of the sample's residuals at its
    ``reach`` (distance from the sensor) (:data:`SUPPORT_SIGMAS` .. :data:`SUPPORT_REFITS`);
    None when every triple drawn lies (nearly) on a line, or no sampled point lies near
    the plane."""
    near_border, pool, pool_reach = points[candidates & ring], points[candidates], reach[candidates]
    drawn = rng.choice(len(pool), size=min(SUPPORT_SAMPLE, len(pool)), replace=False)
    sample, sample_reach = pool[drawn], pool_reach[drawn]
    a, b, c = (near_border[rng.integers(len(near_border), size=SUPPORT_TRIALS)] for _ in range(3))
    normals = np.cross(b - a, c - a)
    size = np.linalg.norm(normals, axis=1)
    # Sides at 6 degrees or more: three points along one row of pixels fit any plane.
    fine = size > 0.1 * np.linalg.norm(b - a, axis=1) * np.linalg.norm(c - a, axis=1)
    if not fine.any():
        return None
    normals = normals[fine] / size[fine, None]
    offsets = np.einsum("ij,ij->i", normals, a[fine])
    best = np.argmax(np.count_nonzero(np.abs(sample @ normals.T - offsets) < band, axis=0))
    normal, offset = normals[best], float(offsets[best])
    within = band
    for _ in range(SUPPORT_REFITS):
        near = sample[np.abs(sample @ normal - offset) < within]
        if len(near) < 3:
            break
        centre = near.mean(axis=0)
        normal = np.linalg.svd(near - centre, full_matrices=False)[2][2]
        offset = float(centre @ normal)
        spread = float(np.median(np.abs(near @ normal - offset))) / 0.6745
        within = min(max(SUPPORT_SIGMAS * spread, SUPPORT_LEAST * band), band)
    # What is its own: the spread in bands of reach holding equal shares of its points.
    residual = np.abs(sample @ normal - offset)
    held = residual < band
    if not held.any():
        return None
    residual, held_reach = residual[held], sample_reach[held]
    order = np.argsort(held_reach)
    parts = np.array_split(order, min(SUPPORT_RANGES, len(order)))
    spreads = np.array([np.median(residual[k]) for k in parts]) / 0.6745
    ranges = np.searchsorted(held_reach[[k[0] for k in parts[1:]]], reach, side="right")
    own = np.clip(SUPPORT_SIGMAS * spreads[ranges], SUPPORT_LEAST * band, band)
    return normal, offset, own


def view_frame(direction: np.ndarray) -> np.ndarray:
    """(3, 3) rows: two unit vectors across a view, and its ``direction`` (3,, any length
    but zero) made a unit vector; (k, 3, 3) of ``k`` directions (k, 3)."""
    view = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    helper = np.where(np.abs(view[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    across = np.cross(view, helper)
    across /= np.linalg.norm(across, axis=-1, keepdims=True)
    return np.stack([across, np.cross(view, across), view], axis=-2)


def organized_scan(
    points: np.ndarray, viewpoint: np.ndarray
) -> tuple[np.ndarray, np.ndarray, Cloud]:
    """An organized cloud (H, W, 3) as a file's is read: its pixels that saw nothing left
    out (:func:`at_the_sensor`), the planes its object stands on or against too
    (:func:`without_support`), then its surface (:func:`organized_surface`), and the
    cloud it was."""
    height, width = points.shape[:2]
    points = np.where(at_the_sensor(points, viewpoint)[..., None], np.nan, points)
    kept, support = without_support(points, viewpoint)
    vertices, faces = organized_surface(kept, viewpoint)
    return vertices, faces, Cloud(len(vertices), (width, height), support)


def at_the_sensor(points: np.ndarray, viewpoint: np.ndarray) -> np.ndarray:
    """(...) bool: which of ``points`` (..., 3) lie exactly at the sensor's ``viewpoint``
    (3,): no surface it saw does, and cameras' software writes a pixel that saw nothing so
    (Kinect's and RealSense's point clouds give it as (0, 0, 0), the sensor in its own
    frame)."""
    at: np.ndarray = (points == viewpoint).all(axis=-1)
    return at


def organized_surface(points: np.ndarray, viewpoint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An organized cloud's surface: (n, 3) its valid points and (m, 3) the grid's
    unshadowed triangles on them.

    Parameters
    ----------
    points : (H, W, 3) float, a point per pixel, any coordinate not finite where the
        pixel saw nothing.
    viewpoint : (3,) float, the sensor's position in the points' frame.
    """
    valid = np.isfinite(points).all(axis=2)
    flat = points.reshape(-1, 3)
    faces = grid_faces(valid)
    faces = faces[unshadowed(np.nan_to_num(flat), faces, viewpoint)]
    number = np.cumsum(valid.ravel()) - 1
    return flat[valid.ravel()], number[faces]


def viewed_surface(
    points: np.ndarray,
    viewpoint: np.ndarray,
    axes: np.ndarray | None = None,
    *,
    find_frame: bool = True,
    start: Callable[[], np.ndarray] | None = None,
    sensor_known: bool = True,
    least_seen: float = VIEW_SHARE,
) -> tuple[np.ndarray, np.ndarray, Cloud]:
    """A cloud without a grid read as one view: (n, 3) its finite points and (m, 3) the
    triangles of the surface its sensor saw, facing the sensor, and the cloud it was.

    Seen from ``viewpoint`` (3,), each point of one view lies on its own ray, and the
    rays' directions are the pixels of the sensor's image: the points' central (pinhole)
    projection on the plane across their mean ray is the image, up to a homography
    (exact for a depth camera at the origin of its points' frame). Its Delaunay
    triangulation is the grid's own: each pixel joined to its neighbours, a square split
    along a diagonal. As on a grid, a triangle is left out when an edge crosses a gap:
    longer in the image than ``GAP_SPACINGS`` times the spacing of its corners (the
    least of their median edges in the image: the points' own spacing however irregular
    or noisy; a missing pixel's hole, which the grid leaves, may close), or shadowed
    (:func:`unshadowed`, an occluding edge along the ray). Points on
    a camera's pixel lattice (:func:`sensor_grid`, the sensor's ``axes`` (3, 3) as
    columns in the points' frame, theirs by default, else, with ``find_frame``, a frame
    found from the points, :func:`sensor_axes`, its rounds from ``start``'s direction,
    there also points moved a little off their pixels, :func:`snapped_steps`) are
    triangulated by that grid instead
    (:func:`organized_surface`), each triangle facing the sensor; an orthographic grid is
    seen along its own line of sight, from ``viewpoint`` if it stands on that line
    (:func:`_seen_along`), else from afar on the side its silhouette says
    (:func:`sensor_side`). The planes its object stands on or against are left out
    (:func:`without_support`), the points' rectangle in the image taken for the frame:
    on a lattice the view is an organized frame; else its image binned in cells of about
    its points' median spacing is (:func:`_binned_support`, not when too coarse), and only
    the rest is triangulated (:func:`_seen_triangles`). Not from a
    ``viewpoint`` that is not ``sensor_known`` (guessed from afar along a direction the
    points overlap themselves least in): seen from the wrong side, an object's face with
    the rest of it behind passes for one. Not looked for, the cloud's ``support`` is None.

    Raises
    ------
    PointCloudError
        Fewer than three points not on one line as seen from ``viewpoint``; a point
        beside or behind it (no image plane holds every ray); or fewer than
        ``least_seen`` of the points on the surface (points hidden behind others, as a
        whole object's or several views' are, are joined to them only along the rays).
    """
    finite = points[np.isfinite(points).all(axis=1)]
    if len(finite) < 3:
        raise PointCloudError(f"The file holds too few points to make a surface. {UPLOAD_A_VIEW}")
    trials = LatticeTrials(finite, viewpoint)
    lattice, sensor, guessed = sensor_grid(finite, viewpoint, axes, trials=trials), viewpoint, None
    searched = find_frame and lattice is None
    found = _found_lattice(finite, viewpoint, trials, start) if searched else None
    if found is not None:
        lattice, frame, orthographic = found
        if orthographic and not _seen_along(finite, viewpoint, frame[:, 2]):
            guessed = frame[:, 2]
            sensor = guessed_viewpoint(finite, guessed)
    if lattice is not None:
        seen_from = sensor
        if guessed is not None:  # the grid's silhouette says which side its sensor stood on
            vertices, faces = organized_surface(lattice, seen_from)
            sensor = guessed_viewpoint(finite, sensor_side(vertices, faces, guessed) * guessed)
        # An organized frame, the points' rectangle its border.
        kept, support = without_support(lattice, sensor) if sensor_known else (lattice, None)
        if guessed is None or support:
            vertices, faces = organized_surface(kept, seen_from)
        return *_facing(vertices, faces, sensor), Cloud(len(vertices), support=support)
    where = ", ".join(f"{c:g}" for c in viewpoint)
    rays = finite - viewpoint
    length = np.linalg.norm(rays, axis=1)
    mean_ray = (rays / np.maximum(length, np.finfo(float).tiny)[:, None]).mean(axis=0)
    # Rays that cancel out (|mean| <= 1e-3) have one within 1e-3 of square to it anyway.
    frame = view_frame(mean_ray) if np.linalg.norm(mean_ray) > 1e-3 else np.zeros((3, 3))
    depth = rays @ frame[2]
    if depth.min() <= 1e-3 * length.max():
        raise PointCloudError(
            f"The file holds points but no triangles, and they are not one view from the "
            f"sensor at ({where}): some lie beside or behind it. {UPLOAD_A_VIEW}"
        )
    image = rays @ frame[:2].T / depth[:, None]
    # The support is looked for first, so that only the rest is triangulated (a floor
    # frame's points are mostly the floor's, and Delaunay's time grows faster than them).
    whole = _delaunay(image, where) if len(image) <= SPACING_EXACT else None
    edges = None if whole is None else median_edges(image, whole.vertex_neighbor_vertices)
    left_out = (
        _binned_support(finite, image, image_spacing(image, edges), viewpoint)
        if sensor_known
        else None
    )
    support = None if left_out is None else int(np.count_nonzero(left_out))
    if left_out is not None and support:
        rest = ~left_out
        remaining = _delaunay(image[rest], where)
        faces = _seen_triangles(finite[rest], image[rest], viewpoint, remaining, image[left_out])
        seen = float(np.unique(faces).size / np.count_nonzero(rest))
        if seen < least_seen:  # one view with its support, if not without it
            every = whole if whole is not None else _delaunay(image, where)
            seen_with = _seen_triangles(finite, image, viewpoint, every, edges=edges)
            seen = max(seen, float(np.unique(seen_with).size / len(finite)))
        finite, image = finite[rest], image[rest]
    else:
        every = whole if whole is not None else _delaunay(image, where)
        faces = _seen_triangles(finite, image, viewpoint, every, edges=edges)
        seen = float(np.unique(faces).size / len(finite))
    if seen < least_seen:
        raise PointCloudError(
            f"The file holds points but no triangles, and they are not one view from the "
            f"sensor at ({where}): {100 * (1 - seen):.0f}% of them hide behind others, as "
            f"a whole object's points do. {UPLOAD_A_VIEW}"
        )
    # Wound clockwise in the image (whose third axis points away from the sensor), a
    # triangle's normal faces the sensor.
    first, second, third = (image[faces[:, k]] for k in range(3))
    (ax, ay), (bx, by) = (second - first).T, (third - first).T
    turn = ax * by - ay * bx
    faces[turn > 0] = faces[turn > 0][:, ::-1]
    return finite, faces, Cloud(len(finite), support=support)


def _delaunay(image: np.ndarray, where: str) -> Delaunay:
    """Delaunay's triangulation of a view's ``image`` (n, 2), seen from ``where``."""
    from scipy.spatial import Delaunay, QhullError

    if len(image) < 3:
        raise PointCloudError(f"The file holds too few points to make a surface. {UPLOAD_A_VIEW}")
    try:
        return Delaunay(image)
    except QhullError as exc:
        raise PointCloudError(
            f"The file's points lie on one line as seen from ({where}): no surface joins "
            f"them. {UPLOAD_A_VIEW}"
        ) from exc


def _seen_triangles(
    points: np.ndarray,
    image: np.ndarray,
    viewpoint: np.ndarray,
    triangulation: Delaunay,
    hidden: np.ndarray | None = None,
    edges: np.ndarray | None = None,
) -> np.ndarray:
    """(m, 3) the triangles of :func:`viewed_surface`'s points (n, 3) seen from
    ``viewpoint``: the ``triangulation`` of their ``image`` (n, 2), but those with an edge
    across a gap (longer than ``GAP_SPACINGS`` times their corners' least median edge) or
    along a ray (:func:`unshadowed`). With the image of ``hidden`` points (k, 2) left out
    (a support's), the triangles are those of every point's triangulation that join none
    of them: a triangle of the rest's whose circle holds one of them is not (it bridges
    where they were), nor are its edges measured. ``edges`` (n,): the points' median edges
    in ``triangulation`` (:func:`median_edges`), when already measured."""
    faces = triangulation.simplices.astype(np.int64)
    if hidden is not None and len(hidden):
        centre, radius = _circumcircles(image[faces])
        nearest, _ = _tree(hidden).query(centre)
        faces = faces[~(np.asarray(nearest) < radius * (1.0 - 1e-9))]
        spacing = median_edges(image, _edge_neighbours(faces, len(image)))
    elif edges is not None:
        spacing = edges
    else:
        spacing = median_edges(image, triangulation.vertex_neighbor_vertices)
    corners = image[faces]
    sides = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)  # (m, 3)
    kept = sides.max(axis=1) <= GAP_SPACINGS * spacing[faces].min(axis=1)
    kept &= unshadowed(points, faces, viewpoint)
    seen: np.ndarray = faces[kept]
    return seen


def _circumcircles(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(m, 2) the centres and (m,) the radii of triangles' circumscribed circles, their
    ``corners`` (m, 3, 2) (a degenerate one's infinite)."""
    a = corners[:, 0]
    b, c = corners[:, 1] - a, corners[:, 2] - a
    det = 2.0 * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0])
    bb, cc = (b**2).sum(axis=1), (c**2).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = np.stack([c[:, 1] * bb - b[:, 1] * cc, b[:, 0] * cc - c[:, 0] * bb], axis=1)
        offset /= det[:, None]
    radius = np.linalg.norm(offset, axis=1)
    radius[~np.isfinite(radius)] = np.inf
    return np.nan_to_num(a + offset), radius


def _edge_neighbours(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The edges of ``faces`` (m, 3) as a CSR pair ``(indptr, indices)`` of each of ``n``
    points' neighbours (as :func:`median_edges` takes them)."""
    start, end = np.divmod(np.unique(edge_keys(faces, n).ravel()), n)
    owner, other = np.concatenate([start, end]), np.concatenate([end, start])
    order = np.argsort(owner, kind="stable")
    indptr = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=n))])
    return indptr, other[order]


#: :func:`viewed_surface`: a view of at most ``SPACING_EXACT`` points is triangulated
#: whole before its support is looked for (its spacing exact, and the triangulation kept
#: when it has none, so that a view without a floor is triangulated once: about 0.3 s at
#: that size); of a larger one, only the rest is. :func:`image_spacing` measures such a view in
#: ``SPACING_WINDOWS`` windows of ``SPACING_WINDOW`` points each, pooling the median
#: edges of each window's ``SPACING_INNER`` points nearest its centre (whose neighbours
#: the window holds).
SPACING_EXACT = 50_000
SPACING_WINDOWS = 32
SPACING_WINDOW = 200
SPACING_INNER = 50


def image_spacing(image: np.ndarray, edges: np.ndarray | None = None) -> float:
    """The median of a view's ``image`` points' (n, 2) median ``edges`` (n,) in their
    Delaunay triangulation (:func:`median_edges`); without them, in windows of the image
    evenly spread over its points (:data:`SPACING_WINDOWS`), each triangulated alone
    (0.95-1.0 of it on the partiality protocol's floor frames, as shot or voxel filtered;
    the distance to each point's third nearest is two thirds of it in a view voxel
    filtered coarsely, whose points lie in rows). ``nan`` when a window's points lie on
    one line."""
    from scipy.spatial import Delaunay, QhullError

    if edges is not None:
        return float(np.median(edges))
    centres = np.linspace(0, len(image) - 1, SPACING_WINDOWS).astype(np.int64)
    _, windows = _tree(image).query(image[centres], k=min(SPACING_WINDOW, len(image)))
    try:
        inner = [
            median_edges(image[window], Delaunay(image[window]).vertex_neighbor_vertices)
            for window in np.asarray(windows)
        ]
    except QhullError:
        return float("nan")
    return float(np.median(np.concatenate([e[:SPACING_INNER] for e in inner])))


#: :func:`_binned_support`: a view's image is binned in cells ``SUPPORT_CELL`` times its
#: points' median spacing (at one, the image of points moved half a pixel left 60% of its
#: border's cells empty, and a floor seemed not to run out of it), and must fill
#: ``SUPPORT_LEAST_CELLS`` of them to be searched for a support: coarser, a curved side
#: passes for a plane within the band of two cells (of 923 views of TOSCA's and SCAPE's
#: wholes alone, moved half a pixel or voxel filtered, three of 189, 265 and 483 cells
#: lost a sixth to a third of their points, none of the 859 of 500 cells or more:
#: docs/decisions.md; the bound is twice the largest that lost any).
SUPPORT_CELL = 1.25
SUPPORT_LEAST_CELLS = 1000


def _binned_support(
    points: np.ndarray, image: np.ndarray, spacing: float, viewpoint: np.ndarray
) -> np.ndarray | None:
    """(n,) bool: which of a view's ``points`` (n, 3), on no lattice, lie on a plane its
    object stands on or against: its ``image`` (n, 2) binned in cells
    :data:`SUPPORT_CELL` times its points' ``spacing`` apart,
    each cell holding the point nearest ``viewpoint`` (a z-buffer's), is the organized
    frame :func:`support_planes` searches; every point in a support's cell is its, and
    every point as near a plane taken as its cell's must be (as on a frame: the points
    a cell's nearest hides, beside an object's feet or behind its silhouette).
    None (not searched) when the cells would outnumber the points ``LATTICE_MAX_FILL``
    times, or the points fill fewer than :data:`SUPPORT_LEAST_CELLS`."""
    if not np.isfinite(spacing) or spacing <= 0.0:
        return None
    cells = np.floor((image - image.min(axis=0)) / (SUPPORT_CELL * spacing)).astype(np.int64)
    width, height = cells.max(axis=0) + 1
    if width * height > LATTICE_MAX_FILL * len(points):
        return None
    cell = cells[:, 1] * width + cells[:, 0]
    order = np.lexsort((np.linalg.norm(points - viewpoint, axis=1), cell))
    nearest = order[np.r_[True, cell[order][1:] != cell[order][:-1]]]
    if len(nearest) < SUPPORT_LEAST_CELLS:
        return None
    frame = np.full((height * width, 3), np.nan)
    frame[cell[nearest]] = points[nearest]
    support, planes = support_planes(frame.reshape(height, width, 3), viewpoint)
    in_support: np.ndarray = support.ravel()[cell]
    for normal, offset, within in planes:
        in_support |= np.abs(points @ normal - offset) < within.ravel()[cell]
    return in_support


def median_edges(image: np.ndarray, neighbours: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(n,) each point's median length in ``image`` (n, 2) of its edges to its
    ``neighbours`` (a CSR pair ``(indptr, indices)``: point ``i``'s are
    ``indices[indptr[i]:indptr[i + 1]]``), the lower of two middle ones; ``inf`` for a
    point with none. One sort of every edge's length offset by its point's number (below
    one), which orders each point's edges and keeps the points apart."""
    indptr, indices = neighbours
    count = np.diff(indptr)
    owner = np.repeat(np.arange(len(image)), count)
    length = np.linalg.norm(image[indices] - image[owner], axis=1)
    scale = 2.0 * float(length.max(initial=0.0)) or 1.0
    ordered = np.sort(owner + length / scale)
    median = np.full(len(image), np.inf)
    has = np.flatnonzero(count > 0)
    median[has] = (ordered[indptr[has] + (count[has] - 1) // 2] - has) * scale
    return median


def _found_lattice(
    points: np.ndarray,
    viewpoint: np.ndarray,
    trials: LatticeTrials,
    start: Callable[[], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, bool] | None:
    """:func:`sensor_grid`'s organized cloud of ``points`` (n, 3) in a frame found from them
    (:func:`sensor_axes`), that frame (3, 3) and whether it is an orthographic grid's; or
    None. A lattice the points lie on in any frame goes first; else one they lie near
    (:func:`snapped_steps`), tried in the last orthographic frame first (the most refined)
    and the pinhole camera's last: a far orthographic grid lies near a pinhole camera's
    lattice too, a little sheared, its squares' diagonals the other way. ``trials``: the
    points', tried in every frame; ``start``: as :func:`sensor_axes`'."""
    frames = []
    for frame, orthographic, steps in sensor_axes(points, viewpoint, start):
        lattice = sensor_grid(points, viewpoint, frame, along=(2,), trials=trials)
        if lattice is not None:
            return lattice, frame, orthographic
        frames.append((frame, orthographic, steps))
    for frame, orthographic, steps in sorted(frames[::-1], key=lambda tried: not tried[1]):
        lattice = sensor_grid(points, viewpoint, frame, along=(2,), steps=steps, trials=trials)
        if lattice is not None:
            return lattice, frame, orthographic
    return None


def _seen_along(points: np.ndarray, viewpoint: np.ndarray, sight: np.ndarray) -> bool:
    """Whether every ray from ``viewpoint`` (3,) to ``points`` (n, 3) runs within
    :data:`ORTHOGRAPHIC_DEGREES` of ``sight`` (3,), as a far orthographic camera's do."""
    rays = points - viewpoint
    along = np.abs(rays @ sight) / np.maximum(np.linalg.norm(rays, axis=1), np.finfo(float).tiny)
    return bool(along.min() >= np.cos(np.radians(ORTHOGRAPHIC_DEGREES)))


def sensor_side(vertices: np.ndarray, faces: np.ndarray, direction: np.ndarray) -> float:
    """1.0 when the sensor that saw the view ``vertices`` (n, 3), ``faces`` (m, 3) stands
    along ``direction`` (3,) from it, -1.0 when it stands the other way.

    At its silhouette a surface turns away from the sensor that sees it, so the view's
    boundary vertices lie farther from the sensor than their neighbours do (an occlusion
    gap's far side, flat, adds little either way): the sign of the summed heights along
    ``direction`` of each boundary vertex's neighbours over its own. The points alone
    cannot tell the two sides apart (a depth map is one seen from either), and a view
    read from the wrong one is described as its mirror image, its unseen side taken on
    the side it was seen from.
    """
    n = len(vertices)
    keys = edge_keys(faces, n).ravel()
    once = keys_seen_once(keys)
    boundary = np.unique(np.concatenate([once // n, once % n]))
    every = np.unique(keys)
    edges = np.stack([every // n, every % n], axis=1)
    height = vertices @ direction
    both = np.concatenate([edges, edges[:, ::-1]])
    around = np.bincount(both[:, 0], weights=height[both[:, 1]], minlength=len(vertices))
    count = np.bincount(both[:, 0], minlength=len(vertices))
    rise = around[boundary] / np.maximum(count[boundary], 1) - height[boundary]
    return 1.0 if rise.sum() >= 0.0 else -1.0


#: :func:`guessed_viewpoint`: how far from the points, in their extents, a guessed
#: sensor stands (its rays all but parallel, an orthographic scanner's).
GUESSED_SENSOR_EXTENTS = 1e3


def one_view(
    points: np.ndarray, viewpoint: np.ndarray, axes: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, Cloud]:
    """:func:`viewed_surface` from ``viewpoint``; points that are not one view from there
    (one view written in another frame than its sensor's, the sensor elsewhere) are tried
    once more from afar along the direction they overlap themselves least in
    (:func:`unfolded_sight`, :func:`guessed_viewpoint`), where a scanner that saw them
    all would stand, and when the triangles so made are an orthographic grid's, once more
    along its own line of sight (:func:`grid_sight`: exact, where the unfolded sight can
    be degrees off), on the side the view's silhouette says its sensor stood
    (:func:`sensor_side`). Points that are not one view from there either (a whole object's,
    several views merged) are read as the view that sees most of them (:func:`whole_view`);
    those plainly none from afar (:func:`plainly_whole`, on their thinned cloud) without
    that try on all of them. When that fails too, the first refusal stands: it names the
    sensor the file gave. Points on one line (:func:`on_a_line`, rounded off it) are refused
    first: from afar they would pass for a view of slivers. A point written more than once
    (frames merged, an export's repeats) is read once: its copies would hide behind one
    another, and share a pixel; one written at the sensor itself is a pixel that saw nothing
    (:func:`at_the_sensor`)."""
    seen = np.isfinite(points).all(axis=1) & ~at_the_sensor(points, viewpoint)
    finite = written_once(points[seen])
    if len(finite) >= 3 and on_a_line(finite):
        raise PointCloudError(
            f"The file's points lie on one line: no surface joins them. {UPLOAD_A_VIEW}"
        )
    # Computed once, when the frame search's rounds or the second try first need it.
    start = cache(lambda: unfolded_sight(finite))
    try:
        return viewed_surface(finite, viewpoint, axes, start=start)
    except PointCloudError as refusal:
        if len(finite) < 3:
            raise  # too few points from anywhere
        guess = guessed_viewpoint(finite, start())
        thinning = thinned(finite, WHOLE_POINTS)
        if plainly_whole(thinning, guess):
            try:
                return whole_view(finite, thinning)
            except PointCloudError:
                raise refusal from None
        try:
            # The first try searched the points' frames already (sensor_axes: where no
            # lattice was found from there, none is from afar).
            vertices, faces, cloud = viewed_surface(
                finite, guess, find_frame=False, sensor_known=False
            )
            sight = grid_sight(vertices, faces)
            if sight is not None:
                guess = guessed_viewpoint(finite, sight)
                vertices, faces, cloud = viewed_surface(
                    finite, guess, find_frame=False, sensor_known=False
                )
        except PointCloudError:
            try:
                return whole_view(finite, thinning)
            except PointCloudError:
                raise refusal from None
        direction = guess - vertices.mean(axis=0)
        if sensor_side(vertices, faces, direction) < 0.0:
            faces = faces[:, ::-1]  # its sensor stands the other way: each triangle faces it
        return vertices, faces, cloud


#: :func:`whole_view`: the directions a cloud is looked at along (a Fibonacci lattice over
#: the sphere), each on a seeded sample of this many of its points; how far the camera
#: stands from their centroid, in their extents; and the radius points are flipped about
#: (:func:`visible_points`), the farthest one's distance times ten to this power (Katz, Tal
#: and Basri 2007's gamma).
WHOLE_DIRECTIONS = 32
WHOLE_SAMPLE = 2000
WHOLE_DISTANCE = 3.0
FLIP_POWER = 2.0
#: :func:`whole_view`: the share of the points seen that must lie on the view's surface.
#: Lower than one view's ``VIEW_SHARE``: the view of a whole object's points loses its
#: rim, seen at a grazing angle (the shadow rule's), which a camera there would have seen
#: as few pixels (a sphere's: the 21% of the points seen whose normals lie 68-82 degrees
#: off the camera).
WHOLE_SEEN = 0.5
#: :func:`whole_view`: a cloud of more points is first thinned to about this many
#: (:func:`thinned`). The view keeps some 40% of them, and the describe resamples a view
#: to 1,250 vertices (half the preset's ``n_vertices``); hidden point removal on a dense
#: cloud sees less of it than on a sparse one (one of TOSCA's 52,565 vertices: 14%).
WHOLE_POINTS = 4000
#: :func:`whole_view`: the points whose plane (:func:`plane_projected`) each is seen on:
#: noise of 0.5% of an object's diagonal hides half of what a camera sees from the
#: method, which takes a noisy front for a rough hull; seen on the plane of its nearest,
#: a point is hidden as its surface would be.
WHOLE_NEIGHBOURS = 16


#: :func:`plainly_whole`: the share of a thinned cloud's points on the surface seen from
#: afar under which it is plainly no view. Thinned to ``WHOLE_POINTS``, TOSCA's 83 wholes
#: as their vertices show at most 53% of them from their sensor or from afar, with noise
#: of 0.5% of their diagonal too; their views and floor frames, written in their sensor's
#: frame or in another, 73% or more, but one floor frame read as a whole's anyway
#: (docs/decisions.md, "A whole's points plainly no view skip the try from afar").
WHOLE_TEST_SHARE = 0.65


def plainly_whole(thinning: tuple[np.ndarray, np.ndarray], viewpoint: np.ndarray) -> bool:
    """Whether a cloud, as :func:`thinned` thins it (``thinning``: k means and each of its
    n points' cell), is plainly no view from ``viewpoint`` (3,): fewer than
    ``WHOLE_TEST_SHARE`` of the thinned points lie on the surface seen from there
    (:func:`viewed_surface`). So :func:`one_view` reads a whole object's points
    (:func:`whole_view`) without triangulating every one of them from afar first (the
    thinned points' triangulation takes a fraction of that time); never when none were
    thinned away (k is n: that try is the full one)."""
    thin, cell = thinning
    if len(thin) == len(cell):
        return False
    try:
        viewed_surface(
            thin, viewpoint, find_frame=False, sensor_known=False, least_seen=WHOLE_TEST_SHARE
        )
    except PointCloudError:
        return True
    return False


def whole_view(
    points: np.ndarray, thinning: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, Cloud]:
    """Points (n, 3) that are not one view from anywhere (a whole object's, several views
    merged) read as the view that sees most of them: thinned to about ``WHOLE_POINTS``
    (:func:`thinned`; ``thinning``, its result when already made), seen from
    :func:`whole_camera` (the largest silhouette), the points it sees
    (:func:`visible_points`, each on the plane of its ``WHOLE_NEIGHBOURS`` nearest,
    :func:`plane_projected`) are read as its view (:func:`viewed_surface`) and
    the rest, hidden behind them, left out: the cloud's ``points`` and ``hidden`` count
    the file's points in each (those in a cell of :func:`thinned` go with its mean). A
    cloud of a whole object has no triangles to tell its touching sheets apart
    (docs/decisions.md, "Point clouds stay refused"); one side of it, seen, does: a view's
    surface is its image's (docs/decisions.md, "A whole object's points read as the view
    that sees most of them", "A whole's points thinned and seen on their planes").

    Raises
    ------
    PointCloudError
        The view so seen is not one (:func:`viewed_surface`) or has no triangle, or the
        points lie in a plane.
    """
    from scipy.spatial import QhullError

    thin, cell = thinned(points, WHOLE_POINTS) if thinning is None else thinning
    camera = whole_camera(thin)
    try:
        visible = visible_points(plane_projected(thin, WHOLE_NEIGHBOURS), camera)
    except QhullError as exc:
        raise PointCloudError(
            f"The file's points lie in a plane: no surface joins them. {UPLOAD_A_VIEW}"
        ) from exc
    vertices, faces, _ = viewed_surface(
        thin[visible], camera, find_frame=False, sensor_known=False, least_seen=WHOLE_SEEN
    )
    if not len(faces):  # a few points seen past a far outlier may lie on a lattice of none
        raise PointCloudError(
            f"The file's points make no surface as seen from where most of them show. "
            f"{UPLOAD_A_VIEW}"
        )
    seen = int(np.count_nonzero(np.isin(cell, visible)))
    return vertices, faces, Cloud(seen, hidden=len(points) - seen)


def whole_camera(points: np.ndarray) -> np.ndarray:
    """(3,) where :func:`whole_view` looks at ``points`` (n, 3) from: of
    ``WHOLE_DIRECTIONS`` directions, the one along which a sample of them covers the most
    cells of their spacing across it (the largest silhouette), ``WHOLE_DISTANCE`` extents
    from their centroid. On TOSCA's wholes as points it finds the own class more often
    than the most points seen or a random direction (docs/decisions.md, "A whole object's
    points read as the view that sees most of them")."""
    from .holes import fibonacci_directions  # holes reads meshes through this module

    directions = fibonacci_directions(WHOLE_DIRECTIONS)
    extent = float(np.ptp(points, axis=0).max())
    sample, spacing = _spaced_sample(points, WHOLE_SAMPLE)
    # Points written twice (whole_view is also called without written_once) space none.
    spacing = spacing or extent / len(sample)
    covered = [
        len(np.unique(np.floor(sample @ frame[:2].T / spacing), axis=0))
        for frame in view_frame(directions)
    ]
    camera: np.ndarray = (
        points.mean(axis=0) + WHOLE_DISTANCE * extent * directions[int(np.argmax(covered))]
    )
    return camera


#: :func:`thinned`: how many times the cell is resized towards the number asked for.
THINNING_ROUNDS = 4


def thinned(points: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``points`` (n, 3) thinned by a voxel filter to about ``count``: the mean of those
    in each cube of a grid that holds any, and (n,) each point's cube; as they are (each
    its own) when no more than ``count``. The cube's side starts where a seeded sample's
    spacing says ``count`` points would lie apart, and is resized ``THINNING_ROUNDS``
    times by the root of how many cubes it made over ``count`` (a surface's cubes grow as
    the square of their side's inverse)."""
    from .mesh_io import cell_means  # mesh_io reads clouds through this module

    if len(points) <= count:
        return points, np.arange(len(points))
    sample, spacing = _spaced_sample(points, WHOLE_SAMPLE)
    side = (spacing or float(np.ptp(points, axis=0).max()) / count) * np.sqrt(len(sample) / count)
    for _ in range(THINNING_ROUNDS):
        means, cube = cell_means(points, side)
        side *= np.sqrt(len(means) / count)
    return means, cube


def plane_projected(points: np.ndarray, neighbours: int) -> np.ndarray:
    """(n, 3) each of ``points`` (n, 3) moved onto the plane fitted (least squares)
    through its ``neighbours`` nearest points, itself among them: the first step of a
    moving least squares projection (Alexa et al., "Computing and rendering point set
    surfaces", IEEE TVCG 2003), which takes noise off a surface's points across it and
    leaves them where they lie along it."""
    k = min(neighbours, len(points))
    _, near = _tree(points).query(points, k=k)
    around = points[np.asarray(near).reshape(len(points), k)]
    centre = around.mean(axis=1)
    offsets = around - centre[:, None]
    normal = np.linalg.eigh(np.einsum("nki,nkj->nij", offsets, offsets))[1][:, :, 0]
    height = np.einsum("ni,ni->n", points - centre, normal)
    projected: np.ndarray = points - height[:, None] * normal
    return projected


def visible_points(points: np.ndarray, viewpoint: np.ndarray) -> np.ndarray:
    """The indices, in order, of ``points`` (n, 3) seen from ``viewpoint`` (3,), none at
    it: Katz, Tal and Basri's hidden point removal ("Direct visibility of point sets",
    SIGGRAPH 2007). About the viewpoint each point is flipped across the sphere of radius
    R (``FLIP_POWER``), p + 2 (R - |p|) p / |p|; a point is seen when its flip is a vertex
    of the convex hull of the flips and the viewpoint."""
    from scipy.spatial import ConvexHull

    rays = points - viewpoint
    length = np.linalg.norm(rays, axis=1)
    radius = float(length.max()) * 10.0**FLIP_POWER
    flipped = rays * ((2.0 * radius - length) / length)[:, None]
    corners = ConvexHull(np.vstack([flipped, np.zeros((1, 3))])).vertices
    seen: np.ndarray = np.sort(corners[corners < len(points)])
    return seen


#: :func:`on_a_line`: points whose spread across their line is under this share of their
#: spread along it (float32's rounding moves a line's points some 1e-7 of it off it).
LINE_SPREAD = 1e-4


def on_a_line(points: np.ndarray) -> bool:
    """Whether ``points`` (n, 3) lie on one line: their second principal spread (the root
    of their covariance's second eigenvalue) under ``LINE_SPREAD`` times their first."""
    variances = np.linalg.eigvalsh(np.cov(points.T))  # ascending
    return bool(variances[1] <= LINE_SPREAD**2 * variances[2])


def written_once(points: np.ndarray) -> np.ndarray:
    """``points`` (n, 3), each written more than once kept once, in the order written.
    One sort of a number made of each point's coordinates first tells whether any is
    (equal points make equal numbers), in a fraction of the time the rows' own sort
    (:func:`~.topology.unique_rows`) takes."""
    key = points @ np.array([1.0, np.pi, np.e])
    if np.unique(key).size == len(key):
        return points
    once: np.ndarray = points[np.sort(unique_rows(points)[0])]
    return once


def guessed_viewpoint(points: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(3,) a point ``GUESSED_SENSOR_EXTENTS`` extents away from ``points`` (n, 3)'s
    centroid along ``direction`` (3,)."""
    finite = points[np.isfinite(points).all(axis=1)]
    if len(finite) < 3:
        return np.zeros(3)
    centre = finite.mean(axis=0)
    extent = float(np.ptp(finite, axis=0).max())
    viewpoint: np.ndarray = centre + GUESSED_SENSOR_EXTENTS * extent * direction
    return viewpoint


#: :func:`unfolded_sight`: how many of the points (a seeded sample) are looked at, how
#: many directions over the half sphere are tried first, and the rings of directions tried
#: around the best so far (radians off it; eight on each ring, and eight at half of it).
SIGHT_SAMPLE = 500
SIGHT_DIRECTIONS = 32
SIGHT_RINGS = (0.25, 0.08, 0.025)


def unfolded_sight(points: np.ndarray) -> np.ndarray:
    """(3,) the unit direction along which ``points`` (n, 3), one view written in any
    frame, overlap themselves least (:func:`overlapped_share`): one view is a height field
    along its sensor's line of sight, its points never above one another, and seen along
    another direction its sheets fold over each other. Directions spread over the half
    sphere (a Fibonacci lattice), the points' least principal axis among them
    (:func:`least_spread`: a view is thin along its line of sight, unless it is long and
    narrow); then rings of them around the best, each nearer, the middle of those least
    overlapped taken. On TOSCA's 83 range scans (SHREC'17's orbiting camera) it lies a
    median 5.6 degrees off the scanner's line of sight (90% within 16.4, the farthest
    45.7), the least principal axis a median 38.5 (87.6); :func:`sensor_axes`' rounds
    then find the exact line."""
    sample, spacing = _spaced_sample(points, SIGHT_SAMPLE)
    turn = np.pi * (1.0 + np.sqrt(5.0)) * (np.arange(SIGHT_DIRECTIONS) + 0.5)
    height = (np.arange(SIGHT_DIRECTIONS) + 0.5) / SIGHT_DIRECTIONS
    radius = np.sqrt(1.0 - height**2)
    lattice = np.stack([radius * np.cos(turn), radius * np.sin(turn), height], axis=1)
    tried = np.vstack([least_spread(sample), lattice])
    angles = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # across the best, unit
    best: np.ndarray = tried[0]
    for off in (None, *SIGHT_RINGS):
        if off is not None:
            across = view_frame(best)[:2]
            tried = np.concatenate([ring * off, ring[:, ::-1] * 0.5 * off]) @ across + best
            tried = np.vstack([best, tried / np.linalg.norm(tried, axis=1, keepdims=True)])
        shares = np.array([overlapped_share(sample, f, spacing) for f in view_frame(tried)])
        if off is None:
            best = tried[int(np.argmin(shares))]
        else:  # the middle of the least overlapped directions around it
            best = tried[shares == shares.min()].mean(axis=0)
            best = best / np.linalg.norm(best)
    return best


def _spaced_sample(points: np.ndarray, size: int) -> tuple[np.ndarray, float]:
    """A seeded sample of ``size`` of ``points`` (n, 3) (all of them when fewer) and the
    median distance from each of its points to the nearest other."""
    sample = points[np.random.default_rng(0).permutation(len(points))[:size]]
    nearest = np.asarray(_tree(sample).query(sample, k=2)[0])[:, 1]
    return sample, float(np.median(nearest))


def least_spread(points: np.ndarray) -> np.ndarray:
    """(3,) the unit direction ``points`` (n, 3) spread least along (their least
    principal axis)."""
    least: np.ndarray = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)[2][-1]
    return least


def overlapped_share(points: np.ndarray, frame: np.ndarray, spacing: float) -> float:
    """The share of ``points`` (n, 3) that lie over or under another of them seen along
    the third row of ``frame`` (3, 3, :func:`view_frame`): within ``spacing`` of it across
    that direction, more than twice that apart along it."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(points @ frame[:2].T).query_pairs(spacing, output_type="ndarray")
    apart = np.abs((points[pairs[:, 0]] - points[pairs[:, 1]]) @ frame[2]) > 2.0 * spacing
    return np.unique(pairs[apart]).size / len(points)


#: :func:`lattice_steps`: values closer than this share of their span are one row or
#: column of pixels (float32's rounding is 1e-7 of a coordinate, six digits of text
#: 1e-6), and their rows must stand ``LATTICE_MIN_PITCH`` times that far apart and within
#: ``LATTICE_RESIDUAL`` of a pitch of the lattice.
LATTICE_TOLERANCE = 1e-5
LATTICE_MIN_PITCH = 10.0
LATTICE_RESIDUAL = 0.1
#: How far float32's rounding can spread one pixel's values along a unit direction, per
#: unit of the points' distance from their frame's origin (half a float32 ulp, 6e-8 of a
#: coordinate, in each of three coordinates, either way): a view written far from its
#: frame's origin keeps its pixels that much apart however small its span.
FLOAT32_SPREAD = 2.1e-7
#: :func:`sensor_grid`: a lattice of more pixels than this many times the points is not
#: a sensor's image of them (nor worth its memory: a view fills a good share of its
#: bounding box); how many of the points (a seeded sample) are tried first (a sample of
#: a lattice is one, a few columns missing: it refuses most frames in a fraction of the
#: time all the points take).
LATTICE_MAX_FILL = 16
LATTICE_TRIAL = 1024
#: :func:`snapped_steps`: each value within ``SNAP_RESIDUAL`` of a pitch of its lattice
#: node, so two neighbouring columns' values at least ``SNAP_GAP`` of a pitch apart
#: (1 - 2 x 0.35, less a little); a cloud on no lattice has values half a pitch off.
SNAP_RESIDUAL = 0.35
SNAP_GAP = 0.25


def lattice_steps(values: np.ndarray, rounding: float = 0.0) -> np.ndarray | None:
    """(n,) int, each of ``values`` (n,) as a step of a regular lattice (0 at the least):
    the columns of a sensor's pixels, equally spaced, each holding any number of the
    values (a pixel's rounding apart: ``LATTICE_TOLERANCE`` of their span, or
    ``rounding`` where that is more), and columns missing between them; None when the
    values are no such lattice."""
    order = np.argsort(values, kind="stable")
    ordered = values[order]
    span = float(ordered[-1] - ordered[0])
    if not span > 0.0:
        return None
    tolerance = max(LATTICE_TOLERANCE * span, rounding)
    starts = np.flatnonzero(np.diff(ordered) > tolerance) + 1
    bounds = np.concatenate([[0], starts, [len(ordered)]])
    low, high = ordered[bounds[:-1]], ordered[bounds[1:] - 1]
    centres = 0.5 * (low + high)
    if len(centres) < 2:
        return None
    # The pitch: the median gap between neighbouring columns (shorter than 1.5 of the
    # least: none missing between them), then the least-squares line through each
    # column's step and centre, so that the pixels' rounding does not add up across
    # hundreds of columns.
    gaps = np.diff(centres)
    pitch = float(np.median(gaps[gaps < 1.5 * gaps.min()]))
    if pitch < LATTICE_MIN_PITCH * tolerance:
        return None
    step = np.round((centres - centres[0]) / pitch)
    pitch, start = (float(c) for c in np.polyfit(step, centres, 1))
    position = (centres - start) / pitch
    if np.abs(position - step).max() > LATTICE_RESIDUAL or (high - low).max() > (
        LATTICE_RESIDUAL * pitch
    ):
        return None
    steps = np.empty(len(values), dtype=np.int64)
    steps[order] = np.repeat(step.astype(np.int64), np.diff(bounds))
    return steps


def snapped_steps(values: np.ndarray, pitch: float) -> np.ndarray | None:
    """(n,) int, each of ``values`` (n,) as the step of its nearest node on a regular
    lattice (0 at the least) whose pitch is ``pitch`` to within a few percent, or None
    when a value lies farther than :data:`SNAP_RESIDUAL` of a pitch from every node.

    The values of one column of pixels, moved off their node (a view's points smoothed
    or resampled after the scan, or written with few decimals), are one run of the
    ordered values, apart from the next column's by more than :data:`SNAP_GAP` of a
    pitch; each run's mean is its column's node, and the columns' steps the whole
    pitches between neighbouring runs (a missing column two). The lattice's pitch and
    origin are then the least-squares line through the runs' steps and means, and each
    value's step its nearest node on it (:func:`lattice_steps` reads a lattice its
    values lie on exactly).
    """
    ordered = np.sort(values)
    starts = np.flatnonzero(np.diff(ordered) > SNAP_GAP * pitch) + 1
    bounds = np.concatenate([[0], starts, [len(ordered)]])
    centres = np.add.reduceat(ordered, bounds[:-1]) / np.diff(bounds)
    step = np.concatenate([[0.0], np.cumsum(np.round(np.diff(centres) / pitch))])
    if step[-1] < 1.0:
        return None
    fitted, start = (float(c) for c in np.polyfit(step, centres, 1))
    position = (values - start) / fitted
    nearest = np.round(position)
    if np.abs(position - nearest).max() > SNAP_RESIDUAL:
        return None
    if not np.ptp(nearest) <= LATTICE_MAX_FILL * len(values):  # a stray point far off
        return None
    steps: np.ndarray = (nearest - nearest.min()).astype(np.int64)
    return steps


def sensor_grid(
    points: np.ndarray,
    viewpoint: np.ndarray,
    axes: np.ndarray | None = None,
    along: tuple[int, ...] = (2, 0, 1),
    steps: Pairs | None = None,
    trials: LatticeTrials | None = None,
) -> np.ndarray | None:
    """The organized cloud (h, w, 3) (``nan`` where no point is) of ``points`` (n, 3) that
    lie on a camera's pixel lattice, or None.

    A camera at ``viewpoint`` looking along one of its ``axes`` (3, 3), the sensor's frame
    as columns in the points' (by default the points' own: a depth camera writes its
    points in its frame, looking along z) sees them on its image's lattice: a pinhole camera's
    ``(x / z, y / z)`` are equally spaced in each coordinate, an orthographic grid's
    ``(x, y)`` (:func:`lattice_steps`, allowing for float32's rounding of the points as
    written, :data:`FLOAT32_SPREAD`; ``axes``' columns are unit vectors). Tried looking
    along each axis in turn (those numbered in ``along``), as a pinhole camera when every
    point lies on one side of the viewpoint along it, then as an orthographic one (each
    tried on ``trials``' sample of the points first: every point's image is made only
    when the sample's lies on a lattice); the first lattice on which every point has its
    own pixel is the grid (its empty rows and columns closed up, :func:`closed_up`), and
    triangulating it needs no Delaunay triangulation. Given
    ``steps`` between neighbouring pixels (the (first, second) indices of pairs of the
    points, :func:`sensor_axes`'), whose median lengths along the image's two axes are
    its pitches, the lattice sought is instead one the points lie near, each within
    :data:`SNAP_RESIDUAL` of a pitch of its node (:func:`snapped_steps`; points on a
    lattice lie near it too; tried first on ``trials``' patch of the points nearest their
    middle). ``trials``: the points' :class:`LatticeTrials` from ``viewpoint``, made once
    for a search that tries many frames.
    """
    trials = LatticeTrials(points, viewpoint) if trials is None else trials
    rays = trials.rays
    for axis in along:
        across = [k for k in (0, 1, 2) if k != axis]
        depth = rays[:, axis] if axes is None else rays @ axes[:, axis]
        # A pinhole camera's image divides by the depth; an orthographic grid's allows for
        # the points' rounding.
        images: list[tuple[np.ndarray | None, float]] = [(None, trials.rounding)]
        if (depth > 0.0).all() or (depth < 0.0).all():
            images.insert(0, (depth, 0.0))
        for divisor, spread in images:
            image = _Image(rays, axes, across, divisor)
            if steps is None:
                pixels = _pixels(image, trials.sample, spread)
            else:
                pitches = _pitches(image, steps)
                pixels = None if pitches is None else _pixels(image, trials.middle, 0.0, pitches)
            if pixels is None:
                continue
            rows, columns = (closed_up(steps) for steps in pixels)
            if rows is None or columns is None:
                continue
            height, width = int(rows.max()) + 1, int(columns.max()) + 1
            if height * width > LATTICE_MAX_FILL * len(points):
                continue
            pixel = rows * width + columns
            if np.unique(pixel).size < len(points):
                continue
            grid = np.full((height * width, 3), np.nan)
            grid[pixel] = points
            return grid.reshape(height, width, 3)
    return None


class LatticeTrials:
    """What :func:`sensor_grid` measures of ``points`` (n, 3) seen from ``viewpoint``
    (3,) whatever the frame, each when first needed: a search for their lattice tries
    many frames."""

    def __init__(self, points: np.ndarray, viewpoint: np.ndarray) -> None:
        self.points, self.viewpoint = points, viewpoint

    @cached_property
    def rays(self) -> np.ndarray:
        """(n, 3) the points less the viewpoint."""
        rays: np.ndarray = self.points - self.viewpoint
        return rays

    @cached_property
    def rounding(self) -> float:
        """How far float32's rounding can spread one pixel's values along a unit
        direction (:data:`FLOAT32_SPREAD` at the points' farthest from the origin)."""
        return FLOAT32_SPREAD * float(np.linalg.norm(self.points, axis=1).max())

    @cached_property
    def sample(self) -> np.ndarray:
        """(:data:`LATTICE_TRIAL`,) a seeded sample of the points (indices): a sample of
        a lattice is one, a few columns missing."""
        trial: np.ndarray = np.random.default_rng(0).permutation(len(self.points))
        return trial[:LATTICE_TRIAL]

    @cached_property
    def middle(self) -> np.ndarray:
        """(:data:`LATTICE_TRIAL`,) the points (indices) nearest the one nearest their
        median: a patch of the view, every point of it, as dense in any frame's image (a
        sample's few values in each column, moved off their lattice, could lie farther
        apart than two columns)."""
        points = self.points
        median = np.median(points, axis=0)
        centre = points[np.argmin(((points - median) ** 2).sum(axis=1))]
        distance = ((points - centre) ** 2).sum(axis=1)
        size = min(LATTICE_TRIAL, len(points))
        patch: np.ndarray = np.argpartition(distance, size - 1)[:size]
        return patch


class _Image:
    """A frame's image of a view's points: their ``rays`` (n, 3) turned into the frame
    ``axes`` (3, 3) (columns; the points' own frame when None), the two coordinates
    ``across`` its line of sight, each row over its ``divisor`` (n,) (a pinhole camera's
    depth) when given; made for the rows asked only, so that a frame refused by a trial
    turns none of the other points."""

    def __init__(
        self,
        rays: np.ndarray,
        axes: np.ndarray | None,
        across: list[int],
        divisor: np.ndarray | None,
    ) -> None:
        self.rays, self.axes, self.across, self.divisor = rays, axes, across, divisor

    def __call__(self, rows: np.ndarray | None = None) -> np.ndarray:
        """(k, 2) the image of the points ``rows`` (indices), of every point by default."""
        rays = self.rays if rows is None else self.rays[rows]
        flat = rays[:, self.across] if self.axes is None else rays @ self.axes[:, self.across]
        if self.divisor is None:
            return flat
        divisor = self.divisor if rows is None else self.divisor[rows]
        image: np.ndarray = flat / divisor[:, None]
        return image


#: :func:`closed_up`: how far (in columns) the columns that hold values may lie from the
#: wider lattice they are rounded from (half a column, and a little for the fit).
CLOSED_RESIDUAL = 0.6


def closed_up(steps: np.ndarray) -> np.ndarray | None:
    """(n,) int, ``steps`` (n,) of a lattice's columns (:func:`lattice_steps`) with the
    empty columns between them closed up, or None.

    Every column of a sensor's grid between the first and the last holds a point (a
    view's silhouette is one piece across them). Points written with coordinates rounded
    finer than their pixels (whole millimetres from a camera whose pixels lie 1.4 mm
    apart) lie on the rounding's lattice instead, each on its own node but with columns
    left empty between them (0, 1, 3, 4, 6, ...: the sensor's column ``k`` at
    ``round(1.4 k)``), and no triangle of that lattice's grid would join them. When at
    least two columns are empty and those holding values lie within
    :data:`CLOSED_RESIDUAL` of a column of a regular lattice of wider pitch, the values
    are the sensor's columns in turn; with none empty, ``steps`` themselves; otherwise
    (a gap of its own, values on no such lattice) None."""
    held, rank = np.unique(steps, return_inverse=True)
    empty = int(held[-1]) + 1 - len(held)
    if empty == 0:
        return steps
    if empty < 2 or len(held) < 3:
        return None
    order = np.arange(len(held))
    pitch, start = np.polyfit(order, held, 1)
    if np.abs(held - (start + pitch * order)).max() > CLOSED_RESIDUAL:
        return None
    closed: np.ndarray = rank.ravel()
    return closed


#: :func:`sensor_axes`: the points whose neighbours in a rough image of the view are
#: looked at (a seeded sample: a frame is a few numbers, which a sample's steps fix to
#: float64's precision), how many neighbours each, and how near a row's or a column's
#: direction a step must run in that image to be read as one.
AXES_SAMPLE = 2000
AXES_NEIGHBOURS = 4
AXES_STEP_DEGREES = 15.0
#: How many times the orthographic frame is fitted, its steps read across the line of
#: sight the last fit found (the points' :func:`unfolded_sight` at first, which can be
#: degrees off: each round comes nearer; of TOSCA's 83 range scans in their mesh's frame,
#: 23 are found in the first round, one in the fourth, 59 in the frames from the origin).
AXES_ROUNDS = 12
#: A round that turns the line of sight less than this, and not half as far as the round
#: before, stops them: points off any lattice (moved by noise, or a pinhole camera's seen
#: as an orthographic grid's) keep turning it by a fraction of a degree, round after round.
AXES_STALL_DEGREES = 1.0
#: An orthographic grid is seen from the sensor a file gives when every ray from it runs
#: within this many degrees of the grid's line of sight (a far camera's), and from afar
#: along that line otherwise (:func:`viewed_surface`).
ORTHOGRAPHIC_DEGREES = 1.0


#: A sensor's steps: the (first, second) indices of pairs of its points.
Pairs = tuple[np.ndarray, np.ndarray]


def sensor_axes(
    points: np.ndarray, viewpoint: np.ndarray, start: Callable[[], np.ndarray] | None = None
) -> Iterator[tuple[np.ndarray, bool, Pairs]]:
    """Frames (3, 3) (unit columns: across the sensor's rows, across its columns, its line
    of sight) in which ``points`` (n, 3), one view written in any frame, may lie on their
    sensor's pixel lattice (:func:`sensor_grid`), each with whether it is an orthographic
    sensor's and the steps it was fitted to (the (first, second) indices of neighbouring
    pixels, for the lattice's pitch), made as they are tried: when every point lies in front
    of ``viewpoint``, a pinhole camera's there and an orthographic grid's from the same
    steps; then an orthographic grid's from steps read afresh (the points' image from
    ``viewpoint`` may be none of theirs: a view written in its mesh's frame).

    A pixel's neighbours along its row and its column are the sensor's steps. Two
    points of one row of a pinhole camera span, with the camera, a plane through the
    row's direction ``a``: the cross product of their rays is square to ``a``, which is
    so the direction most nearly square to every row step's cross product (the least
    singular vector), and the columns' ``b`` likewise; the camera looks along
    ``n = a x b`` and its image coordinates are ``(ray . (b x n), ray . (a x n)) /
    (ray . n)``. Two points of one row of an orthographic grid differ by ``i a + z d``
    (``d`` its line of sight): the rows' steps all lie in the plane of ``a`` and ``d``,
    the columns' in that of ``b`` and ``d``, so the two planes' normals are the
    image's coordinates and ``d`` their cross product. Steps are read in a rough image
    (the points' central projection from ``viewpoint``, among their nearest neighbours
    there; then their projection across the direction they overlap themselves least in
    (:func:`unfolded_sight`), among their nearest neighbours in space, and again across
    each line of sight so found, :data:`AXES_ROUNDS`), for a sample of points, as a
    row's or a column's by their direction about the image's dominant one (four-fold,
    rows and columns square), each fit refitted twice without the steps that stray from
    it (a step across a gap that joined two rows). A frame is only a guess:
    :func:`sensor_grid` keeps it when every point has its own pixel. ``start`` gives the
    direction the rounds start from (:func:`unfolded_sight` of the points by default),
    called when they first need it.
    """
    if len(points) <= AXES_NEIGHBOURS:
        return
    rays = points - viewpoint
    mean_ray = rays.mean(axis=0)
    view = view_frame(mean_ray) if np.linalg.norm(mean_ray) > 0.0 else np.zeros((3, 3))
    depth = rays @ view[2]
    if (depth > 0.0).all():
        rows, columns = _steps(rays @ view[:2].T / depth[:, None])
        a = _least_direction(np.cross(rays[rows[0]], rays[rows[1]]))
        b = _least_direction(np.cross(rays[columns[0]], rays[columns[1]]))
        if a is not None and b is not None:
            sight = np.cross(a, b)
            frame = _unit_columns(np.cross(b, sight), np.cross(a, sight), sight)
            if frame is not None:
                yield frame, False, _joined(rows, columns)
        frame = _orthographic_frame(points, rows, columns)
        if frame is not None:
            yield frame, True, _joined(rows, columns)
    centred = points - points.mean(axis=0)
    pairs = _neighbours(centred)
    sight = unfolded_sight(points) if start is None else start()
    moved = np.inf
    for _ in range(AXES_ROUNDS):
        rows, columns = _steps(centred @ view_frame(sight)[:2].T, pairs)
        frame = _orthographic_frame(points, rows, columns)
        if frame is None:
            return
        yield frame, True, _joined(rows, columns)
        along = abs(float(frame[:, 2] @ sight))
        if along > 1.0 - 1e-12:
            return  # settled: another round reads the same steps
        turn = float(np.degrees(np.arccos(along)))
        if turn < AXES_STALL_DEGREES and turn > 0.5 * moved:
            return  # stalled: the steps' noise moves it, no lattice draws it nearer
        sight, moved = frame[:, 2], turn


def _orthographic_frame(points: np.ndarray, rows: Pairs, columns: Pairs) -> np.ndarray | None:
    """:func:`sensor_axes`' orthographic frame of ``points`` (n, 3) from their steps along
    ``rows`` and ``columns``, or None."""
    across_rows = _least_direction(points[rows[1]] - points[rows[0]])
    across_columns = _least_direction(points[columns[1]] - points[columns[0]])
    if across_rows is None or across_columns is None:
        return None
    return _unit_columns(across_columns, across_rows, np.cross(across_rows, across_columns))


def _neighbours(points: np.ndarray) -> Pairs:
    """The (first, second) indices of each of a seeded sample of ``points`` (n, d) and its
    nearest ``AXES_NEIGHBOURS``."""
    sample = np.random.default_rng(0).permutation(len(points))[:AXES_SAMPLE]
    near = np.asarray(_tree(points).query(points[sample], k=AXES_NEIGHBOURS + 1)[1])[:, 1:]
    return np.repeat(sample, AXES_NEIGHBOURS), near.ravel()


def _tree(points: np.ndarray) -> cKDTree:
    """A k-d tree of ``points`` (n, d) for nearest-neighbour queries, its nodes neither
    balanced at the median nor shrunk to their points (the same neighbours, built in
    about half the time: 19 against 35 ms at 116,000 points in the plane)."""
    from scipy.spatial import cKDTree

    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _steps(image: np.ndarray, pairs: Pairs | None = None) -> tuple[Pairs, Pairs]:
    """:func:`sensor_axes`' steps in ``image`` (n, 2): the (first, second) point indices
    of the steps along its rows and along its columns, among ``pairs`` (neighbours in the
    image by default, :func:`_neighbours`)."""
    first, second = _neighbours(image) if pairs is None else pairs
    step = image[second] - image[first]
    angle = np.arctan2(step[:, 1], step[:, 0])
    turn = angle - np.angle(np.exp(4j * angle).sum()) / 4  # from the dominant direction
    sine = np.sin(np.radians(AXES_STEP_DEGREES))
    rows, columns = np.abs(np.sin(turn)) < sine, np.abs(np.cos(turn)) < sine
    return (first[rows], second[rows]), (first[columns], second[columns])


def _least_direction(vectors: np.ndarray) -> np.ndarray | None:
    """The unit vector (3,) most nearly square to every one of ``vectors`` (k, 3) (the
    least eigenvector of their directions' scatter), refitted twice without those more
    than three times the median off square to it; None for fewer than three."""
    size = np.linalg.norm(vectors, axis=1)
    directions = vectors[size > 0.0] / size[size > 0.0, None]
    if len(directions) < 3:
        return None
    kept = directions
    for _ in range(2):
        off = np.abs(directions @ _least_eigenvector(kept))
        kept = directions[off <= 3.0 * np.median(off)]
        if len(kept) < 3:
            return None
    return _least_eigenvector(kept)


def _least_eigenvector(directions: np.ndarray) -> np.ndarray:
    """(3,) the unit vector least along ``directions`` (k, 3)."""
    least: np.ndarray = np.linalg.eigh(directions.T @ directions)[1][:, 0]
    return least


def _unit_columns(*columns: np.ndarray) -> np.ndarray | None:
    """(3, 3) the ``columns`` (3,) each made a unit vector; None when one is zero."""
    size = np.array([np.linalg.norm(column) for column in columns])
    if not (size > 1e-12).all():
        return None
    frame: np.ndarray = np.stack(columns, axis=1) / size
    return frame


def _joined(rows: Pairs, columns: Pairs) -> Pairs:
    """The steps along ``rows`` and along ``columns`` as one set of pairs."""
    return np.concatenate([rows[0], columns[0]]), np.concatenate([rows[1], columns[1]])


def _pitches(image: _Image, steps: Pairs) -> tuple[float, float] | None:
    """The pitches (across columns, across rows) of the lattice ``image`` may lie on: the
    median length of the ``steps`` that run along each of its axes (at least twice as
    far along it as across), or None when fewer than ten do."""
    delta = np.abs(image(steps[1]) - image(steps[0]))
    pitches = []
    for axis in (0, 1):
        along = delta[:, axis] > 2.0 * delta[:, 1 - axis]
        if along.sum() < 10:
            return None
        pitches.append(float(np.median(delta[along, axis])))
    return pitches[0], pitches[1]


def _pixels(
    image: _Image,
    trial: np.ndarray,
    rounding: float,
    pitches: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """(rows, columns) (n,) int of the points whose ``image`` lies on a lattice
    (:func:`lattice_steps`, ``rounding`` allowed for; near one of about ``pitches``,
    :func:`snapped_steps`, when given), or None. Most frames hold no lattice: the
    ``trial`` points (indices) tell first, and only then is every point's image made."""
    pixels = None
    for part in (image(trial), image()):
        if pitches is None:
            rows = lattice_steps(part[:, 1], rounding)
            columns = None if rows is None else lattice_steps(part[:, 0], rounding)
        else:
            rows = snapped_steps(part[:, 1], pitches[1])
            columns = None if rows is None else snapped_steps(part[:, 0], pitches[0])
        if rows is None or columns is None:
            return None
        pixels = rows, columns
    return pixels


def _facing(
    points: np.ndarray, faces: np.ndarray, viewpoint: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``points`` and ``faces`` with every triangle wound so that its normal faces
    ``viewpoint``."""
    corners = points[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    away = np.einsum("ij,ij->i", normals, corners[:, 0] - viewpoint) > 0.0
    faces = faces.copy()
    faces[away] = faces[away][:, ::-1]
    return points, faces


def read_pcd(
    data: bytes, max_bytes: int = DEFAULT_MAX_DECOMPRESSED_BYTES
) -> tuple[np.ndarray, np.ndarray, Cloud]:
    """A PCD file's (n, 3) vertices and (m, 3) triangles, and its cloud: an organized
    cloud's surface (:func:`organized_surface`, from its ``VIEWPOINT``), or one without
    a grid (``HEIGHT`` 1) as one view seen from there (:func:`viewed_surface`).

    Its data ``ascii``, ``binary`` (a record per point) or ``binary_compressed`` (PCL's
    default for files it saves: each field's values in turn, compressed by LZF,
    :func:`lzf_decompress`, to at most ``max_bytes``).

    Raises
    ------
    PointCloudError
        A cloud without a grid that is not one view from its ``VIEWPOINT``.
    UnreadableMeshError
        Not a PCD file, no x, y, z fields, other data, or points that do not match the
        header.
    """
    header, body = _pcd_header(data)
    fields = header["FIELDS"]
    try:
        width, height = int(header["WIDTH"][0]), int(header["HEIGHT"][0])
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
    except ValueError as exc:
        raise UnreadableMeshError(
            "The PCD header's WIDTH, HEIGHT or COUNT is not a whole number."
        ) from exc
    if not {"x", "y", "z"} <= set(fields):
        raise UnreadableMeshError("The PCD file has no x, y and z fields.")
    if not len(counts) == len(header["SIZE"]) == len(header["TYPE"]) == len(fields):
        raise UnreadableMeshError("The PCD header's FIELDS, SIZE, TYPE and COUNT disagree.")
    kind = header["DATA"][0].lower() if header["DATA"] else ""
    if kind not in ("ascii", "binary", "binary_compressed"):
        raise UnreadableMeshError(
            f"PCD data stored as {kind or 'nothing'} cannot be read here; save the cloud "
            "with DATA ascii, binary or binary_compressed."
        )
    n = width * height
    try:
        if kind == "ascii":
            with warnings.catch_warnings():  # a token that is not a number warns, or raises
                warnings.simplefilter("error")
                numbers = np.fromstring(body.decode("ascii"), sep=" ")
            values = numbers.reshape(n, sum(counts))
            column = {name: sum(counts[:i]) for i, name in enumerate(fields)}
            xyz = values[:, [column["x"], column["y"], column["z"]]]
        elif kind == "binary_compressed":
            xyz = _compressed_xyz(header, body, n, counts, max_bytes)
        else:
            dtype = np.dtype(
                [
                    (f"{i}", f"<{_PCD_TYPES[t.upper()]}{s}", (c,))
                    for i, (t, s, c) in enumerate(
                        zip(header["TYPE"], header["SIZE"], counts, strict=True)
                    )
                ]
            )
            records = np.frombuffer(body, dtype=dtype, count=n)
            xyz = np.stack([records[str(fields.index(a))][:, 0] for a in "xyz"], axis=1)
    except UnreadableMeshError:
        raise
    except (ValueError, KeyError, TypeError, IndexError, struct.error, DeprecationWarning) as exc:
        raise UnreadableMeshError(
            "The PCD file's points do not match its header: it is damaged or truncated."
        ) from exc
    pose = _pcd_viewpoint(header)
    viewpoint = pose[:3]
    with np.errstate(invalid="ignore"):  # a signalling NaN (a damaged file's) is a NaN too
        xyz = xyz.astype(np.float64)
    if height <= 1 or width <= 1:  # no grid: one view seen from its viewpoint
        return one_view(xyz, viewpoint, _rotation(pose[3:]))
    return organized_scan(xyz.reshape(height, width, 3), viewpoint)


def _pcd_viewpoint(header: dict[str, list[str]]) -> np.ndarray:
    """(7,) a PCD's ``VIEWPOINT``: the sensor's position, then its orientation as a
    quaternion ``qw qx qy qz`` (PCL's default, the identity, where the header has none)."""
    values = header.get("VIEWPOINT", [])[:7]
    try:
        return np.array([float(v) for v in values + _PCD_VIEWPOINT[len(values) :]])
    except ValueError as exc:
        raise UnreadableMeshError("The PCD header's VIEWPOINT is not seven numbers.") from exc


def _rotation(quaternion: np.ndarray) -> np.ndarray:
    """(3, 3) the rotation of a quaternion ``w x y z`` (any length; the identity for a
    zero one): the sensor's axes as columns."""
    from scipy.spatial.transform import Rotation

    if not float(np.linalg.norm(quaternion)) > 0.0:
        return np.eye(3)
    matrix: np.ndarray = Rotation.from_quat(quaternion, scalar_first=True).as_matrix()
    return matrix


def read_e57(
    data: bytes, max_bytes: int = DEFAULT_MAX_DECOMPRESSED_BYTES
) -> tuple[np.ndarray, np.ndarray, Cloud]:
    """An E57 file's scan (ASTM E2807, laser scanners' exchange format) as an organized
    cloud: a *structured* scan's points put on their grid by their ``rowIndex`` and
    ``columnIndex`` (the scanner's angular grid), in the file's global frame, and
    triangulated by it seen from the scan's position (:func:`organized_surface`).

    Raises
    ------
    PointCloudError
        The scan has no grid (no row and column indices, or one row or column).
    UnreadableMeshError
        Not an E57 file, no scan or several, a grid over ``max_bytes`` as points, or no
        E57 library for this platform (pye57's builds).
    """
    try:
        import pye57
    except ImportError as exc:
        raise UnreadableMeshError(
            "E57 files cannot be read on this server (the pye57 library has no build for "
            "its platform); export the scan as an organized PCD."
        ) from exc
    with tempfile.NamedTemporaryFile(suffix=".e57") as handle:
        handle.write(data)
        handle.flush()
        try:
            e57 = pye57.E57(handle.name)
        except Exception as exc:  # libE57's own error types, and pye57's
            raise UnreadableMeshError(
                "The file could not be read as E57: it is damaged or not an E57 file."
            ) from exc
        try:
            return _structured_scan(e57, max_bytes)
        except MeshError:
            raise
        except Exception as exc:  # libE57's errors; pye57 raises a plain Exception for a
            # scan in neither cartesian nor spherical coordinates
            raise UnreadableMeshError(
                "The E57 file's scan could not be read: it is damaged, truncated, or its "
                "points are in neither cartesian nor spherical coordinates."
            ) from exc
        finally:
            e57.close()


def _structured_scan(e57: Any, max_bytes: int) -> tuple[np.ndarray, np.ndarray, Cloud]:
    """:func:`read_e57`'s scan from an open ``pye57.E57``."""
    if e57.scan_count != 1:
        raise UnreadableMeshError(
            f"The E57 file holds {e57.scan_count} scans; upload one scan per file (each is "
            "one view, triangulated by its own grid)."
        )
    header = e57.get_header(0)
    if not {"rowIndex", "columnIndex"} <= set(header.point_fields):
        raise PointCloudError(
            "The E57 scan has no grid (no row and column index per point): its points' "
            "neighbours are unknown. Upload a triangle mesh, or a structured scan."
        )
    if header.point_count * 48 > max_bytes:  # x, y, z, row and column as read
        raise UnreadableMeshError(
            f"The E57 scan has {header.point_count:,} points, too many to read here; subsample it."
        )
    scan = e57.read_scan(0, row_column=True, ignore_missing_fields=True)
    rows = np.asarray(scan["rowIndex"], dtype=np.int64)
    columns = np.asarray(scan["columnIndex"], dtype=np.int64)
    if not len(rows):
        raise UnreadableMeshError("The E57 scan has no valid point.")
    # The scan's grid: its index bounds (the pixels that saw nothing are not read).
    first_row, last_row = _bounds(header, "row", rows)
    first_column, last_column = _bounds(header, "column", columns)
    rows, columns = rows - first_row, columns - first_column
    height, width = last_row - first_row + 1, last_column - first_column + 1
    if height <= 1 or width <= 1:
        raise PointCloudError(
            "The E57 scan's points lie on one row or column of its grid: no surface joins "
            "them. Upload a triangle mesh, or a structured scan."
        )
    if height * width * 24 > max_bytes:
        raise UnreadableMeshError(
            f"The E57 scan's grid has {height:,} x {width:,} cells, too many to read here; "
            "subsample it."
        )
    grid = np.full((height, width, 3), np.nan)
    # A pixel with several returns keeps the last one listed.
    grid[rows, columns] = np.stack([scan[f"cartesian{a}"] for a in "XYZ"], axis=1)
    viewpoint = np.asarray(e57.scan_position(0), dtype=np.float64).reshape(3)
    return organized_scan(grid, viewpoint)


def _bounds(header: Any, axis: str, indices: np.ndarray) -> tuple[int, int]:
    """The first and last ``axis`` ("row" or "column") index of an E57 scan's grid: its
    ``indexBounds``, widened to every point's (a file may leave them out)."""
    from pye57.libe57 import E57Exception

    first, last = int(indices.min()), int(indices.max())
    try:
        first = min(first, int(getattr(header, f"{axis}Minimum")))
        last = max(last, int(getattr(header, f"{axis}Maximum")))
    except E57Exception:  # no indexBounds
        pass
    return first, last


def _compressed_xyz(
    header: dict[str, list[str]], body: bytes, n: int, counts: list[int], max_bytes: int
) -> np.ndarray:
    """(n, 3) the x, y, z of ``binary_compressed`` data: the compressed and the raw sizes
    (two little-endian uint32), then the compressed bytes of each field's ``n`` values in
    turn (PCL's ``PCDWriter::writeBinaryCompressed``).

    Raises
    ------
    ValueError, KeyError, IndexError, struct.error
        Data that does not match the header.
    UnreadableMeshError
        A cloud larger than ``max_bytes`` once decompressed.
    """
    compressed, size = struct.unpack("<II", body[:8])
    sizes = [int(s) for s in header["SIZE"]]
    if size != n * sum(s * c for s, c in zip(sizes, counts, strict=True)):
        raise ValueError("the raw size is not the header's points")
    if size > max_bytes:
        raise UnreadableMeshError(
            f"The PCD cloud expands to more than {max_bytes:,} bytes; save a smaller cloud."
        )
    raw = lzf_decompress(body[8 : 8 + compressed], size)
    fields, offset, columns = header["FIELDS"], 0, {}
    for name, kind, width, count in zip(fields, header["TYPE"], sizes, counts, strict=True):
        values = np.frombuffer(
            raw, dtype=f"<{_PCD_TYPES[kind.upper()]}{width}", count=n * count, offset=offset
        )
        columns[name] = values.reshape(n, count)[:, 0]
        offset += n * count * width
    return np.stack([columns[a] for a in "xyz"], axis=1)


def lzf_decompress(data: bytes, size: int) -> bytes:
    """LZF-compressed ``data`` (Lehmann's liblzf, ``lzf_decompress``) as the ``size`` bytes
    it was made from.

    A control byte ``c`` below 32 is followed by ``c + 1`` literal bytes; any other copies
    ``(c >> 5) + 2`` bytes (plus the next byte when ``c >> 5`` is 7) from
    ``((c & 31) << 8) + next byte + 1`` bytes back in the output, overlapping it when the
    copy is longer than that distance.

    Raises
    ------
    ValueError, IndexError
        Damaged data: a copy from before the start, or an output of another size.
    """
    out = bytearray()
    at, end = 0, len(data)
    while at < end:
        control = data[at]
        at += 1
        if control < 32:
            run = control + 1
            if at + run > end:
                raise ValueError("a literal run past the end")
            out += data[at : at + run]
            at += run
        else:
            length = control >> 5
            if length == 7:
                length += data[at]
                at += 1
            back = ((control & 31) << 8) + data[at] + 1
            at += 1
            length += 2
            start = len(out) - back
            if start < 0:
                raise ValueError("a copy from before the start")
            if back >= length:
                out += out[start : start + length]
            else:  # the copy repeats the last ``back`` bytes
                out += (out[start:] * (length // back + 1))[:length]
        if len(out) > size:
            raise ValueError("more bytes than the header says")
    if len(out) != size:
        raise ValueError("fewer bytes than the header says")
    return bytes(out)


def _pcd_header(data: bytes) -> tuple[dict[str, list[str]], bytes]:
    """The header's entries (keyword -> its values) and the bytes after its DATA line."""
    header: dict[str, list[str]] = {}
    offset = 0
    while "DATA" not in header:
        end = data.find(b"\n", offset)
        if end < 0:
            raise UnreadableMeshError("The file could not be read as PCD: no DATA line.")
        line = data[offset:end].decode("ascii", errors="replace").strip()
        offset = end + 1
        if line and not line.startswith("#"):
            keyword, *values = line.split()
            header[keyword.upper()] = values
    for needed in ("FIELDS", "SIZE", "TYPE", "WIDTH", "HEIGHT"):
        if not header.get(needed):
            raise UnreadableMeshError(f"The file could not be read as PCD: no {needed} line.")
    return header, data[offset:]
