"""Sample meshes the project owns: five articulated figures in four poses each.

The tests and a first try of the service need labelled meshes of several classes,
each in several poses, without the shared data sets (TOSCA, SCAPE). Each figure here
is a skeleton of bones, tapered tubes, carrying blobs, ellipsoids; a pose turns its
joints, which keeps every bone's length, so the poses of one figure are near-isometric
deformations of each other, like TOSCA's poses of one body.

The surface is the zero level set of the smooth union of the tubes' and blobs' signed
distances: one closed surface with the limbs fused to the body, filleted at the joints
(the engine keeps only the largest connected part of a file). It is extracted by
marching tetrahedra, which gives a closed manifold without the ambiguous cases of
marching cubes, and decimated to :data:`SAMPLE_VERTICES` vertices by MeshLab's
quadric edge collapse, which keeps that topology (the ``eval`` extra). Everything is
deterministic (no random numbers) and the coordinates are written rounded
(:data:`DECIMALS`), so ``shapes samples examples`` rewrites the committed folder.
"""

from __future__ import annotations

import csv
import gzip
import io
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from worker.engine.mesh_io import Mesh, clean_mesh

from .remesh import import_pymeshlab

#: The figures, in the order of ``labels.csv``.
SAMPLE_CLASSES = ("biped", "quadruped", "spider", "bird", "hand")
#: Poses of each figure (0 is its rest pose).
N_POSES = 4
#: Vertices of a written sample.
SAMPLE_VERTICES = 2500
#: MeshLab's quadric collapse weighs its error by triangle quality (0 to 1) by this
#: much: well-shaped triangles, for the engine's own resampling of the files.
DECIMATION_QUALITY = 0.5
#: Decimals of the written coordinates: the figures are 60 to 230 units across, and
#: their shortest edges about 0.03 (:data:`CROSSING_MARGIN`), so the rounding moves a
#: vertex by 1e-5 of the figure and merges none.
DECIMALS = 3
#: Grid steps across the thinnest tube's radius: the level set then resolves every
#: tube as a round section, several grid cells wide.
STEPS_PER_RADIUS = 2.5

Vector = tuple[float, float, float]


@dataclass(frozen=True)
class Bone:
    """A tapered tube of a skeleton, starting on its parent bone.

    Attributes
    ----------
    name : the joint's name in a pose.
    parent : the bone it starts on; None for the root bone, which starts at the
        figure's ``root``.
    at : where along the parent it starts (0 the parent's start, 1 its end).
    vector : (3,) float, from its start to its end in the rest pose.
    radii : its radius at the start and at the end.
    """

    name: str
    parent: str | None
    at: float
    vector: Vector
    radii: tuple[float, float]


@dataclass(frozen=True)
class Blob:
    """An ellipsoid carried by a bone: centred ``at`` along it, with semi-axes
    ``radii`` along the rest pose's x, y and z, turning with the bone."""

    bone: str
    at: float
    radii: Vector


@dataclass(frozen=True)
class Figure:
    """A skeleton, its blobs and its poses.

    Attributes
    ----------
    root : (3,) float, where the root bone starts.
    bones : parents before their children.
    blobs : the ellipsoids the bones carry.
    blend : width of the smooth union (same units): how far apart two parts start
        to fuse, i.e. how round the fillets at the joints are.
    poses : per pose, the joints it turns: bone name -> rotation vector in degrees
        (axis times angle, in the parent bone's frame); bones not named keep their
        rest direction relative to their parent.
    """

    root: Vector
    bones: tuple[Bone, ...]
    blobs: tuple[Blob, ...]
    blend: float
    poses: tuple[Mapping[str, Vector], ...]


def posed_bones(figure: Figure, pose: int) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Forward kinematics: where every bone of ``figure`` is in pose ``pose``.

    Returns
    -------
    bone name -> (start (3,), end (3,), frame (3, 3)), the frame turning the rest
    pose's directions into the posed bone's (the product of its ancestors' turns).
    """
    turns = figure.poses[pose]
    placed: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for bone in figure.bones:
        turn = Rotation.from_rotvec(np.radians(turns.get(bone.name, (0.0, 0.0, 0.0))))
        if bone.parent is None:
            start, frame = np.asarray(figure.root, dtype=np.float64), turn.as_matrix()
        else:
            parent_start, parent_end, parent_frame = placed[bone.parent]
            start = parent_start + bone.at * (parent_end - parent_start)
            frame = parent_frame @ turn.as_matrix()
        placed[bone.name] = (start, start + frame @ np.asarray(bone.vector), frame)
    return placed


def tube_distance(
    points: np.ndarray, start: np.ndarray, end: np.ndarray, radii: tuple[float, float]
) -> np.ndarray:
    """Signed distance (negative inside) of ``points`` (n, 3) to a tube around the
    segment ``start``-``end`` whose radius goes linearly from ``radii[0]`` to
    ``radii[1]``, with round ends; exact for a constant radius, close to it for the
    slight tapers of the figures. Returns (n,) float."""
    axis = end - start
    t = np.clip((points - start) @ axis / (axis @ axis), 0.0, 1.0)
    off_axis = np.linalg.norm(points - start - t[:, None] * axis, axis=1)
    distance: np.ndarray = off_axis - (radii[0] + t * (radii[1] - radii[0]))
    return distance


def blob_distance(
    points: np.ndarray, centre: np.ndarray, frame: np.ndarray, radii: Vector
) -> np.ndarray:
    """Signed distance of ``points`` (n, 3) to the ellipsoid with semi-axes ``radii``
    along the columns of ``frame`` (3, 3), centred on ``centre``: Quilez's first-order
    bound, exact on the surface (so its zero level set is the ellipsoid) and close
    near it. Returns (n,) float."""
    semi_axes = np.asarray(radii, dtype=np.float64)
    local = (points - centre) @ frame
    scaled = np.linalg.norm(local / semi_axes, axis=1)
    gradient = np.linalg.norm(local / semi_axes**2, axis=1)
    distance: np.ndarray = scaled * (scaled - 1.0) / np.maximum(gradient, np.finfo(float).tiny)
    return distance


def smooth_union(a: np.ndarray, b: np.ndarray, blend: float) -> np.ndarray:
    """Polynomial smooth minimum of two signed distances: ``min(a, b)`` where they
    differ by more than ``blend``, a fillet where they are closer."""
    h = np.clip(0.5 + 0.5 * (b - a) / blend, 0.0, 1.0)
    union: np.ndarray = b + (a - b) * h - blend * h * (1.0 - h)
    return union


def figure_field(figure: Figure, pose: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The figure's signed distance field sampled on a regular grid.

    Each part is evaluated only on the grid points within ``blend`` plus two steps of
    its bounding box: farther out its distance exceeds the blend, so it cannot change
    the union near the surface; points no part reaches keep a positive value.

    Returns
    -------
    values : (nx, ny, nz) float, negative inside the figure, positive on the grid's
        boundary.
    origin : (3,) float, the position of ``values[0, 0, 0]``.
    step : the grid spacing.
    """
    placed = posed_bones(figure, pose)
    step = min(min(bone.radii) for bone in figure.bones) / STEPS_PER_RADIUS
    parts: list[tuple[np.ndarray, np.ndarray, Callable[[np.ndarray], np.ndarray]]] = []
    for bone in figure.bones:  # (lowest corner, highest corner, distance of points)
        start, end, _ = placed[bone.name]
        reach = max(bone.radii)
        tube = partial(tube_distance, start=start, end=end, radii=bone.radii)
        parts.append((np.minimum(start, end) - reach, np.maximum(start, end) + reach, tube))
    for blob in figure.blobs:
        start, end, frame = placed[blob.bone]
        centre = start + blob.at * (end - start)
        reach = max(blob.radii)
        ellipsoid = partial(blob_distance, centre=centre, frame=frame, radii=blob.radii)
        parts.append((centre - reach, centre + reach, ellipsoid))
    margin = figure.blend + 2 * step
    low = np.min([part[0] for part in parts], axis=0) - margin
    high = np.max([part[1] for part in parts], axis=0) + margin
    shape = np.ceil((high - low) / step).astype(np.int64) + 1
    far = float(np.linalg.norm(high - low))
    values = np.full(tuple(shape), far)
    for part_low, part_high, distance in parts:
        first = np.maximum(np.floor((part_low - margin - low) / step).astype(np.int64), 0)
        last = np.minimum(np.ceil((part_high + margin - low) / step).astype(np.int64) + 1, shape)
        axes = [low[i] + step * np.arange(first[i], last[i]) for i in range(3)]
        points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        box = tuple(slice(first[i], last[i]) for i in range(3))
        values[box] = smooth_union(
            values[box], distance(points).reshape(values[box].shape), figure.blend
        )
    return values, low, step


#: The six tetrahedra of a grid cube around its diagonal from corner 0 to corner 7
#: (corner ``dx + 2 dy + 4 dz``): every cube is cut the same way, so neighbouring
#: cubes' tetrahedra share whole faces and the level set has no cracks.
CUBE_TETRAHEDRA = np.array(
    [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]]
)
#: Where the level crosses a grid edge, kept this far (a fraction of the edge) from
#: its ends: crossings near a grid point where the field is nearly 0 would otherwise
#: make edges of almost no length, which the decimation leaves (measured: 0.0015 units)
#: and the written rounding would merge. It moves the surface by a tenth of a step at
#: most, about what the linear interpolation between grid points errs by.
CROSSING_MARGIN = 0.1


def marching_tetrahedra(
    values: np.ndarray, origin: np.ndarray, step: float
) -> tuple[np.ndarray, np.ndarray]:
    """The zero level set of a field sampled on a grid, as a triangle mesh.

    The field is linear on each tetrahedron of the grid's cubes (:data:`CUBE_TETRAHEDRA`),
    so its level set is a triangle in a tetrahedron with one corner on one side and a
    quadrilateral, cut in two, in one with two on each side. Each grid edge the level
    crosses gives one vertex, shared by all the tetrahedra around it: the surface is a
    closed manifold when the grid's boundary is outside.

    Parameters
    ----------
    values : (nx, ny, nz) float, negative inside.
    origin : (3,) float, the position of ``values[0, 0, 0]``.
    step : the grid spacing.

    Returns
    -------
    vertices : (n, 3) float
    faces : (m, 3) int, ordered so that normals point to positive values (outward).
    """
    nx, ny, nz = values.shape
    flat = values.ravel()
    inside = values < 0.0
    corner_offsets = [(dx, dy, dz) for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)]
    # The cubes the level crosses: some corners inside, some not.
    in_cube = np.zeros((nx - 1, ny - 1, nz - 1), dtype=np.uint8)
    for dx, dy, dz in corner_offsets:
        in_cube += inside[dx : nx - 1 + dx, dy : ny - 1 + dy, dz : nz - 1 + dz]
    i, j, k = np.nonzero((in_cube > 0) & (in_cube < 8))
    offsets = np.array([(dx * ny + dy) * nz + dz for dx, dy, dz in corner_offsets])
    corners = ((i * ny + j) * nz + k)[:, None] + offsets  # (cubes, 8) flat grid indices
    tetrahedra = corners[:, CUBE_TETRAHEDRA].reshape(-1, 4)
    in_tetrahedron = inside.ravel()[tetrahedra]
    count = in_tetrahedron.sum(axis=1)
    crossed = (count > 0) & (count < 4)
    tetrahedra, in_tetrahedron, count = tetrahedra[crossed], in_tetrahedron[crossed], count[crossed]
    # Inside corners first: each case's triangles are then fixed (inside, outside) pairs.
    order = np.argsort(~in_tetrahedron, axis=1, kind="stable")
    tetrahedra = np.take_along_axis(tetrahedra, order, axis=1)
    cases = (
        (1, [[(0, 1), (0, 2), (0, 3)]]),
        (2, [[(0, 2), (0, 3), (1, 3)], [(0, 2), (1, 3), (1, 2)]]),
        (3, [[(0, 3), (1, 3), (2, 3)]]),
    )
    triangles = []  # (t, 3, 2) grid indices: each corner's (inside, outside) edge
    for inside_count, pattern in cases:
        of_case = tetrahedra[count == inside_count]
        for triangle in pattern:
            triangles.append(of_case[:, np.array(triangle)])
    edges = np.concatenate(triangles)
    keys, corner_vertex = np.unique(edges[..., 0] * flat.size + edges[..., 1], return_inverse=True)
    start, end = keys // flat.size, keys % flat.size
    fraction = np.clip(
        flat[start] / (flat[start] - flat[end]), CROSSING_MARGIN, 1.0 - CROSSING_MARGIN
    )

    def position(index: np.ndarray) -> np.ndarray:
        """(..., 3) float, where the grid points of flat indices ``index`` (...) are."""
        located: np.ndarray = origin + step * np.stack(np.unravel_index(index, values.shape), -1)
        return located

    vertices = position(start) + fraction[:, None] * (position(end) - position(start))
    faces = corner_vertex.reshape(-1, 3)
    # Outward is from inside to outside along the crossed edges.
    outward = (position(edges[..., 1]) - position(edges[..., 0])).sum(axis=1)
    corner = vertices[faces]
    normal = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])
    flip = np.einsum("ij,ij->i", normal, outward) < 0
    faces[flip] = faces[flip][:, ::-1]
    return vertices, faces


def topology_preserving_decimation(
    vertices: np.ndarray, faces: np.ndarray, n_vertices: int
) -> Mesh:
    """MeshLab's quadric edge collapse of a closed genus-0 surface to ``n_vertices``,
    refusing every collapse that would change the topology.

    fast_simplification (the engine's decimator) collapses in passes under a growing
    threshold, without a link condition: on these figures' thin limbs it left 4 of 16
    meshes non-manifold or short of a limb (measured on the biped, quadruped, bird and
    hand).

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int, a closed genus-0 surface.
    n_vertices : the vertex count wanted (a sphere's ``2 n - 4`` triangles).

    Returns
    -------
    Mesh, cleaned.
    """
    pymeshlab = import_pymeshlab("decimating the sample figures")
    meshes = pymeshlab.MeshSet()
    meshes.add_mesh(pymeshlab.Mesh(vertices, faces.astype(np.int32)))
    meshes.meshing_decimation_quadric_edge_collapse(
        targetfacenum=2 * n_vertices - 4,
        qualitythr=DECIMATION_QUALITY,
        preservenormal=True,
        preservetopology=True,
        optimalplacement=True,
    )
    result = meshes.current_mesh()
    return clean_mesh(result.vertex_matrix(), result.face_matrix())


def sample_mesh(name: str, pose: int) -> Mesh:
    """The sample figure ``name`` (one of :data:`SAMPLE_CLASSES`) in pose ``pose``
    (0 to ``N_POSES - 1``), as written: :data:`SAMPLE_VERTICES` vertices, coordinates
    rounded to :data:`DECIMALS`."""
    values, origin, step = figure_field(FIGURES[name](), pose)
    vertices, faces = marching_tetrahedra(values, origin, step)
    mesh = topology_preserving_decimation(vertices, faces, SAMPLE_VERTICES)
    return Mesh(vertices=np.round(mesh.vertices, DECIMALS), faces=mesh.faces)


def sample_name(name: str, pose: int) -> str:
    """File name of a sample, e.g. ``quadruped-3.off.gz``."""
    return f"{name}-{pose}.off.gz"


def off_gz_bytes(mesh: Mesh) -> bytes:
    """``mesh`` as gzip'd ASCII OFF; the same mesh always gives the same bytes (no time
    stamp in the gzip header)."""
    text = io.StringIO()
    text.write(f"OFF\n{mesh.n_vertices} {mesh.n_faces} 0\n")
    np.savetxt(text, mesh.vertices, fmt=f"%.{DECIMALS}f")
    np.savetxt(text, np.column_stack([np.full(mesh.n_faces, 3), mesh.faces]), fmt="%d")
    return gzip.compress(text.getvalue().encode("ascii"), mtime=0)


#: A partial scan the walk-through queries with: PARTIAL_SOURCE's sample with its top
#: (PARTIAL_SHARE of its vertices, along z) cut off, written as PARTIAL_SAMPLE.
PARTIAL_SOURCE = ("quadruped", 3)
PARTIAL_SHARE = 0.25
PARTIAL_SAMPLE = Path("partial") / "quadruped-3-top-cut.off.gz"
#: A depth camera's view of the same sample: its left side seen from afar (an
#: orthographic depth grid, about DEPTH_PIXELS pixels on it), written as the organized
#: cloud such a camera writes (ASCII PCD, ``nan`` where a pixel saw nothing).
DEPTH_SAMPLE = Path("partial") / "quadruped-3-depth.pcd.gz"
DEPTH_DIRECTION = (0.0, 1.0, 0.0)
DEPTH_PIXELS = 1500
#: The same sample standing on a floor, seen from its left FLOOR_ELEVATION degrees above
#: the floor (pixels a FLOOR_PIXELS-th of its extent apart), the frame cut around it so
#: that the floor runs out of it: what a depth camera on a tripod writes.
FLOOR_SAMPLE = Path("partial") / "quadruped-3-floor.pcd.gz"
FLOOR_ELEVATION = 35.0
FLOOR_PIXELS = 60


def pcd_bytes(points: np.ndarray, viewpoint: np.ndarray, data: str = "ascii") -> bytes:
    """An organized cloud (h, w, 3) (``nan`` where a pixel saw nothing) and its sensor's
    position (3,) as PCD (v0.7), ``data`` ``ascii`` (``DECIMALS`` decimals) or ``binary``
    (single precision); the same cloud always gives the same bytes."""
    height, width = points.shape[:2]
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\n"
        f"SIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {width}\nHEIGHT {height}\n"
        f"VIEWPOINT {' '.join(f'{v:.{DECIMALS}f}' for v in viewpoint)} 1 0 0 0\n"
        f"POINTS {width * height}\nDATA {data}\n"
    )
    if data == "binary":
        return header.encode("ascii") + points.reshape(-1, 3).astype("<f4").tobytes()
    text = io.StringIO()
    text.write(header)
    np.savetxt(text, points.reshape(-1, 3), fmt=f"%.{DECIMALS}f")
    return text.getvalue().encode("ascii")


def pcd_gz_bytes(points: np.ndarray, viewpoint: np.ndarray) -> bytes:
    """:func:`pcd_bytes` as ASCII, gzip'd (the depth example's file)."""
    return gzip.compress(pcd_bytes(points, viewpoint), mtime=0)


def e57_bytes(
    points: np.ndarray, viewpoint: np.ndarray, *, grid: bool = True, scans: int = 1
) -> bytes:
    """An organized cloud (h, w, 3) as an E57 file of ``scans`` structured scans taken
    from ``viewpoint`` (the scan's pose there, no rotation; its points relative to it):
    each point's row and column kept unless not ``grid``, the pixels that saw nothing
    marked invalid. Needs pye57 (a dependency where it has builds)."""
    import tempfile

    import pye57

    height, width = points.shape[:2]
    origin = np.asarray(viewpoint, dtype=np.float64)
    local = points.reshape(-1, 3) - origin
    seen = np.isfinite(local).all(axis=1)
    local = np.nan_to_num(local)
    fields: dict[str, np.ndarray] = {
        "cartesianX": local[:, 0],
        "cartesianY": local[:, 1],
        "cartesianZ": local[:, 2],
        "cartesianInvalidState": np.logical_not(seen).astype(np.int8),
    }
    if grid:
        rows, columns = np.divmod(np.arange(height * width), width)
        fields["rowIndex"] = rows.astype(np.int32)
        fields["columnIndex"] = columns.astype(np.int32)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "scan.e57"
        out = pye57.E57(str(path), mode="w")
        for _ in range(scans):
            out.write_scan_raw(fields, rotation=np.array([1.0, 0.0, 0.0, 0.0]), translation=origin)
        out.close()
        return path.read_bytes()


def depth_scan(mesh: Mesh, direction: np.ndarray, pixels: int) -> tuple[np.ndarray, np.ndarray]:
    """``mesh`` seen along ``-direction`` by an orthographic depth grid with about
    ``pixels`` pixels on it: the organized cloud (h, w, 3) and a viewpoint far along
    ``direction`` (3,)."""
    from .partial import depth_grid, far_viewpoint, grid_points

    extent = float(np.ptp(mesh.vertices, axis=0).max())
    image, origin = depth_grid(mesh, direction, extent / 10)
    pitch = extent / 10 * float(np.sqrt(np.count_nonzero(~np.isnan(image)) / pixels))
    image, origin = depth_grid(mesh, direction, pitch)
    return grid_points(image, origin, direction, pitch), far_viewpoint(mesh, direction)


def seen_from_left(elevation: float) -> np.ndarray:
    """The direction (3,) towards a camera on a figure's left (+y), ``elevation`` degrees
    above the floor (z up)."""
    angle = np.radians(elevation)
    return np.array([0.0, np.cos(angle), np.sin(angle)])


def floor_scan(mesh: Mesh, pitch: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``mesh`` on a floor as :data:`FLOOR_SAMPLE` sees it (its pixels ``pitch`` apart, by
    default a :data:`FLOOR_PIXELS`-th of its extent): the organized cloud (h, w, 3) and a
    viewpoint far along the camera's direction (3,)."""
    from .partial import far_viewpoint, floor_frame

    direction = seen_from_left(FLOOR_ELEVATION)
    if pitch is None:
        pitch = float(np.ptp(mesh.vertices, axis=0).max()) / FLOOR_PIXELS
    return floor_frame(mesh, direction, pitch), far_viewpoint(mesh, direction)


def write_samples(out_dir: str | Path) -> list[Path]:
    """Write every sample (``<class>-<pose>.off.gz``), ``labels.csv`` (columns
    ``file,class``), the partial scan ``PARTIAL_SAMPLE`` and the depth camera's views
    ``DEPTH_SAMPLE`` and ``FLOOR_SAMPLE`` into ``out_dir``; returns
    the paths written, labels last."""
    from .partial import planar_cut

    out = Path(out_dir)
    (out / PARTIAL_SAMPLE).parent.mkdir(parents=True, exist_ok=True)
    written, rows = [], []
    for name in SAMPLE_CLASSES:
        for pose in range(N_POSES):
            mesh = sample_mesh(name, pose)
            path = out / sample_name(name, pose)
            path.write_bytes(off_gz_bytes(mesh))
            written.append(path)
            rows.append((path.name, name))
            if (name, pose) == PARTIAL_SOURCE:
                part = planar_cut(mesh, PARTIAL_SHARE, np.array([0.0, 0.0, 1.0]))
                (out / PARTIAL_SAMPLE).write_bytes(off_gz_bytes(part))
                scan = depth_scan(mesh, np.array(DEPTH_DIRECTION), DEPTH_PIXELS)
                (out / DEPTH_SAMPLE).write_bytes(pcd_gz_bytes(*scan))
                (out / FLOOR_SAMPLE).write_bytes(pcd_gz_bytes(*floor_scan(mesh)))
                written += [out / PARTIAL_SAMPLE, out / DEPTH_SAMPLE, out / FLOOR_SAMPLE]
    labels = out / "labels.csv"
    with open(labels, "w", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(("file", "class"))
        writer.writerows(rows)
    return [*written, labels]


# -- the figures ------------------------------------------------------------------------
# Units are about centimetres; x points forward, y to the figure's left, z up. Paired
# limbs are written for the left side (suffix _l) and mirrored (_r).


def _mirrored(bones: list[Bone]) -> list[Bone]:
    """The bones, and a right-hand copy (y negated, ``_l`` -> ``_r``) of those whose
    name ends in ``_l``."""
    right = [
        Bone(
            name=bone.name[:-2] + "_r",
            parent=(
                bone.parent[:-2] + "_r"
                if bone.parent is not None and bone.parent.endswith("_l")
                else bone.parent
            ),
            at=bone.at,
            vector=(bone.vector[0], -bone.vector[1], bone.vector[2]),
            radii=bone.radii,
        )
        for bone in bones
        if bone.name.endswith("_l")
    ]
    return bones + right


def _mirror(rotation: Vector) -> Vector:
    """The right side's rotation of a left-side joint turned by ``rotation``: mirroring
    y turns a rotation vector (a pseudovector) into (-x, y, -z)."""
    return (-rotation[0], rotation[1], -rotation[2])


def _both(name: str, rotation: Vector) -> dict[str, Vector]:
    """The same turn of the left joint ``name`` and, mirrored, of the right one."""
    return {f"{name}_l": rotation, f"{name}_r": _mirror(rotation)}


def _bend(direction: Vector, degrees: float) -> Vector:
    """Rotation vector that bends a bone pointing along ``direction`` (horizontal)
    downward by ``degrees``: about the horizontal axis across it."""
    across = np.cross((0.0, 0.0, 1.0), direction)
    across = degrees * across / np.linalg.norm(across)
    return (float(across[0]), float(across[1]), float(across[2]))


def _spin(degrees: float) -> Vector:
    """Rotation vector about the vertical."""
    return (0.0, 0.0, degrees)


def biped() -> Figure:
    """A standing person: head, torso, arms out in an A, legs and feet."""
    bones = _mirrored(
        [
            Bone("pelvis", None, 0.0, (0.0, 0.0, 8.0), (12.0, 12.0)),
            Bone("spine", "pelvis", 1.0, (0.0, 0.0, 45.0), (11.0, 12.0)),
            Bone("neck", "spine", 1.0, (0.0, 0.0, 10.0), (5.5, 5.5)),
            Bone("head", "neck", 1.0, (0.0, 0.0, 18.0), (6.0, 6.0)),
            Bone("clavicle_l", "spine", 0.92, (0.0, 18.0, 0.0), (6.0, 5.5)),
            Bone("upper_arm_l", "clavicle_l", 1.0, (0.0, 12.0, -26.0), (5.0, 4.2)),
            Bone("forearm_l", "upper_arm_l", 1.0, (0.0, 6.0, -25.0), (4.0, 3.2)),
            Bone("hand_l", "forearm_l", 1.0, (0.0, 2.0, -13.0), (3.0, 2.8)),
            Bone("hip_l", "pelvis", 0.0, (0.0, 11.0, -4.0), (9.0, 8.0)),
            Bone("thigh_l", "hip_l", 1.0, (0.0, 2.0, -42.0), (7.5, 5.5)),
            Bone("shin_l", "thigh_l", 1.0, (0.0, 0.0, -40.0), (5.2, 4.0)),
            Bone("foot_l", "shin_l", 1.0, (13.0, 0.0, -3.0), (4.0, 3.5)),
        ]
    )
    blobs = (
        Blob("pelvis", 0.5, (12.0, 16.0, 11.0)),
        Blob("spine", 0.55, (11.0, 15.0, 26.0)),
        Blob("head", 0.45, (10.0, 8.5, 11.5)),
        Blob("hand_l", 0.6, (2.8, 4.0, 6.5)),
        Blob("hand_r", 0.6, (2.8, 4.0, 6.5)),
    )
    poses: tuple[Mapping[str, Vector], ...] = (
        {},
        {  # walking: left leg and right arm forward
            "thigh_l": (0.0, -25.0, 0.0),
            "shin_l": (0.0, 20.0, 0.0),
            "thigh_r": (0.0, 20.0, 0.0),
            "shin_r": (0.0, 15.0, 0.0),
            "upper_arm_l": (0.0, 15.0, 0.0),
            "upper_arm_r": (0.0, -20.0, 0.0),
            "forearm_r": (0.0, -30.0, 0.0),
            "neck": _spin(15.0),
        },
        {  # arms raised sideways, knees bent, leaning forward
            **_both("upper_arm", (55.0, 0.0, 0.0)),
            **_both("forearm", (30.0, 0.0, 0.0)),
            **_both("thigh", (0.0, -40.0, 0.0)),
            **_both("shin", (0.0, 60.0, 0.0)),
            **_both("foot", (0.0, -20.0, 0.0)),
            "spine": (0.0, 15.0, 0.0),
        },
        {  # reaching forward with the right arm, left elbow bent, left knee raised
            "upper_arm_r": (0.0, -75.0, 0.0),
            "forearm_r": (0.0, -20.0, 0.0),
            "forearm_l": (0.0, -90.0, 0.0),
            "thigh_l": (0.0, -45.0, 0.0),
            "shin_l": (0.0, 60.0, 0.0),
            "spine": _spin(15.0),
            "neck": (10.0, 0.0, -20.0),
        },
    )
    return Figure((0.0, 0.0, 95.0), tuple(bones), blobs, 3.0, poses)


def quadruped() -> Figure:
    """A four-legged animal: a barrel body in two halves, neck and head, tail."""
    bones = _mirrored(
        [
            Bone("back", None, 0.0, (40.0, 0.0, 0.0), (13.0, 14.0)),
            Bone("chest", "back", 1.0, (40.0, 0.0, 0.0), (14.0, 13.0)),
            Bone("neck", "chest", 1.0, (14.0, 0.0, 24.0), (9.0, 7.0)),
            Bone("head", "neck", 1.0, (22.0, 0.0, -6.0), (7.0, 4.5)),
            Bone("tail", "back", 0.0, (-30.0, 0.0, 8.0), (4.5, 2.5)),
            Bone("shoulder_l", "chest", 0.8, (0.0, 9.0, -8.0), (8.0, 7.0)),
            Bone("foreleg_l", "shoulder_l", 1.0, (0.0, 1.0, -24.0), (6.0, 4.5)),
            Bone("forefoot_l", "foreleg_l", 1.0, (0.0, 0.0, -26.0), (4.0, 3.2)),
            Bone("hip_l", "back", 0.2, (0.0, 9.0, -8.0), (8.0, 7.0)),
            Bone("hindleg_l", "hip_l", 1.0, (0.0, 1.0, -24.0), (6.5, 4.5)),
            Bone("hindfoot_l", "hindleg_l", 1.0, (0.0, 0.0, -26.0), (4.0, 3.2)),
        ]
    )
    blobs = (
        Blob("back", 0.5, (27.0, 15.0, 17.0)),
        Blob("chest", 0.5, (27.0, 16.0, 18.0)),
        Blob("head", 0.35, (13.0, 8.0, 8.5)),
    )
    poses: tuple[Mapping[str, Vector], ...] = (
        {},
        {  # walking, looking aside, tail swinging
            "foreleg_l": (0.0, -25.0, 0.0),
            "forefoot_l": (0.0, 15.0, 0.0),
            "foreleg_r": (0.0, 20.0, 0.0),
            "hindleg_l": (0.0, 20.0, 0.0),
            "hindleg_r": (0.0, -20.0, 0.0),
            "hindfoot_r": (0.0, 20.0, 0.0),
            "neck": _spin(25.0),
            "tail": _spin(25.0),
        },
        {  # grazing: head down, legs apart
            "neck": (0.0, 60.0, 0.0),
            "head": (0.0, 10.0, 0.0),
            **_both("foreleg", (0.0, -15.0, 0.0)),
            **_both("hindleg", (0.0, 15.0, 0.0)),
            "tail": (0.0, -20.0, 0.0),
        },
        {  # galloping with the body bent aside, tail up
            **_both("foreleg", (0.0, -40.0, 0.0)),
            **_both("forefoot", (0.0, 30.0, 0.0)),
            **_both("hindleg", (0.0, 35.0, 0.0)),
            **_both("hindfoot", (0.0, -20.0, 0.0)),
            "chest": _spin(12.0),
            "neck": (0.0, -20.0, 0.0),
            "tail": (0.0, 40.0, 0.0),
        },
    )
    return Figure((-40.0, 0.0, 60.0), tuple(bones), blobs, 3.0, poses)


#: The spider's legs on its left, as angles from straight ahead (degrees).
SPIDER_LEG_AZIMUTHS = (40.0, 75.0, 110.0, 140.0)


def spider() -> Figure:
    """A spider: cephalothorax and abdomen, four pairs of three-segment legs."""
    legs = []
    for i, azimuth in enumerate(SPIDER_LEG_AZIMUTHS, start=1):
        c, s = np.cos(np.radians(azimuth)), np.sin(np.radians(azimuth))
        legs += [
            Bone(f"femur{i}_l", "thorax", 0.4, (30.0 * c, 30.0 * s, 16.0), (3.2, 2.8)),
            Bone(f"tibia{i}_l", f"femur{i}_l", 1.0, (32.0 * c, 32.0 * s, -22.0), (2.7, 2.3)),
            Bone(f"tarsus{i}_l", f"tibia{i}_l", 1.0, (12.0 * c, 12.0 * s, -8.0), (2.2, 1.9)),
        ]
    bones = _mirrored(
        [
            Bone("thorax", None, 0.0, (12.0, 0.0, 0.0), (8.0, 8.0)),
            Bone("waist", "thorax", 0.0, (-22.0, 0.0, 2.0), (5.0, 5.0)),
            Bone("abdomen", "waist", 1.0, (-20.0, 0.0, 3.0), (6.0, 6.0)),
            *legs,
        ]
    )
    blobs = (Blob("thorax", 0.4, (14.0, 12.0, 8.0)), Blob("abdomen", 0.5, (18.0, 14.0, 12.0)))

    def lift(leg: int, degrees: float) -> Vector:
        """Raise left leg ``leg`` (1 front .. 4 back) by ``degrees`` at the body."""
        azimuth = np.radians(SPIDER_LEG_AZIMUTHS[leg - 1])
        return _bend((float(np.cos(azimuth)), float(np.sin(azimuth)), 0.0), -degrees)

    def knee(leg: int, degrees: float) -> Vector:
        """Bend left leg ``leg``'s tibia down by ``degrees``."""
        return lift(leg, -degrees)

    poses: tuple[Mapping[str, Vector], ...] = (
        {},
        {  # walking: alternate legs lifted
            "femur1_l": lift(1, 20.0),
            "femur3_l": lift(3, 20.0),
            "femur2_r": _mirror(lift(2, 20.0)),
            "femur4_r": _mirror(lift(4, 20.0)),
            "tibia1_l": knee(1, -15.0),
            "tibia3_l": knee(3, -15.0),
        },
        {  # crouching, every leg swept back
            **{
                name: turn
                for i in (1, 2, 3, 4)
                for name, turn in _both(f"femur{i}", _spin(8.0)).items()
            },
            **{
                name: turn
                for i in (1, 2, 3, 4)
                for name, turn in _both(f"tibia{i}", knee(i, 25.0)).items()
            },
        },
        {  # threatening: front legs raised high, abdomen tilted up
            **_both("femur1", lift(1, 45.0)),
            **_both("tibia1", knee(1, -30.0)),
            **_both("femur2", lift(2, 15.0)),
            "waist": (0.0, 20.0, 0.0),
        },
    )
    return Figure((0.0, 0.0, 20.0), tuple(bones), blobs, 1.5, poses)


def bird() -> Figure:
    """A bird: body, neck, head and beak, two-part flat wings, tail fan, legs."""
    bones = _mirrored(
        [
            Bone("body", None, 0.0, (30.0, 0.0, 3.0), (9.0, 9.0)),
            Bone("neck", "body", 1.0, (5.0, 0.0, 10.0), (5.0, 4.5)),
            Bone("head", "neck", 1.0, (6.0, 0.0, 0.0), (4.5, 4.5)),
            Bone("beak", "head", 1.0, (9.0, 0.0, -1.5), (2.6, 1.4)),
            Bone("tail", "body", 0.0, (-12.0, 0.0, -1.0), (3.0, 2.0)),
            Bone("wing_l", "body", 0.6, (-3.0, 24.0, 2.0), (3.5, 2.8)),
            Bone("tip_l", "wing_l", 1.0, (-6.0, 22.0, 0.0), (2.8, 2.0)),
            Bone("thigh_l", "body", 0.45, (0.0, 4.0, -16.0), (2.2, 1.8)),
            Bone("shank_l", "thigh_l", 1.0, (3.0, 0.0, -10.0), (1.7, 1.5)),
            Bone("foot_l", "shank_l", 1.0, (5.0, 0.0, -1.0), (1.5, 1.4)),
        ]
    )
    blobs = (
        Blob("body", 0.5, (19.0, 10.0, 10.0)),
        Blob("head", 0.3, (6.5, 5.5, 5.5)),
        Blob("tail", 0.6, (8.0, 6.0, 1.5)),
        Blob("wing_l", 0.5, (7.0, 12.0, 1.8)),
        Blob("wing_r", 0.5, (7.0, 12.0, 1.8)),
        Blob("tip_l", 0.5, (6.0, 11.0, 1.5)),
        Blob("tip_r", 0.5, (6.0, 11.0, 1.5)),
    )
    poses: tuple[Mapping[str, Vector], ...] = (
        {},
        {  # wings raised
            **_both("wing", (35.0, 0.0, 0.0)),
            **_both("tip", (15.0, 0.0, 0.0)),
            **_both("shank", (0.0, 20.0, 0.0)),
        },
        {  # wings lowered, head turned
            **_both("wing", (-30.0, 0.0, 0.0)),
            **_both("tip", (-20.0, 0.0, 0.0)),
            "neck": _spin(30.0),
            "tail": (0.0, -15.0, 0.0),
        },
        {  # banking: left wing up and swept back, right wing down, tail fanned up
            "wing_l": (45.0, 0.0, 0.0),
            "tip_l": (0.0, 0.0, 25.0),
            "wing_r": _mirror((-20.0, 0.0, 0.0)),
            "tail": (0.0, 20.0, 0.0),
            "neck": (0.0, 25.0, 0.0),
            **_both("thigh", (0.0, 25.0, 0.0)),
        },
    )
    return Figure((-15.0, 0.0, 30.0), tuple(bones), blobs, 1.2, poses)


#: The hand's fingers: (name, knuckle's y, direction from straight ahead in degrees,
#: phalanx lengths).
FINGERS = (
    ("index", 33.0, 15.0, (36.0, 24.0, 18.0)),
    ("middle", 11.0, 5.0, (40.0, 26.0, 20.0)),
    ("ring", -11.0, -5.0, (37.0, 24.0, 19.0)),
    ("little", -33.0, -15.0, (28.0, 19.0, 16.0)),
)
#: The thumb's direction after its first bone (degrees from straight ahead).
THUMB_AZIMUTH = 56.0


def hand() -> Figure:
    """A right hand, palm down, fingers spread: wrist, palm, four fingers of three
    phalanges, a thumb of three bones."""
    bones = [
        Bone("wrist", None, 0.0, (40.0, 0.0, 0.0), (22.0, 20.0)),
        Bone("palm", "wrist", 1.0, (80.0, 0.0, 0.0), (16.0, 16.0)),
    ]
    directions = {}
    for name, knuckle, azimuth, lengths in FINGERS:
        c, s = np.cos(np.radians(azimuth)), np.sin(np.radians(azimuth))
        directions[name] = (float(c), float(s), 0.0)
        bones += [
            Bone(f"{name}_root", "palm", 0.15, (68.0, knuckle, 0.0), (8.0, 8.0)),
            Bone(
                f"{name}1", f"{name}_root", 1.0, (lengths[0] * c, lengths[0] * s, 0.0), (7.5, 6.5)
            ),
            Bone(f"{name}2", f"{name}1", 1.0, (lengths[1] * c, lengths[1] * s, 0.0), (6.5, 5.8)),
            Bone(f"{name}3", f"{name}2", 1.0, (lengths[2] * c, lengths[2] * s, 0.0), (5.8, 5.2)),
        ]
    c, s = np.cos(np.radians(THUMB_AZIMUTH)), np.sin(np.radians(THUMB_AZIMUTH))
    directions["thumb"] = (float(c), float(s), 0.0)
    bones += [
        Bone("thumb_root", "palm", 0.1, (28.0, 38.0, -8.0), (11.0, 9.0)),
        Bone("thumb1", "thumb_root", 1.0, (30.0 * c, 30.0 * s, 0.0), (8.5, 7.5)),
        Bone("thumb2", "thumb1", 1.0, (24.0 * c, 24.0 * s, 0.0), (7.5, 6.5)),
    ]
    blobs = (Blob("palm", 0.5, (45.0, 46.0, 14.0)),)

    def curl(name: str, first: float, second: float, third: float) -> dict[str, Vector]:
        """Bend a finger's three joints down by these angles (degrees)."""
        return {
            f"{name}{joint}": _bend(directions[name], angle)
            for joint, angle in ((1, first), (2, second), (3, third))
        }

    poses: tuple[Mapping[str, Vector], ...] = (
        {},
        {  # every finger half curled
            **curl("index", 30.0, 40.0, 30.0),
            **curl("middle", 30.0, 40.0, 30.0),
            **curl("ring", 30.0, 40.0, 30.0),
            **curl("little", 30.0, 40.0, 30.0),
            "thumb1": _bend(directions["thumb"], 20.0),
            "thumb2": _bend(directions["thumb"], 25.0),
        },
        {  # pointing: the index straight, the others curled
            **curl("middle", 55.0, 60.0, 40.0),
            **curl("ring", 55.0, 60.0, 40.0),
            **curl("little", 55.0, 60.0, 40.0),
            "thumb1": _bend(directions["thumb"], 30.0),
        },
        {  # waving: the hand bent up at the wrist, the index spread, the little finger bent
            "palm": (0.0, -25.0, 0.0),
            "index1": _spin(8.0),
            **curl("little", 15.0, 20.0, 15.0),
            "thumb_root": _spin(15.0),
        },
    )
    return Figure((-40.0, 0.0, 0.0), tuple(bones), blobs, 3.0, poses)


#: Each class's figure, by name.
FIGURES = {
    "biped": biped,
    "quadruped": quadruped,
    "spider": spider,
    "bird": bird,
    "hand": hand,
}
