"""Reading and cleaning triangle meshes from user files.

``load_mesh`` accepts OBJ, PLY, OFF, STL, GLB and GLTF, a scanner's PCD and E57, and
points as text (XYZ, PTS, CSV), optionally gzip-compressed, from a path or from bytes
plus the original file name, and returns one clean, connected triangle surface (a cloud
triangulated as :mod:`.scans` reads it) or raises a :class:`~worker.engine.errors.MeshError` whose
message can be shown to the person who uploaded the file.
"""

from __future__ import annotations

import io
import re
import warnings
import zlib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .errors import (
    EmptyMeshError,
    FileTooLargeError,
    MeshError,
    NonFiniteCoordinatesError,
    NonManifoldError,
    TooFewVerticesError,
    TooManyFacesError,
    UnreadableMeshError,
)
from .formats import DEFAULT_MAX_DECOMPRESSED_BYTES, DEFAULT_MAX_FACES, mesh_format
from .scans import Cloud, one_view, read_e57, read_pcd
from .tol import TOL
from .topology import edge_keys, unique_rows, used_vertices

MIN_VERTICES = 10
#: Surface area of the canonical frame. fast_simplification collapses, pass after
#: pass, every edge whose quadric error is below an absolute threshold that grows
#: like 1e-9 (pass + 3)^7; at unit area the errors of a 2,500-vertex mesh fall
#: under it from the first passes and collapses happen nearly unordered (measured:
#: a decimated copy of a TOSCA file then moves the spectrum 4-10x more than at area
#: 1e4, where the thresholds stay below the errors as they should).
CANONICAL_AREA = 1e4
_TINY = float(np.finfo(float).tiny)


@dataclass(frozen=True)
class Mesh:
    """A triangle surface.

    Attributes
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64, indices into ``vertices``
    """

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)


def face_crosses(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle's corners and edge vectors' cross product, coordinate by coordinate
    on contiguous columns: ``(3, 3, m)`` corners ``a, b, c`` and ``(3, m)``
    ``(b - a) x (c - a)``, the same products in the same order as numpy's ``cross`` of
    (m, 3) rows (so bitwise equal to it), in a third of the time on a 100,000-face
    upload, where ``cross`` and ``norm`` walk strided rows."""
    columns = np.asarray(vertices, dtype=np.float64).T
    corners = np.stack([columns[:, corner] for corner in np.asarray(faces).T])
    return corners, column_cross(corners[1] - corners[0], corners[2] - corners[0])


def column_cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(3, m) the cross products of (3, m) vectors given coordinate by coordinate, bitwise
    numpy's ``cross`` of their (m, 3) rows."""
    return np.stack(
        [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    )


def column_dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(m,) the dot products of (3, m) vectors given coordinate by coordinate, bitwise
    ``(u * v).sum(axis=1)`` of their (m, 3) rows."""
    dotted: np.ndarray = u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
    return dotted


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m,) float, the area of every triangle: half its edge vectors' cross product
    (:func:`face_crosses`), bitwise ``0.5 * norm(cross(b - a, c - a), axis=1)``."""
    return cross_areas(face_crosses(vertices, faces)[1])


def cross_areas(cross: np.ndarray) -> np.ndarray:
    """(m,) half the lengths of (3, m) cross products (:func:`face_crosses`)."""
    areas: np.ndarray = 0.5 * np.sqrt(column_dot(cross, cross))
    return areas


def tiling_edge(area: float, n_vertices: int) -> float:
    """Edge of the equilateral tiling of ``area`` by a closed mesh of ``n_vertices``
    vertices (about ``2 n_vertices`` triangles)."""
    return float(np.sqrt(area / (2 * n_vertices) * 4 / np.sqrt(3)))


def cell_means(
    points: np.ndarray, cell: float, origin: np.ndarray | float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """The mean of ``points`` (n, 3) in each cube of side ``cell`` that holds any (a grid
    from ``origin``, as a voxel filter thins a cloud): (k, 3), in the cubes'
    lexicographic order, and (n,) each point's cube."""
    _, cube = unique_rows(np.floor((points - origin) / cell))
    sums = np.stack([np.bincount(cube, weights=points[:, k]) for k in range(3)], axis=1)
    means: np.ndarray = sums / np.bincount(cube)[:, None]
    return means, cube


def _gunzip(data: bytes, limit: int) -> bytes:
    """Decompress at most ``limit`` bytes, refusing gzip bombs without expanding them."""
    decompressor = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
    try:
        out = decompressor.decompress(data, limit + 1)
    except zlib.error as exc:
        raise UnreadableMeshError("The file ends in .gz but is not valid gzip data.") from exc
    if len(out) > limit:
        raise FileTooLargeError(
            f"The file expands to more than {limit // (1024 * 1024)} MB when decompressed, "
            "which is over this service's limit."
        )
    if not decompressor.eof:
        raise UnreadableMeshError("The gzip data is truncated.")
    return out


def _parse_triangle_off(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """The common ASCII OFF layout, parsed by numpy in one pass.

    ``OFF`` (or ``NOFF``, ``COFF``...), the three counts, one line per vertex
    (``x y z`` and possibly a normal or a colour, the same for every vertex) and
    ``3 a b c`` per face: trimesh's general parser takes about a second for a
    50,000-vertex file, this about a twentieth of it. Anything else (comments,
    polygons, face colours, binary OFF) returns None and is left to trimesh.
    """
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError:
        return None
    parts = text.split(maxsplit=4)
    if len(parts) < 5 or not parts[0].endswith("OFF") or "#" in text:
        return None
    try:
        n_vertices, n_faces = int(parts[1]), int(parts[2])
        int(parts[3])  # the edge count, unused
    except ValueError:
        return None
    with warnings.catch_warnings():  # bad text shows as a wrong count, checked below
        warnings.simplefilter("ignore")
        try:
            numbers = np.fromstring(parts[4], sep=" ")
        except ValueError:  # a token that is not a number (newer numpy raises)
            return None
    columns, rest = divmod(numbers.size - 4 * n_faces, max(n_vertices, 1))
    if n_vertices < 1 or n_faces < 0 or rest or columns < 3:
        return None
    faces = numbers[columns * n_vertices :].reshape(n_faces, 4)
    if not np.all(faces[:, 0] == 3) or not np.all(faces == np.round(faces)):
        return None
    vertices = numbers[: columns * n_vertices].reshape(n_vertices, columns)[:, :3]
    return np.ascontiguousarray(vertices), faces[:, 1:].astype(np.int64)


#: Formats of points as text, a point a line (its x, y and z: the columns a header line
#: names so, else its first three numbers; lines without three, a header or a count,
#: skipped).
TEXT_POINTS = ("xyz", "pts", "csv")


def _parse_text_points(data: bytes) -> np.ndarray:
    """(n, 3) the points of an XYZ, PTS or CSV file: on each line, its x, y and z
    (separated by spaces, tabs, commas or semicolons): the columns the header names
    ``x``, ``y`` and ``z`` (:func:`_named_columns`: a table written with its row numbers
    first, CloudCompare's ``//X,Y,Z``, PDAL's ``"X","Y","Z"``, in any order), else the
    first three (more columns, as colours or normals, ignored); lines before the first
    with three numbers (a header, a PTS count) skipped."""
    try:
        lines = data.decode("utf-8-sig").splitlines()
    except UnicodeDecodeError as exc:
        raise UnreadableMeshError("The file of points is not text.") from exc
    start = next(
        (i for i, line in enumerate(lines) if len(row := _tokens(line)) >= 3 and _numbers(row[:3])),
        None,
    )
    if start is None:
        return np.empty((0, 3))
    body = [line for line in lines[start:] if line.strip()]
    columns = len(_tokens(body[0]))
    header = [line for line in lines[:start] if line.strip()]
    named = _named_columns(header[-1]) if header else None
    xyz = list(named) if named is not None and max(named) < columns else [0, 1, 2]
    # Every line as many numbers as the first: all at once; otherwise line by line.
    with warnings.catch_warnings():  # a token that is not a number warns, or raises
        warnings.simplefilter("error")
        try:
            values = np.fromstring(_tokens_text(" ".join(body)), sep=" ")
            if values.size == columns * len(body):
                return np.ascontiguousarray(values.reshape(len(body), columns)[:, xyz])
        except (ValueError, DeprecationWarning):
            pass
    try:
        return np.array([[_tokens(line)[k] for k in xyz] for line in body], dtype=np.float64)
    except (ValueError, IndexError) as exc:
        raise UnreadableMeshError(
            "A line of the file of points does not hold its x, y and z as numbers."
        ) from exc


def _named_columns(line: str) -> tuple[int, int, int] | None:
    """The columns a header ``line`` names ``x``, ``y`` and ``z`` (any case, quoted or
    not, after a comment's ``//`` or ``#``; fields split as the numbers are, an empty
    first name, a table's row numbers, kept), or None."""
    text = line.strip().lstrip("/#").strip()
    fields = re.split(r"\s*[,;]\s*", text) if re.search(r"[,;]", text) else text.split()
    names = [field.strip("\"' ").lower() for field in fields]
    if not {"x", "y", "z"} <= set(names):
        return None
    return names.index("x"), names.index("y"), names.index("z")


def _tokens_text(text: str) -> str:
    return text.replace(",", " ").replace(";", " ")


def _tokens(line: str) -> list[str]:
    return _tokens_text(line).split()


def _numbers(tokens: list[str]) -> bool:
    try:
        [float(t) for t in tokens]
    except ValueError:
        return False
    return True


def _parse(
    data: bytes, fmt: str, max_bytes: int = DEFAULT_MAX_DECOMPRESSED_BYTES
) -> tuple[np.ndarray, np.ndarray, Cloud | None]:
    """A file's vertices and triangles (none for points alone), and its cloud when it is
    a scanner's triangulated by :mod:`.scans` (a compressed one expanding to at most
    ``max_bytes``)."""
    if fmt == "off" and (parsed := _parse_triangle_off(data)) is not None:
        return (*parsed, None)
    if fmt in TEXT_POINTS:
        return _parse_text_points(data), np.empty((0, 3), dtype=np.int64), None
    if fmt == "pcd":
        return read_pcd(data, max_bytes)
    if fmt == "e57":
        return read_e57(data, max_bytes)
    import trimesh  # heavy import, only needed when a file is actually parsed

    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=fmt, process=False)
        # Scenes (GLB/GLTF, multi-object OBJ): every mesh placed by its transform.
        parts = loaded.dump() if isinstance(loaded, trimesh.Scene) else [loaded]
    except Exception as exc:  # trimesh raises many unrelated types on bad bytes
        raise UnreadableMeshError(
            f"The file could not be read as {fmt.upper()}: it is damaged or not a mesh."
        ) from exc
    meshes = [p for p in parts if isinstance(p, trimesh.Trimesh) and len(p.faces)]
    if not meshes:  # points alone, read as one view (_read_arrays)
        clouds = [np.asarray(getattr(p, "vertices", ()), dtype=np.float64) for p in parts]
        clouds = [c for c in clouds if c.size]
        if any(c.ndim != 2 or c.shape[1] != 3 for c in clouds):
            raise UnreadableMeshError(
                f"The file could not be read as {fmt.upper()}: it is damaged or not a mesh."
            )
        points = np.concatenate([np.empty((0, 3)), *clouds])
        return points, np.empty((0, 3), dtype=np.int64), None
    vertices, faces, offset = [], [], 0
    for mesh in meshes:
        vertices.append(np.asarray(mesh.vertices, dtype=np.float64))
        faces.append(np.asarray(mesh.faces, dtype=np.int64) + offset)
        if vertices[-1].ndim != 2 or vertices[-1].shape[1] != 3:
            # an OBJ's vertex line cut short parses as fewer coordinates
            raise UnreadableMeshError(
                f"The file could not be read as {fmt.upper()}: it is damaged or not a mesh."
            )
        offset += len(vertices[-1])
    return np.concatenate(vertices), np.concatenate(faces), None


@dataclass(frozen=True)
class CleanedMesh:
    """A cleaned surface and how much of its source it keeps.

    Attributes
    ----------
    mesh : the largest connected part of the source's surface (:func:`clean_mesh`).
    kept_area_fraction : its share of the source's surface area (after duplicate and
        degenerate triangles are removed); below 1 when the source had other, separate
        parts, which are not described.
    cloud : the point cloud the source was, triangulated as :mod:`.scans` reads it (by
        its sensor grid, or as one view); None for a mesh.
    """

    mesh: Mesh
    kept_area_fraction: float
    cloud: Cloud | None = None


def clean_mesh(vertices: np.ndarray, faces: np.ndarray) -> Mesh:
    """Merge duplicate vertices, drop degenerate faces, keep the largest component.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int

    Returns
    -------
    Mesh with only referenced vertices (renumbered).
    """
    return clean_surface(vertices, faces).mesh


def clean_surface(vertices: np.ndarray, faces: np.ndarray) -> CleanedMesh:
    """:func:`clean_mesh`, also saying what share of the surface area it kept."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)

    # Merge vertices that coincide up to a tiny fraction of the model size (relative:
    # a model in any unit merges alike).
    extent = float(np.linalg.norm(np.ptp(vertices, axis=0))) if len(vertices) else 0.0
    if extent == 0.0 and len(faces):
        raise TooFewVerticesError(
            "Every vertex of the file is at the same point. If the model is in a very small "
            "unit, its coordinates may have been written with too few digits (a text format "
            "with a fixed number of decimals): export it with more digits or in a larger unit."
        )
    quantum = (extent or 1.0) * TOL.merge_fraction
    first, inverse = unique_rows(np.round(vertices / quantum).astype(np.int64))
    faces = inverse[faces]

    # Faces with a repeated corner or (almost) zero area carry no surface.
    repeated = (
        (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    )
    faces = faces[~repeated]
    merged = vertices[first]
    area = face_areas(merged, faces) if len(faces) else np.zeros(0)
    if len(faces):
        solid = area > TOL.degenerate_area_fraction * max(area.mean(), np.finfo(float).tiny)
        faces, area = faces[solid], area[solid]
    if len(faces):
        # The same triangle listed twice (in any corner order) is one face.
        first_face, _ = unique_rows(np.sort(faces, axis=1))
        kept = np.sort(first_face)
        faces, area = faces[kept], area[kept]
    if not len(faces):
        raise TooFewVerticesError(
            "After removing duplicate vertices and degenerate triangles no surface is left."
        )

    # Keep the connected component with the most faces (specks and debris are dropped).
    n = len(merged)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    graph = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    face_component = component[faces[:, 0]]
    largest = np.bincount(face_component).argmax()
    in_largest = face_component == largest
    faces = faces[in_largest]
    kept_area_fraction = float(area[in_largest].sum() / area.sum())

    used = used_vertices(faces, n)
    renumber = np.full(n, -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    mesh = Mesh(vertices=merged[used], faces=renumber[faces])
    return CleanedMesh(mesh=mesh, kept_area_fraction=kept_area_fraction)


def canonical_frame(mesh: Mesh) -> Mesh:
    """The same surface centred on its area centroid, turned to its principal axes
    and scaled to an area of ``CANONICAL_AREA``.

    Every descriptor is invariant to rigid motion and scale, so this changes none
    of them mathematically; it removes the file's units and orientation from the
    floating-point work that follows. Quadric decimation in particular gives a
    different vertex set for a rotated or rescaled copy of the same file (measured
    on TOSCA: as different as a decimation of another tessellation), and at 1e30
    or 1e-30 length units its results drift. Axis signs follow the sign of the
    third moment along each axis, so a rotated copy lands on the same coordinates
    up to rounding (ties, as on a sphere, stay arbitrary).

    Parameters
    ----------
    mesh : a cleaned mesh.

    Returns
    -------
    Mesh with the same faces and transformed vertices.
    """
    vertices = mesh.vertices
    # Order-one coordinates first, so that squares and cubes below cannot overflow.
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    vertices = (vertices - 0.5 * (low + high)) / max(float(np.max(high - low)), _TINY)
    areas = face_areas(vertices, mesh.faces)
    total = float(areas.sum())
    # The corners' mean as two sums and a division, as vertices[faces].mean(axis=1)
    # computes it (bitwise equal), without its slow reduction over a middle axis.
    a, b, c = mesh.faces.T
    centroids = (vertices[a] + vertices[b] + vertices[c]) / 3.0
    centre = areas @ centroids / total
    scale = np.sqrt(CANONICAL_AREA / total)
    offsets = (centroids - centre) * scale
    _, axes = np.linalg.eigh((offsets * areas[:, None]).T @ offsets / total)
    axes = axes[:, ::-1]  # largest spread first
    # Only the third moments' signs are used: cubes by two products (numpy's ``** 3``
    # calls pow, 30 times slower), which can differ from it in the last bit.
    along = offsets @ axes
    skew = areas @ (along * along * along)
    axes = axes * np.where(skew < 0.0, -1.0, 1.0)
    return Mesh(vertices=((vertices - centre) * scale) @ axes, faces=mesh.faces)


def non_manifold_face_fraction(faces: np.ndarray, n_vertices: int) -> float:
    """Fraction of ``faces`` (m, 3) that touch an edge shared by three or more faces."""
    if not len(faces):
        return 0.0
    _, inverse, counts = np.unique(
        edge_keys(faces, n_vertices).ravel(), return_inverse=True, return_counts=True
    )
    per_face = counts[inverse].reshape(-1, 3).max(axis=1)
    return float(np.mean(per_face > 2))


def load_mesh(
    source: str | Path | bytes,
    filename: str | None = None,
    *,
    max_faces: int = DEFAULT_MAX_FACES,
    max_decompressed_bytes: int = DEFAULT_MAX_DECOMPRESSED_BYTES,
    min_vertices: int = MIN_VERTICES,
) -> Mesh:
    """Read a mesh file and return its cleaned largest connected surface
    (:func:`read_mesh`'s mesh)."""
    return read_mesh(
        source,
        filename,
        max_faces=max_faces,
        max_decompressed_bytes=max_decompressed_bytes,
        min_vertices=min_vertices,
    ).mesh


def read_mesh(
    source: str | Path | bytes,
    filename: str | None = None,
    *,
    max_faces: int = DEFAULT_MAX_FACES,
    max_decompressed_bytes: int = DEFAULT_MAX_DECOMPRESSED_BYTES,
    min_vertices: int = MIN_VERTICES,
) -> CleanedMesh:
    """Read a mesh file: its cleaned largest connected surface, and the share of the
    file's surface area that is (other separate parts are left out).

    Parameters
    ----------
    source : path of the file, or its bytes.
    filename : the original file name; required with bytes, it selects the format.
    max_faces : refuse meshes with more triangles than this.
    max_decompressed_bytes : refuse ``.gz`` files that expand beyond this.
    min_vertices : refuse surfaces with fewer vertices than this after cleaning.

    Raises
    ------
    MeshError
        A subclass naming what is wrong, with a sentence for the user.
    """
    vertices, faces, cloud = _read_arrays(source, filename, max_faces, max_decompressed_bytes)
    cleaned = replace(clean_surface(vertices, faces), cloud=cloud)
    mesh = cleaned.mesh
    if mesh.n_vertices < min_vertices:
        raise TooFewVerticesError(
            f"After cleaning, the largest connected surface has only {mesh.n_vertices} "
            f"vertices; at least {min_vertices} are needed."
        )
    # Geodesics and the Laplace-Beltrami operator are defined on a 2-manifold; a
    # fan of triangles hinged on one edge has no surface to walk on.
    if non_manifold_face_fraction(mesh.faces, mesh.n_vertices) > TOL.max_non_manifold_face_fraction:
        raise NonManifoldError(
            "The mesh is not a surface: many triangles meet at edges shared by three or more "
            "triangles (non-manifold); upload a manifold triangle mesh."
        )
    return cleaned


def read_numbered_mesh(
    source: str | Path | bytes,
    filename: str | None = None,
    *,
    max_faces: int = DEFAULT_MAX_FACES,
    max_decompressed_bytes: int = DEFAULT_MAX_DECOMPRESSED_BYTES,
) -> Mesh:
    """Read a mesh file's vertices and triangles as the file numbers them, checked as
    :func:`read_mesh` checks a file but not cleaned (cleaning renumbers the vertices):
    what a resampling carried between the poses of one figure by vertex id needs
    (:func:`~worker.engine.resample.shared_resampling`).

    Raises
    ------
    MeshError
        As :func:`read_mesh`, for what is wrong with the file itself.
    """
    vertices, faces, _ = _read_arrays(source, filename, max_faces, max_decompressed_bytes)
    return Mesh(vertices=vertices, faces=faces)


def _read_arrays(
    source: str | Path | bytes,
    filename: str | None,
    max_faces: int,
    max_decompressed_bytes: int,
) -> tuple[np.ndarray, np.ndarray, Cloud | None]:
    """A file's vertices (n, 3) float and triangles (m, 3) int as it numbers them, after
    the checks of the file itself (format, size, triangles, indices, coordinates), and
    its cloud when it was points (points without triangles read as one view seen from
    the origin of their frame, or from afar along their thinnest direction,
    :func:`~.scans.one_view`)."""
    if isinstance(source, bytes | bytearray | memoryview):
        if filename is None:
            raise ValueError("filename is required when the mesh is given as bytes")
        data = bytes(source)
    else:
        path = Path(source)
        filename = filename or path.name
        data = path.read_bytes()
    fmt, gzipped = mesh_format(filename)
    if gzipped:
        data = _gunzip(data, max_decompressed_bytes)
    if not data.strip():
        raise EmptyMeshError("The file is empty.")

    vertices, faces, cloud = _parse(data, fmt, max_decompressed_bytes)
    if not len(vertices):
        raise EmptyMeshError("The file contains no vertices.")
    if not len(faces):
        if len(vertices) > max_faces // 2:  # a view's triangles are about twice its points
            raise TooManyFacesError(
                f"The cloud has {len(vertices):,} points; the limit is {max_faces // 2:,}. "
                "Subsample it before uploading."
            )
        vertices, faces, cloud = one_view(vertices, np.zeros(3))
    if len(faces) > max_faces:
        raise TooManyFacesError(
            f"The mesh has {len(faces):,} triangles; the limit is {max_faces:,}. "
            "Simplify it before uploading."
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise UnreadableMeshError("Some triangles refer to vertices that do not exist.")
    used = vertices[used_vertices(faces, len(vertices))]
    if not np.all(np.isfinite(used)) or np.abs(used).max() > TOL.max_abs_coordinate:
        raise NonFiniteCoordinatesError(
            "Some vertex coordinates are not finite numbers (NaN, infinity or too large)."
        )
    return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), cloud


__all__ = [
    "CleanedMesh",
    "Mesh",
    "MeshError",
    "canonical_frame",
    "clean_mesh",
    "clean_surface",
    "load_mesh",
    "read_mesh",
    "read_numbered_mesh",
]
