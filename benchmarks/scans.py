"""A scan as a scanner's file against the same surface as a mesh: describe seconds, or
query seconds through the service.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.scans [--pixels 1500 30000]
        [--subdivisions 0 2] [--repeats 5] [--service]

For each size, the walk-through's quadruped-3 seen from its left side by an orthographic
depth grid of about ``--pixels`` pixels on it (as ``examples/partial/quadruped-3-depth``
was made), written as an organized PCD (ascii, binary), as a structured E57 scan, as its
points without the grid (in another order, in the camera's frame: an XYZ text file and a
binary PLY of vertices; the PLY's points also turned about the camera, so that they lie
on no pixel lattice in their own frame, turned in the mesh's frame, the camera elsewhere,
and turned with each point moved at random, a tenth of a pixel (near its lattice) or half
a pixel (near none)), and
its surface (what :func:`~worker.engine.scans.read_pcd` makes of the binary file) as an
OFF mesh: a mesh of the same size. Beside them, the quadruped on a floor seen from 35
degrees above at the same pitch (as ``examples/partial/quadruped-3-floor`` was made) as a
binary PCD, and as its points without the grid in the camera's frame (a binary PLY; also
each point moved half a pixel, on no lattice), the floor left out as it is read, against
that surface as an OFF mesh. A cloud moved off its lattice reads to a rougher surface
than the mesh's, so that surface as read, written as an OFF mesh (``mesh.off of`` the
cloud), is timed too, and the last column gives the cloud over it: its reading's cost
alone. Each file is described by
:func:`~worker.engine.pipeline.describe_file` ``--repeats`` times, the files' order
alternated, in one process; the table gives the median load (read, triangulate, clean)
and total seconds, and each total over the mesh's of its surface. With ``--service``, each
file is instead the query of ``POST /query`` (``k`` 1) of the service as a user runs it
(``python -m app`` on a fresh data directory, the 15 examples ``examples/*-[012]``
enrolled with their labels; no recent query's descriptor kept, so that every query is
described afresh), one request at a time: the median seconds of the round trip (upload,
read, describe, search, a view's verification, the answer), each over the mesh's, and
the class the first answer is. After the scans, the quadruped-3 whole as a scanner's
merged cloud (its vertices in another order and frame, an XYZ text file, read as the view
that sees most of them, :func:`~worker.engine.scans.whole_view`) against its mesh, at its
own 2,500 vertices and with each triangle split in four ``--subdivisions`` times (Loop),
and against the mesh of the surface it is read as (``mesh.off of`` the cloud).
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import time
from contextlib import ExitStack
from typing import cast

import httpx
import numpy as np
import trimesh

from app.client import import_files, read_labels
from benchmarks.common import EXAMPLES, TIMEOUT, free_port, serving
from worker.engine.mesh_io import load_mesh
from worker.engine.pipeline import describe_file
from worker.engine.presets import DEFAULT_PRESET, get_preset
from worker.engine.scans import read_pcd, view_frame
from worker.evaluation.partial import random_rotation
from worker.evaluation.samples import (
    DEPTH_DIRECTION,
    FLOOR_ELEVATION,
    PARTIAL_SOURCE,
    depth_scan,
    e57_bytes,
    floor_scan,
    pcd_bytes,
    sample_mesh,
    seen_from_left,
)
from worker.evaluation.variants import subdivided


def points_ply(points: np.ndarray) -> bytes:
    """``points`` (n, 3) as a binary PLY of vertices alone, as scanners' tools write it."""
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(points)}\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n"
    )
    return header.encode() + points.astype("<f4").tobytes()


#: The floor scan's files: their names end so, and they are timed against its mesh.
ON_A_FLOOR = "(on a floor)"
#: The whole's files: their names end so, and they are timed against its mesh.
WHOLE = "(whole)"
#: A cloud moved off its lattice reads to a surface of its own, rougher than the mesh's:
#: that surface as an OFF mesh is named so before the cloud's name, and the cloud is
#: timed against it too (its reading's cost alone).
OF_ITS_SURFACE = "mesh.off of"
#: The last column's title.
OWN = "/ its surface's mesh"


def off_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A surface as an OFF file."""
    return cast(
        str, trimesh.Trimesh(vertices, faces, process=False).export(file_type="off")
    ).encode()


def scan_files(pixels: int) -> tuple[dict[str, bytes], str, str]:
    """The scan's files by name (the meshes first), and the scan and the floor scan as
    the table names them (their points and grids)."""
    whole = sample_mesh(*PARTIAL_SOURCE)
    points, viewpoint = depth_scan(whole, np.array(DEPTH_DIRECTION), pixels)
    binary = pcd_bytes(points, viewpoint, "binary")
    vertices, faces, cloud = read_pcd(binary)
    assert cloud.grid is not None
    seen = (vertices - viewpoint)[np.random.default_rng(0).permutation(len(vertices))]
    turn = random_rotation(np.random.default_rng(1))  # out of the camera's frame
    pitch = float(np.nanmedian(np.linalg.norm(np.diff(points, axis=1), axis=2)))
    noise = np.random.default_rng(2).normal(scale=pitch / np.sqrt(3), size=seen.shape)
    floor_grid, floor_viewpoint = floor_scan(whole, pitch)
    on_floor = pcd_bytes(floor_grid, floor_viewpoint, "binary")
    floor_vertices, floor_faces, floor = read_pcd(on_floor)
    assert floor.grid is not None
    floor_seen = floor_grid[np.isfinite(floor_grid).all(axis=2)] - floor_viewpoint
    floor_seen = floor_seen[np.random.default_rng(0).permutation(len(floor_seen))]
    # As the camera's software writes them: in its frame (floor_scan's, rows along x),
    # looking along +z (view_frame's z points back at the camera).
    camera = view_frame(seen_from_left(FLOOR_ELEVATION)) * np.array([[1.0], [-1.0], [-1.0]])
    floor_camera = floor_seen @ camera.T
    floor_noise = np.random.default_rng(2).normal(scale=pitch / np.sqrt(3), size=floor_seen.shape)
    files = {
        "mesh.off": off_bytes(vertices, faces),
        f"mesh.off {ON_A_FLOOR}": off_bytes(floor_vertices, floor_faces),
        "scan.pcd (ascii)": pcd_bytes(points, viewpoint),
        "scan.pcd (binary)": binary,
        "scan.e57": e57_bytes(points, viewpoint),
        "scan.xyz (no grid)": xyz_bytes(seen),
        "scan.ply (no grid)": points_ply(seen),
        "scan.ply (no grid, turned)": points_ply(seen @ turn.T),
        "scan.ply (no grid, mesh's frame)": points_ply((seen + viewpoint) @ turn.T),
        "scan.ply (no grid, turned, moved 0.1 pixel)": points_ply((seen + 0.1 * noise) @ turn.T),
        "scan.ply (no grid, turned, moved 0.5 pixel)": points_ply((seen + 0.5 * noise) @ turn.T),
        f"scan.pcd (binary) {ON_A_FLOOR}": on_floor,
        f"scan.ply (no grid) {ON_A_FLOOR}": points_ply(floor_camera),
        f"scan.ply (no grid, moved 0.5 pixel) {ON_A_FLOOR}": points_ply(
            floor_camera + 0.5 * floor_noise
        ),
    }
    with_surfaces = {}
    for name, data in files.items():
        with_surfaces[name] = data
        if "moved" in name:  # the mesh of its surface right after it
            surface = load_mesh(data, name.split(" ")[0])
            with_surfaces[f"{OF_ITS_SURFACE} {name}"] = off_bytes(surface.vertices, surface.faces)
    scan = f"{cloud.points:,} points, {cloud.grid[0]} x {cloud.grid[1]}"
    floor_label = (
        f"{floor.points:,} points and {floor.support:,} of the floor, "
        f"{floor.grid[0]} x {floor.grid[1]}"
    )
    return with_surfaces, scan, floor_label


def xyz_bytes(points: np.ndarray) -> bytes:
    """``points`` (n, 3) as an XYZ text file, each coordinate as Python writes it."""
    return "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in points.tolist()).encode()


def whole_files(subdivisions: int) -> tuple[dict[str, bytes], str]:
    """The quadruped-3 whole's mesh, each triangle split in four ``subdivisions`` times
    (Loop), its vertices in another order and frame as an XYZ file, and the surface that
    file is read as (the view that sees most of it) as a mesh, by name; and the whole as
    the table names it."""
    whole = sample_mesh(*PARTIAL_SOURCE)
    for _ in range(subdivisions):
        whole = subdivided(whole)
    vertices, faces = whole.vertices, whole.faces
    rng = np.random.default_rng(0)
    moved = vertices[rng.permutation(len(vertices))] @ random_rotation(rng).T
    points = xyz_bytes(moved + np.ptp(vertices))
    surface = load_mesh(points, "points.xyz")  # one side of it, as the service reads it
    files = {
        f"mesh.off {WHOLE}": off_bytes(vertices, faces),
        f"points.xyz {WHOLE}": points,
        f"{OF_ITS_SURFACE} points.xyz {WHOLE}": off_bytes(surface.vertices, surface.faces),
    }
    return files, f"a whole, {len(vertices):,} points"


def described(files: dict[str, bytes], repeats: int) -> dict[str, tuple[list[float], str]]:
    """Each file's describe seconds (``repeats``, the files' order alternated) and its
    median load milliseconds."""
    preset = get_preset(DEFAULT_PRESET)
    load: dict[str, list[float]] = {name: [] for name in files}
    total: dict[str, list[float]] = {name: [] for name in files}
    for repeat in range(repeats):
        for name in list(files) if repeat % 2 == 0 else list(files)[::-1]:
            start = time.perf_counter()
            descriptor = describe_file(files[name], preset, name.split(" ")[0])
            total[name].append(time.perf_counter() - start)
            load[name].append(descriptor.timings["load"])
    return {name: (total[name], f"{1000 * statistics.median(load[name]):.1f}") for name in files}


def queried(
    client: httpx.Client, files: dict[str, bytes], repeats: int
) -> dict[str, tuple[list[float], str]]:
    """Each file's ``POST /query`` seconds (``repeats``, the files' order alternated, after
    a round not timed: the service's query processes load what each format needs once)
    and the class of its first answer."""
    seconds: dict[str, list[float]] = {name: [] for name in files}
    first: dict[str, str] = {}
    for repeat in range(-1, repeats):
        for name in list(files) if repeat % 2 == 0 else list(files)[::-1]:
            start = time.perf_counter()
            response = client.post(
                "/query", files={"file": (name.split(" ")[0], files[name])}, data={"k": "1"}
            )
            if repeat >= 0:
                seconds[name].append(time.perf_counter() - start)
            if response.status_code != 200:
                raise SystemExit(f"{name}: HTTP {response.status_code} {response.text[:300]}")
            answer = response.json()
            assert answer["descriptor_source"] == "computed", "a query answered from a cache"
            matches = answer["matches"]
            first[name] = matches[0]["label"] if matches else "-"
    return {name: (seconds[name], first[name]) for name in files}


def print_table(timed: dict[str, tuple[list[float], str]], labels: dict[str, str]) -> None:
    """One row a file: the label of its group (``labels``: the suffix its name ends with,
    the scan's ``""``, -> the label), its column, its median seconds, those over its
    group's mesh's, and a moved cloud's over the mesh of its own surface."""
    for name, (seconds, column) in timed.items():
        group = next(end for end in sorted(labels, key=len, reverse=True) if name.endswith(end))
        mesh = f"mesh.off {group}".rstrip()
        median = statistics.median(seconds)
        own = timed.get(f"{OF_ITS_SURFACE} {name}")
        over_own = "" if own is None else f"{median / statistics.median(own[0]):.2f}"
        print(
            f"| {labels[group]} | {name.removesuffix(f' {group}')} | "
            f"{column} | {median:.3f} | {median / statistics.median(timed[mesh][0]):.2f} | "
            f"{over_own} |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, nargs="*", default=[1500, 30000])
    parser.add_argument("--subdivisions", type=int, nargs="*", default=[0, 2])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--service", action="store_true", help="time POST /query through a fresh service"
    )
    args = parser.parse_args()
    with ExitStack() as stack:
        client = None
        if args.service:
            # Every query described afresh, as a file the service has not seen is.
            os.environ["SHAPES_QUERY_CACHE_SIZE"] = "0"
            url = stack.enter_context(serving(free_port()))
            client = stack.enter_context(httpx.Client(base_url=url, timeout=TIMEOUT))
            examples = sorted(EXAMPLES.glob("*-[012].off.gz"))
            labels = read_labels(EXAMPLES / "labels.csv")
            done = import_files(examples, url=url, labels=labels, wait=True, stream=io.StringIO())
            if done.failed:
                raise SystemExit(f"enrollment failed: {done.failed}")
            print(f"{len(examples)} examples enrolled; medians of {args.repeats} queries each")
            print(f"\n| scan | file | first answer | query s | query / mesh's | {OWN} |")
        else:
            print(f"{DEFAULT_PRESET}; medians of {args.repeats} describes, files alternated")
            print(f"\n| scan | file | load ms | total s | total / mesh's | {OWN} |")
        print(f"|---|---|{'---' if client else '---:'}|---:|---:|---:|")
        groups = []
        for pixels in args.pixels:
            files, scan, floor_label = scan_files(pixels)
            groups.append((files, {"": scan, ON_A_FLOOR: floor_label}))
        for subdivisions in args.subdivisions:
            files, label = whole_files(subdivisions)
            groups.append((files, {WHOLE: label}))
        for files, labels in groups:
            timed = (
                described(files, args.repeats)
                if client is None
                else queried(client, files, args.repeats)
            )
            print_table(timed, labels)


if __name__ == "__main__":
    main()
