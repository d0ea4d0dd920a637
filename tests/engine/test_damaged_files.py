"""Damaged copies of every kind of file the service reads: each is read or refused with a
sentence (a :class:`~worker.engine.errors.MeshError`), never an error of another kind
(which the service could only answer as its own failure)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
import trimesh

from worker.engine.errors import MeshError
from worker.engine.mesh_io import read_mesh
from worker.evaluation.samples import (
    DEPTH_DIRECTION,
    PARTIAL_SOURCE,
    depth_scan,
    e57_bytes,
    pcd_bytes,
    sample_mesh,
)

#: How many damaged copies of each file are read (seeded: the same copies every run).
COPIES = 100
#: Words a damaged header may hold instead of its own.
WORDS = (b"nan", b"inf", b"-1", b"0", b"99999999999", b"1e308", b"binary", b"ascii", b"F", b"\n")


@cache
def intact_files() -> dict[str, bytes]:
    """The walk-through's quadruped seen by a depth camera (about 600 pixels) as every
    point-cloud format, its points in the camera's frame, and its mesh as every mesh
    format with faces."""
    source = sample_mesh(*PARTIAL_SOURCE)
    grid, viewpoint = depth_scan(source, np.array(DEPTH_DIRECTION), 600)
    points = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()] - viewpoint
    rows = [" ".join(f"{c!r}" for c in row) for row in points.tolist()]
    mesh = trimesh.Trimesh(source.vertices, source.faces, process=False)
    return {
        "scan.pcd": pcd_bytes(grid, viewpoint),
        "binary.pcd": pcd_bytes(grid, viewpoint, "binary"),
        "scan.e57": e57_bytes(grid, viewpoint),
        "points.ply": trimesh.PointCloud(points).export(file_type="ply"),
        "points.xyz": "".join(f"{row}\n" for row in rows).encode(),
        "points.csv": ("x,y,z\n" + "".join(f"{row.replace(' ', ',')}\n" for row in rows)).encode(),
        "points.pts": (f"{len(rows)}\n" + "".join(f"{row} 10 1 2 3\n" for row in rows)).encode(),
        "mesh.off": mesh.export(file_type="off").encode(),
        "mesh.ply": mesh.export(file_type="ply"),
        "mesh.obj": mesh.export(file_type="obj").encode(),
        "mesh.stl": mesh.export(file_type="stl"),
    }


def damaged(data: bytes, rng: np.random.Generator) -> bytes:
    """``data`` with one kind of damage: bytes overwritten, cut short, a stretch cut out,
    random bytes slipped in, a digit of the header changed, or a header word replaced."""
    out, size = bytearray(data), len(data)
    kind = rng.integers(6)
    if kind == 0:
        for at in rng.integers(size, size=rng.integers(1, 20)):
            out[at] = rng.integers(256)
    elif kind == 1:
        del out[rng.integers(size) :]
    elif kind == 2:
        at = rng.integers(size)
        del out[at : at + rng.integers(1, 200)]
    elif kind == 3:
        at = rng.integers(size)
        out[at:at] = rng.bytes(rng.integers(1, 50))
    elif kind == 4:
        digits = [at for at, byte in enumerate(data[:600]) if 48 <= byte <= 57]
        for at in rng.choice(digits, size=rng.integers(1, 4)):
            out[at] = ord(str(rng.integers(10)))
    else:
        at = rng.integers(min(size, 600))
        out[at : at + rng.integers(1, 6)] = WORDS[rng.integers(len(WORDS))]
    return bytes(out)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name",
    ["scan.pcd", "binary.pcd", "scan.e57", "points.ply", "points.xyz", "points.csv", "points.pts"]
    + ["mesh.off", "mesh.ply", "mesh.obj", "mesh.stl"],
)
def test_a_damaged_file_is_read_or_refused_with_a_sentence(name):
    data = intact_files()[name]
    read_mesh(data, name)  # intact, it is read
    rng = np.random.default_rng(sorted(intact_files()).index(name))
    for _ in range(COPIES):
        try:
            read_mesh(damaged(data, rng), name)
        except MeshError as refusal:
            assert refusal.message.endswith(".")
