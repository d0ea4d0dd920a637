"""Generate the hostile-input corpus: malformed, degenerate and oversized mesh files.

Every file is made here (nothing is downloaded). ``build_corpus(max_faces)``
returns the cases in memory; ``python -m tests.hardening.make_corpus DIR``
writes them to ``DIR`` (one file per case, named after it).

Each :class:`Case` names what the service must answer: the status of a
synchronous ``POST /query`` and the error code, and, for uploads that pass the
service's cheap checks (extension, size), that the enrolled mesh ends
``failed`` with the same code and sentence.
"""

from __future__ import annotations

import gzip
import io
import random
import struct
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MESH_EXTENSIONS = ("obj", "ply", "off", "stl", "glb", "gltf")


@dataclass(frozen=True)
class Case:
    """One hostile file.

    Attributes
    ----------
    name : the case's id (also the stored file name's stem).
    filename : the name it is uploaded as (the extension selects the format).
    data : the bytes.
    status : what ``POST /query`` answers (413, 415 or 422).
    codes : acceptable ``error`` codes (a few cases can be refused by either of
        two checks, e.g. trimesh reads an empty OBJ as no vertices).
    early : refused by the service itself before a worker sees it (no mesh row).
    """

    name: str
    filename: str
    data: bytes
    status: int
    codes: tuple[str, ...]
    early: bool = False


# -- small writers -------------------------------------------------------------
def off(vertices, faces) -> bytes:
    vertices, faces = np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64)
    out = io.StringIO()
    out.write(f"OFF\n{len(vertices)} {len(faces)} 0\n")
    for v in vertices:
        out.write(" ".join(repr(float(x)) for x in v) + "\n")
    for f in faces:
        out.write("3 " + " ".join(str(int(i)) for i in f) + "\n")
    return out.getvalue().encode()


def obj(vertices, faces) -> bytes:
    out = io.StringIO()
    for v in np.asarray(vertices, dtype=float):
        out.write("v " + " ".join(repr(float(x)) for x in v) + "\n")
    for f in np.asarray(faces, dtype=np.int64):
        out.write("f " + " ".join(str(int(i) + 1) for i in f) + "\n")
    return out.getvalue().encode()


def ply_ascii(vertices, faces) -> bytes:
    vertices, faces = np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64)
    head = (
        "ply\nformat ascii 1.0\n"
        f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    body = "".join(" ".join(repr(float(x)) for x in v) + "\n" for v in vertices)
    body += "".join("3 " + " ".join(str(int(i)) for i in f) + "\n" for f in faces)
    return (head + body).encode()


def stl_binary(vertices, faces) -> bytes:
    vertices, faces = np.asarray(vertices, dtype="<f4"), np.asarray(faces, dtype=np.int64)
    out = bytearray(b"\0" * 80 + struct.pack("<I", len(faces)))
    for f in faces:
        out += struct.pack("<3f", 0, 0, 0) + vertices[f].tobytes() + b"\0\0"
    return bytes(out)


def icosphere(subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """A closed sphere (no trimesh needed to make the corpus)."""
    t = (1 + 5**0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
         (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]  # fmt: skip
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]  # fmt: skip
    vertices = [np.array(p, dtype=float) / np.linalg.norm(p) for p in v]
    faces = f

    def mid(a: int, b: int, cache: dict[tuple[int, int], int]) -> int:
        key = (min(a, b), max(a, b))
        if key not in cache:
            p = vertices[a] + vertices[b]
            vertices.append(p / np.linalg.norm(p))
            cache[key] = len(vertices) - 1
        return cache[key]

    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}
        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b, cache), mid(b, c, cache), mid(c, a, cache)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return np.array(vertices), np.array(faces, dtype=np.int64)


def _glb(vertices, faces) -> bytes:
    """A minimal valid binary glTF with one triangle mesh."""
    import json

    pos = np.asarray(vertices, dtype="<f4").tobytes()
    idx = np.asarray(faces, dtype="<u4").tobytes()
    binary = pos + idx
    binary += b"\0" * (-len(binary) % 4)
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
            {"buffer": 0, "byteOffset": len(pos), "byteLength": len(idx)},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": len(vertices),
                "type": "VEC3",
                "min": np.min(vertices, 0).tolist(),
                "max": np.max(vertices, 0).tolist(),
            },
            {
                "bufferView": 1,
                "componentType": 5125,
                "count": int(np.size(faces)),
                "type": "SCALAR",
            },
        ],  # fmt: skip
    }
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    chunks = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(binary), b"BIN\0")
    chunks += binary
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


# -- the corpus ----------------------------------------------------------------
UNREADABLE = ("unreadable_mesh", "empty_mesh", "no_faces")


def build_corpus(max_faces: int, seed: int = 5) -> list[Case]:
    """Every hostile case; ``max_faces`` is the service's face limit (one case exceeds it)."""
    rng = random.Random(seed)
    sphere_v, sphere_f = icosphere(2)  # 162 vertices, 320 faces
    cases: list[Case] = []

    def add(name, filename, data, status, codes, early=False):
        codes = (codes,) if isinstance(codes, str) else tuple(codes)
        cases.append(Case(name, filename, data, status, codes, early))

    good = {
        "obj": obj(sphere_v, sphere_f),
        "ply": ply_ascii(sphere_v, sphere_f),
        "off": off(sphere_v, sphere_f),
        "stl": stl_binary(sphere_v, sphere_f),
        "glb": _glb(sphere_v, sphere_f),
    }
    for ext in MESH_EXTENSIONS:
        # Empty and whitespace-only files: the service refuses an empty file itself.
        add(f"empty-{ext}", f"empty.{ext}", b"", 422, "empty_mesh", early=True)
        add(f"blank-{ext}", f"blank.{ext}", b" \n\t\n" * (8 + len(cases)), 422, UNREADABLE)
        # Random bytes.
        noise = bytes(rng.getrandbits(8) for _ in range(4096))
        add(f"random-{ext}", f"random.{ext}", noise, 422, UNREADABLE)
        add(f"random-{ext}-gz", f"random.{ext}.gz", gzip.compress(noise), 422, UNREADABLE)
    for ext, data in good.items():
        # A valid sphere cut in half: the rest of the file is missing.
        add(f"truncated-{ext}", f"truncated.{ext}", data[: len(data) // 2], 422, UNREADABLE)
    add("truncated-gz", "truncated.off.gz", gzip.compress(good["off"])[:200], 422, UNREADABLE)
    add("not-gzip", "plain.off.gz", good["off"], 422, "unreadable_mesh")
    # A word where a number belongs (numpy's reader raises ValueError on it).
    add("off-word-token", "word.off", b"OFF\n3 1 0\nx 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", 422,
        "unreadable_mesh")  # fmt: skip
    add("gltf-bad-json", "broken.gltf", b'{"asset": {"version": "2.0"}, "meshes": [', 422,
        UNREADABLE)  # fmt: skip
    add("gltf-missing-buffer", "external.gltf",
        b'{"asset":{"version":"2.0"},"buffers":[{"uri":"../../etc/passwd","byteLength":4}]}',
        422, UNREADABLE)  # fmt: skip

    # Wrong extension for the content (a smaller sphere, so the bytes differ from the
    # cases above: the same bytes under two formats are refused with 409, tested apart).
    small_v, small_f = icosphere(1)
    good = {
        "obj": obj(small_v, small_f),
        "ply": ply_ascii(small_v, small_f),
        "off": off(small_v, small_f),
        "stl": stl_binary(small_v, small_f),
        "glb": _glb(small_v, small_f),
    }
    add("off-as-stl", "sphere.stl", good["off"], 422, UNREADABLE)
    add("obj-as-ply", "sphere.ply", good["obj"], 422, UNREADABLE)
    add("stl-as-obj", "sphere.obj", good["stl"], 422, UNREADABLE)
    add("glb-as-off", "sphere.off", good["glb"], 422, UNREADABLE)
    add("png-as-glb", "picture.glb", b"\x89PNG\r\n\x1a\n" + bytes(200), 422, UNREADABLE)
    add("zip-as-obj", "archive.obj", b"PK\x03\x04" + bytes(300), 422, UNREADABLE)
    # Not a mesh extension at all: refused before any byte is stored.
    add("ext-txt", "sphere.txt", good["off"], 415, "unsupported_format", early=True)
    add("ext-none", "sphere", good["off"], 415, "unsupported_format", early=True)
    add("ext-exe-gz", "setup.exe.gz", gzip.compress(b"MZ" + bytes(100)), 415,
        "unsupported_format", early=True)  # fmt: skip

    # Numbers that cannot be computed with.
    for what, value in (("nan", np.nan), ("inf", np.inf), ("huge", 1e300)):
        v = sphere_v.copy()
        v[7, 1] = value
        add(f"coord-{what}-off", f"{what}.off", off(v, sphere_f), 422, "non_finite_coordinates")
        add(f"coord-{what}-obj", f"{what}.obj", obj(v, sphere_f), 422, "non_finite_coordinates")
    v = sphere_v.copy()
    v[:, 0] = 1e300
    add("coord-huge-ply", "huge.ply", ply_ascii(v, sphere_f), 422, "non_finite_coordinates")

    # Topology that is wrong or too small.
    f = sphere_f.copy()
    f[5] = (0, 1, 100_000)
    add("face-missing-vertex-off", "missing.off", off(sphere_v, f), 422, UNREADABLE)
    f2 = sphere_f.copy()
    f2[5] = (0, 1, -7)
    add("face-negative-index-ply", "negative.ply", ply_ascii(sphere_v, f2), 422, UNREADABLE)
    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    add("single-triangle", "triangle.off", off(tri, [[0, 1, 2]]), 422, "too_few_vertices")
    add("single-triangle-stl", "triangle.stl", stl_binary(tri, [[0, 1, 2]]), 422,
        "too_few_vertices")  # fmt: skip
    # Points without faces that make no surface from anywhere: on one line (a blob of them
    # is read as the view along its largest silhouette, as a whole object's points are).
    points = np.outer(np.random.default_rng(seed).normal(size=500), [1.0, 2.0, 3.0])
    ply_points = (
        "ply\nformat ascii 1.0\nelement vertex 500\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n" + "".join(f"{x} {y} {z}\n" for x, y, z in points)
    ).encode()
    add("point-cloud-ply", "cloud.ply", ply_points, 422, ("no_faces", "empty_mesh"))
    add("point-cloud-off", "cloud.off", off(points, np.empty((0, 3))), 422,
        ("no_faces", "empty_mesh"))  # fmt: skip
    add("point-cloud-obj", "cloud.obj",
        "".join(f"v {x} {y} {z}\n" for x, y, z in points).encode(), 422,
        ("no_faces", "empty_mesh"))  # fmt: skip
    # Points as text: on one line (no surface), not numbers, not text at all.
    add("point-cloud-xyz", "cloud.xyz", "".join(f"{x} {y} {z}\n" for x, y, z in points).encode(),
        422, "no_faces")  # fmt: skip
    add("points-not-numbers-csv", "cloud.csv", b"x,y,z\n1,2,3\n4,five,6\n", 422, UNREADABLE)
    add("points-binary-xyz", "cloud.xyz", bytes(range(256)) * 8, 422, UNREADABLE)
    add("points-far-view-pts", "far.pts", b"3\n0 0 1e300\n1 0 1e300\n0 1 1e300\n", 422,
        UNREADABLE + ("non_finite_coordinates",))  # fmt: skip
    same = np.ones_like(sphere_v) * 3.0
    add("identical-vertices", "collapsed.off", off(same, sphere_f), 422, "too_few_vertices")
    flat = sphere_v.copy()
    flat[:, 2] = 0.0
    flat[:, 1] = 0.0
    add("collinear-vertices", "line.obj", obj(flat, sphere_f), 422, "too_few_vertices")
    # A non-manifold fan: 40 triangles sharing one edge, like pages of a book.
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    ring = np.c_[np.cos(angles), np.sin(angles), np.full(40, 0.5)]
    fan_v = np.vstack([[0, 0, 0], [0, 0, 1], ring])
    fan_f = np.array([[0, 1, i + 2] for i in range(40)])
    add("non-manifold-fan", "fan.off", off(fan_v, fan_f), 422, "non_manifold")
    # Thousands of disconnected specks: the largest component is one tiny triangle.
    n = 3000
    centres = np.random.default_rng(seed).uniform(-100, 100, size=(n, 3))
    speck_v = (centres[:, None, :] + tri[None] * 0.01).reshape(-1, 3)
    speck_f = np.arange(3 * n).reshape(n, 3)
    add("specks", "specks.obj", obj(speck_v, speck_f), 422, "too_few_vertices")
    add("specks-stl", "specks.stl", stl_binary(speck_v, speck_f), 422, "too_few_vertices")

    # Over the limits.
    subdivisions = int(np.floor(np.log(max_faces / 20) / np.log(4))) + 1  # 20 * 4**s faces
    big_v, big_f = icosphere(subdivisions)
    assert len(big_f) > max_faces
    add("over-face-limit", "dense.off", off(big_v, big_f), 413, "too_many_faces")
    add("over-face-limit-gz", "dense.ply.gz", gzip.compress(ply_ascii(big_v, big_f)), 413,
        "too_many_faces")  # fmt: skip
    # A gzip bomb: 1 GiB of zeros in about 1 MB would pass the upload limit; this one
    # expands past the 512 MB decompression limit from ~600 kB.
    add("gzip-bomb", "bomb.obj.gz", gzip_bomb(600 * 1024 * 1024), 413, "file_too_large")
    return cases


def gzip_bomb(expanded_bytes: int) -> bytes:
    """Gzip of ``expanded_bytes`` zero bytes, compressed in pieces (never held expanded)."""
    buf = io.BytesIO()
    block = bytes(16 * 1024 * 1024)
    with gzip.GzipFile(fileobj=buf, mode="wb", compresslevel=9) as gz:
        left = expanded_bytes
        while left > 0:
            gz.write(block[: min(left, len(block))])
            left -= len(block)
    return buf.getvalue()


def write_corpus(directory: Path, max_faces: int) -> list[Path]:
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for case in build_corpus(max_faces):
        path = directory / f"{case.name}--{case.filename}"
        path.write_bytes(case.data)
        paths.append(path)
    return paths


if __name__ == "__main__":
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "hostile-corpus")
    written = write_corpus(out, int(sys.argv[2]) if len(sys.argv) > 2 else 5000)
    print(f"{len(written)} files in {out}")
