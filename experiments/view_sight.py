"""Where a view written in its object's frame is seen from: the sight it starts from.

    OPENBLAS_NUM_THREADS=1 python -m experiments.view_sight [--every 1]

A view's points written in the scanned object's frame, no sensor placed, are read on
their scanner's lattice in a frame found from their steps
(:func:`worker.engine.scans.sensor_axes`, its rounds started from a guess of the line of
sight), or, on no lattice, seen from afar along that guess
(:func:`worker.engine.scans.one_view`). For every TOSCA and SCAPE file (every
``--every``-th), one range scan (SHREC'17's orbiting camera,
:func:`worker.evaluation.partial.range_image`, seeded by the file's number, SCAPE's up
axis the protocol's), its points shuffled and written as float32, and the same scan
thinned by a voxel filter of two pixels (on no lattice). Per guess, the direction the
points overlap themselves least in (:func:`~worker.engine.scans.unfolded_sight`) and
their least principal axis (:func:`~worker.engine.scans.least_spread`, the guess before
2026-12-05, here with the current rounds): its angle to the scanner's line of sight
(median, 90%, largest), the scans read on their lattice and refused, the median
milliseconds reading one, and the voxel views refused and the median share of their
points on a triangle.
"""

from __future__ import annotations

import argparse
import statistics
import time
from unittest import mock

import numpy as np

from benchmarks.common import SCAPE, SCAPE_UP, TOSCA
from worker.engine import scans
from worker.engine.errors import PointCloudError
from worker.engine.mesh_io import load_mesh
from worker.evaluation.partial import range_image, voxel_means

GUESSES = {"unfolded_sight": scans.unfolded_sight, "least_spread": scans.least_spread}


def degrees_off(guess: np.ndarray, sight: np.ndarray) -> float:
    return float(np.degrees(np.arccos(min(1.0, abs(float(guess @ sight))))))


def on_lattice(points: np.ndarray) -> bool:
    """Whether a frame found from ``points``' steps holds them on their pixel lattice."""
    return any(
        scans.sensor_grid(points, np.zeros(3), frame, along=(2,)) is not None
        for frame, _, _ in scans.sensor_axes(points, np.zeros(3))
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=int, default=1)
    args = parser.parse_args()
    files = [(p, "z") for p in sorted(TOSCA.glob("*.off.gz"))]
    files += [(p, SCAPE_UP) for p in sorted(SCAPE.glob("*.off.gz"))]
    views = []
    for number, (path, up) in enumerate(files[:: args.every]):
        grid, sight, pitch = range_image(load_mesh(path), np.random.default_rng(number), up)
        seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()]
        seen = seen[np.random.default_rng(0).permutation(len(seen))]
        written = seen.astype(np.float32).astype(np.float64)
        views.append((written, voxel_means(seen, 2 * pitch), sight))
    print(f"{len(views)} range scans in their mesh's frame, one a file\n")
    print(
        "| guess | off the sight: median | 90% | largest | on their lattice | refused | "
        "ms to read | voxel views refused | their points on a triangle |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, guess in GUESSES.items():
        off, lattice, refused, seconds, voxels_refused, on = [], 0, 0, [], 0, []
        with mock.patch.object(scans, "unfolded_sight", guess):
            for points, means, sight in views:
                off.append(degrees_off(guess(points), sight))
                lattice += on_lattice(points)
                start = time.perf_counter()
                try:
                    scans.one_view(points, np.zeros(3))
                except PointCloudError:
                    refused += 1
                seconds.append(time.perf_counter() - start)
                try:
                    _, faces, _ = scans.one_view(means, np.zeros(3))
                    on.append(np.unique(faces).size / len(means))
                except PointCloudError:
                    voxels_refused += 1
        print(
            f"| {name} | {np.median(off):.1f} | {np.percentile(off, 90):.1f} | {max(off):.1f} | "
            f"{lattice} | {refused} | {1000 * statistics.median(seconds):.0f} | "
            f"{voxels_refused} | {np.median(on) if on else float('nan'):.3f} |"
        )


if __name__ == "__main__":
    main()
