"""Mesh input: every supported format, gzip, cleaning, and a typed error per bad input."""

from __future__ import annotations

import gzip
import io

import numpy as np
import pytest
import trimesh
from conftest import random_rotation

from worker.engine import errors, mesh_io
from worker.engine.formats import mesh_format
from worker.engine.mesh_io import (
    CANONICAL_AREA,
    Mesh,
    canonical_frame,
    clean_mesh,
    clean_surface,
    column_cross,
    column_dot,
    face_areas,
    load_mesh,
    read_mesh,
    read_numbered_mesh,
)


@pytest.fixture(scope="module")
def sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=3)


@pytest.mark.parametrize("fmt", ["obj", "ply", "off", "stl", "glb"])
@pytest.mark.parametrize("gz", [False, True])
def test_reads_every_format_from_bytes_and_path(tmp_path, sphere, fmt, gz):
    data = sphere.export(file_type=fmt)
    data = data.encode() if isinstance(data, str) else data
    name = f"shape.{fmt}" + (".gz" if gz else "")
    if gz:
        data = gzip.compress(data)
    (tmp_path / name).write_bytes(data)
    for mesh in (load_mesh(data, name), load_mesh(tmp_path / name)):
        # STL stores unmerged triangles: cleaning merges them back.
        assert mesh.n_vertices == len(sphere.vertices)
        assert mesh.n_faces == len(sphere.faces)
        area = trimesh.Trimesh(mesh.vertices, mesh.faces).area
        assert area == pytest.approx(sphere.area, rel=1e-5)


@pytest.mark.parametrize("fmt", ["obj", "ply", "off", "stl"])
@pytest.mark.parametrize("scale", [1e-30, 1e-6, 1e6, 1e30])
def test_a_file_in_any_unit_reads_as_the_same_surface(sphere, fmt, scale):
    """Merging is relative to the model's size: the same sphere in any unit keeps its
    vertices and faces (text written with every digit; STL holds float32)."""
    scaled = trimesh.Trimesh(sphere.vertices * scale, sphere.faces, process=False)
    if fmt in ("obj", "off"):
        rows = "".join(" ".join(repr(float(c)) for c in v) + "\n" for v in scaled.vertices)
        data = (
            (f"OFF\n{len(sphere.vertices)} {len(sphere.faces)} 0\n" + rows)
            + "".join(f"3 {a} {b} {c}\n" for a, b, c in sphere.faces)
            if fmt == "off"
            else "".join(f"v {r}" for r in rows.splitlines(keepends=True))
            + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in sphere.faces)
        ).encode()
    else:
        data = scaled.export(file_type=fmt)
    mesh = load_mesh(data, f"sphere.{fmt}")
    assert (mesh.n_vertices, mesh.n_faces) == (len(sphere.vertices), len(sphere.faces))
    rel = 1e-6 if fmt in ("ply", "stl") else 1e-12  # trimesh writes float32 there
    assert face_areas(mesh.vertices, mesh.faces).sum() == pytest.approx(scaled.area, rel=rel)


def test_a_file_whose_vertices_all_coincide_says_why(sphere):
    """A tiny unit written with a fixed number of decimals (trimesh's OFF: 10) leaves
    every coordinate 0: refused with the likely cause, not as a small surface."""
    tiny = trimesh.Trimesh(sphere.vertices * 1e-30, sphere.faces, process=False)
    with pytest.raises(errors.TooFewVerticesError, match="same point.*more digits"):
        load_mesh(trimesh.exchange.off.export_off(tiny).encode(), "tiny.off")


def test_reads_gltf_with_embedded_buffers(sphere):
    files = trimesh.Scene(sphere).export(file_type="gltf", embed_buffers=True)
    data = files["model.gltf"]
    mesh = load_mesh(data, "scene.gltf")
    assert mesh.n_faces == len(sphere.faces)


def test_tosca_file_reads(tosca_dir):
    mesh = load_mesh(tosca_dir / "wolf0.off.gz")
    assert mesh.n_vertices == 4344
    assert mesh.faces.max() < mesh.n_vertices


def test_cleaning_merges_drops_degenerate_and_keeps_largest_component(sphere):
    big = sphere
    small = trimesh.creation.icosphere(subdivisions=1, radius=0.1)
    first = big.faces[0]
    vertices = np.concatenate([big.vertices, small.vertices + 5.0, big.vertices[first[::-1]]])
    faces = np.concatenate(
        [
            big.faces,
            small.faces + len(big.vertices),
            [[0, 0, 1]],  # repeated corner
            [
                [len(vertices) - 3, len(vertices) - 2, len(vertices) - 1]
            ],  # face 0 again, other winding
        ]
    )
    # Split every face's vertices apart, as STL does.
    soup = vertices[faces].reshape(-1, 3)
    mesh = clean_mesh(soup, np.arange(len(soup)).reshape(-1, 3))
    assert mesh.n_vertices == len(big.vertices)
    assert mesh.n_faces == len(big.faces)


def test_the_share_of_the_surface_left_out_is_measured(tmp_path):
    """A file of two separate parts: the one with the most triangles is kept (a dense
    small sphere, not the coarse big one) and the kept share of the file's surface
    area says that the rest, four fifths of it, was left out."""
    dense = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    coarse = trimesh.creation.icosphere(subdivisions=2, radius=2.0)
    coarse.apply_translation([10.0, 0.0, 0.0])
    both = trimesh.util.concatenate([coarse, dense])
    cleaned = clean_surface(both.vertices, both.faces)
    assert cleaned.mesh.n_faces == len(dense.faces)
    expected = dense.area / (dense.area + coarse.area)
    assert cleaned.kept_area_fraction == pytest.approx(expected, rel=1e-12)
    assert 0.2 < expected < 0.25
    # The same through a file, and load_mesh's mesh is read_mesh's.
    path = tmp_path / "two_parts.off"
    path.write_bytes(both.export(file_type="off").encode())
    read = read_mesh(path)
    assert read.kept_area_fraction == pytest.approx(expected, rel=1e-6)  # OFF's decimals
    np.testing.assert_array_equal(load_mesh(path).faces, read.mesh.faces)
    # One part: all of it, exactly.
    one = clean_surface(dense.vertices, dense.faces)
    assert one.kept_area_fraction == 1.0
    assert np.isclose(face_areas(one.mesh.vertices, one.mesh.faces).sum(), dense.area)


def test_collinear_face_is_dropped():
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], dtype=float)
    mesh = clean_mesh(tri, np.array([[0, 1, 2], [0, 1, 3]]))
    assert mesh.n_faces == 1


def _off(vertices, faces) -> bytes:
    lines = ["OFF", f"{len(vertices)} {len(faces)} 0"]
    lines += [" ".join(str(c) for c in v) for v in vertices]
    lines += ["3 " + " ".join(str(i) for i in f) for f in faces]
    return ("\n".join(lines) + "\n").encode()


def test_unsupported_extension():
    with pytest.raises(errors.UnsupportedFormatError, match=r"\.docx"):
        load_mesh(b"hello", "report.docx")
    with pytest.raises(errors.UnsupportedFormatError, match="no extension"):
        mesh_format("README")


def test_empty_file():
    with pytest.raises(errors.EmptyMeshError):
        load_mesh(b"", "empty.obj")
    with pytest.raises(errors.EmptyMeshError):
        load_mesh(b"   \n", "blank.ply")


def test_random_bytes_are_unreadable():
    junk = np.random.default_rng(0).bytes(4096)
    for ext in ("ply", "glb", "off"):
        with pytest.raises(errors.MeshError) as info:
            load_mesh(junk, f"junk.{ext}")
        assert isinstance(info.value, errors.UnreadableMeshError | errors.EmptyMeshError)
        assert info.value.message.endswith(".")


def test_an_off_file_with_a_word_for_a_number_is_unreadable():
    """numpy refuses the token with a ValueError; the file is damaged, not a crash."""
    bad = b"OFF\n3 1 0\nx 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    with pytest.raises(errors.UnreadableMeshError, match="could not be read as OFF"):
        load_mesh(bad, "bad.off")


def test_an_obj_file_with_a_vertex_line_cut_short_is_unreadable():
    """trimesh reads the file's vertices as pairs (or single numbers) when a line holds
    fewer than three; the file is damaged, not a crash."""
    for line in (b"v 0.0\n", b"v 0.0 1.0\n"):
        bad = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n" + line + b"f 1 2 3\nf 1 3 4\n"
        with pytest.raises(errors.UnreadableMeshError, match="could not be read as OBJ"):
            load_mesh(bad, "bad.obj")


def test_truncated_gzip():
    data = gzip.compress(_off(*_tetra()))[:20]
    with pytest.raises(errors.UnreadableMeshError, match="truncated|not valid gzip"):
        load_mesh(data, "t.off.gz")


def test_gzip_bomb_is_refused_without_expanding():
    bomb = gzip.compress(b"0" * (8 * 1024 * 1024))
    with pytest.raises(errors.FileTooLargeError):
        load_mesh(bomb, "bomb.obj.gz", max_decompressed_bytes=1024 * 1024)


def test_a_point_cloud_that_is_no_view_is_read_as_the_view_that_sees_most_of_it():
    """Points filling a cube are no view from the origin, nor from afar (most of them
    hide behind others as seen from either): a PLY of them is read as the view that sees
    most of them, its triangles among the points seen, the rest counted as hidden."""
    points = np.random.default_rng(0).random((500, 3))
    read = mesh_io.read_mesh(trimesh.PointCloud(points).export(file_type="ply"), "cloud.ply")
    cloud = read.cloud
    assert cloud is not None and cloud.hidden is not None and cloud.hidden > 0
    assert cloud.points + cloud.hidden == len(points)
    assert read.mesh.n_vertices <= cloud.points
    nearest = np.linalg.norm(read.mesh.vertices[:, None] - points[None], axis=2).min(axis=1)
    assert nearest.max() < 1e-6  # the PLY's float32 coordinates


def test_non_finite_coordinates():
    vertices, faces = _tetra()
    vertices[1][0] = float("nan")
    with pytest.raises(errors.NonFiniteCoordinatesError):
        load_mesh(_off(vertices, faces), "nan.off")
    vertices, faces = _tetra()
    vertices[2][1] = 1e300
    with pytest.raises(errors.NonFiniteCoordinatesError):
        load_mesh(_off(vertices, faces), "huge.off")


def test_faces_indexing_missing_vertices():
    vertices, faces = _tetra()
    faces[0][2] = 99
    with pytest.raises(errors.MeshError):
        load_mesh(_off(vertices, faces), "bad.off")


def test_too_few_vertices_after_cleaning():
    with pytest.raises(errors.TooFewVerticesError):
        load_mesh(_off(*_tetra()), "tetra.off")
    # All vertices identical: every face is degenerate.
    with pytest.raises(errors.TooFewVerticesError):
        load_mesh(_off([[1, 1, 1]] * 4, [[0, 1, 2], [1, 2, 3]]), "point.off")


def test_non_manifold_fan_is_refused_and_a_stray_edge_tolerated(sphere):
    # 40 triangles hinged on one edge, like the pages of a book.
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    ring = np.c_[np.cos(angles), np.sin(angles), np.full(40, 0.5)]
    vertices = np.vstack([[0, 0, 0], [0, 0, 1], ring])
    faces = [[0, 1, i + 2] for i in range(40)]
    with pytest.raises(errors.NonManifoldError, match="non-manifold"):
        load_mesh(_off(vertices.tolist(), faces), "fan.off")
    # One extra triangle on an existing edge of a 1,280-face sphere is not refused.
    v, f = sphere.vertices, sphere.faces
    a, b = f[0][0], f[0][1]
    extra_vertex = (v[a] + v[b]) / 2 + 0.3 * (v[a] + v[b])
    vertices = np.vstack([v, extra_vertex])
    faces = np.vstack([f, [[a, b, len(v)]]])
    assert len(load_mesh(_off(vertices.tolist(), faces.tolist()), "s.off").faces) == len(f) + 1


def test_face_limit(sphere):
    data = sphere.export(file_type="ply")
    with pytest.raises(errors.TooManyFacesError, match="limit"):
        load_mesh(data, "s.ply", max_faces=100)


def _tetra():
    vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    faces = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
    return vertices, faces


def test_canonical_frame_undoes_rotation_translation_and_scale(sphere):
    rng = np.random.default_rng(5)
    # An ellipsoid with bumps: distinct principal axes, no symmetry to tie the signs.
    x, y, z = sphere.vertices.T
    bumps = 1.0 + 0.15 * np.sin(3 * x + 2 * y + 1.5 * z)
    shape = Mesh(sphere.vertices * bumps[:, None] * [3.0, 2.0, 1.0], sphere.faces)
    canonical = canonical_frame(shape)
    tri = canonical.vertices[canonical.faces]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert areas.sum() == pytest.approx(CANONICAL_AREA)
    assert np.linalg.norm(areas @ tri.mean(axis=1)) < 1e-9
    for scale in (1e-30, 0.01, 100.0, 1e30):
        rotated = shape.vertices @ random_rotation(rng).T
        moved = Mesh((rotated + [5.0, -3.0, 2.0]) * scale, shape.faces)
        np.testing.assert_allclose(
            canonical_frame(moved).vertices, canonical.vertices, atol=1e-9 * CANONICAL_AREA**0.5
        )


def test_face_areas_are_the_cross_product_formula_bitwise():
    # The fast path must give numpy's cross-and-norm numbers exactly: the canonical
    # frame's scale, and so every resample, depends on their sum to the last bit.
    rng = np.random.default_rng(11)
    vertices = rng.normal(size=(300, 3)) * 10.0 ** rng.uniform(-20, 20, size=(300, 1))
    faces = rng.integers(0, 300, size=(1000, 3))
    corners = vertices[faces]
    expected = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    np.testing.assert_array_equal(mesh_io.face_areas(vertices, faces), expected)


@pytest.mark.parametrize(
    ("header", "vertex_extra", "note"),
    [
        ("OFF", "", "plain"),
        ("NOFF", " 0 0 1", "normals"),
        ("OFF", "", "comment"),
        ("OFF", "", "quad"),
        ("OFF", "", "face colour"),
    ],
)
def test_fast_off_reader_agrees_with_trimesh(header, vertex_extra, note):
    """The numpy OFF reader takes the common layout; anything else goes to trimesh,
    and either way the mesh read is trimesh's."""
    vertices = ["0 0 0", "1 0 0", "1 1 0", "0 1 0", "0.5 0.5 1"]
    faces = ["3 0 1 4", "3 1 2 4", "3 2 3 4", "3 3 0 4"]
    faces += ["4 0 3 2 1"] if note == "quad" else ["3 0 2 1", "3 0 3 2"]
    if note == "face colour":
        faces = [f + " 255 0 0" for f in faces]
    lines = [header, f"{len(vertices)} {len(faces)} 0"] + [v + vertex_extra for v in vertices]
    if note == "comment":
        lines.insert(1, "# made by hand")
    data = ("\n".join(lines + faces) + "\n").encode()
    loaded = trimesh.load(io.BytesIO(data), file_type="off", process=False)
    fast = mesh_io._parse_triangle_off(data)
    assert (fast is not None) == (note in ("plain", "normals"))
    vertices_read, faces_read, grid = mesh_io._parse(data, "off")
    assert grid is None
    np.testing.assert_array_equal(vertices_read, loaded.vertices)
    np.testing.assert_array_equal(faces_read, loaded.faces)


def test_fast_off_reader_refuses_what_is_not_its_layout():
    for data in (b"OFF\n3 1 0\n0 0 0\n1 0 0\n", b"OFF\nx y z\n", "OFF\n1 0 0\n0 0 \xe9\n".encode()):
        assert mesh_io._parse_triangle_off(data) is None


def test_a_file_read_as_numbered_keeps_its_vertex_order(sphere):
    """Cleaning renumbers the vertices (by position); the numbered read keeps the
    file's, which the poses of one figure share."""
    rng = np.random.default_rng(2)
    order = rng.permutation(len(sphere.vertices))
    vertices, faces = sphere.vertices[order], np.argsort(order)[sphere.faces]
    data = _off(vertices, faces)
    numbered = read_numbered_mesh(data, "s.off")
    np.testing.assert_array_equal(numbered.vertices, vertices)
    np.testing.assert_array_equal(numbered.faces, faces)
    cleaned = read_mesh(data, "s.off").mesh
    assert not np.array_equal(cleaned.vertices, vertices)
    with pytest.raises(errors.UnreadableMeshError):
        read_numbered_mesh(_off(vertices, faces + len(vertices)), "s.off")


def test_column_products_are_numpy_s_bitwise():
    rng = np.random.default_rng(3)
    u, v = rng.normal(size=(2, 1000, 3)) * np.logspace(-6, 6, 1000)[:, None]
    assert np.array_equal(column_cross(u.T, v.T), np.cross(u, v).T)
    assert np.array_equal(column_dot(u.T, v.T), (u * v).sum(axis=1))
    faces = rng.integers(0, 1000, size=(500, 3))
    a, b, c = (u[faces[:, k]] for k in range(3))
    expected = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    assert np.array_equal(face_areas(u, faces), expected)
