"""What a surface of slivers costs to describe, side by side with the resampling's
earlier ways with it.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.sliver_cost [--repeat 3]

Quadric decimation cannot thin a surface made of slivers (:mod:`worker.engine.resample`).
Each file is described ``--repeat`` times, each in a fresh process, three ways:

* ``engine``: as the engine does it;
* ``tried``: the decimation tried even when its needles say it would stall
  (``needle_vertices`` read as 0), the reference the engine's result must equal;
* ``one cube``: the clustering only in cubes of one tiling edge (``CLUSTER_CELLS``
  ``(1.0,)``, the resampling of v19), the stalled decimation standing when they lose area.

The files: trimesh's thin torus (radii 1 and 0.016, its ring as thick as about two tiling
edges) faceted with 1,024 sides round its ring and 24 along it (24,576 vertices), its
cylinder of 2,048 strips, and, when the TOSCA set is found
(``SHAPES_DATASETS_DIR``, else ``../shared/datasets``), victoria12's frame as the
partiality protocol's ``floor-voxels`` shoots and voxel filters it, its points written where
no sensor is placed, so read from afar with their floor (222,980 points of a floor and a
body, nearly all the corners of slivers). ``--files`` picks some of them. Prints the
described vertex count, the median seconds of the whole description and of its resample
stage, and the largest peak RSS.
"""

from __future__ import annotations

import argparse
import json
import statistics

from benchmarks.common import fresh_process_runs, timed_description
from worker.engine.mesh_io import Mesh
from worker.engine.presets import DEFAULT_PRESET
from worker.evaluation.datasets import shared_dataset

FILES = (
    "thin torus, 1,024 sides",
    "cylinder 1:2, 2,048 sides",
    "victoria12 floor frame, from afar",
)
FILE_KEYS = ("torus", "cylinder", "victoria12")
SETTINGS = ("engine", "tried", "one cube")


def _mesh(label: str) -> Mesh:
    import trimesh

    from worker.engine.mesh_io import clean_mesh, load_mesh

    if label.startswith("thin torus"):
        shape = trimesh.creation.torus(1.0, 0.016, major_sections=24, minor_sections=1024)
        return clean_mesh(shape.vertices, shape.faces)
    if label.startswith("cylinder"):
        shape = trimesh.creation.cylinder(0.5, 2.0, sections=2048)
        return clean_mesh(shape.vertices, shape.faces)
    import numpy as np

    from worker.engine.scans import one_view
    from worker.evaluation.partial import DRAWN_AS, floor_voxel_points
    from worker.evaluation.variants import variant_seed

    name = "victoria12.off.gz"
    rng = np.random.default_rng(variant_seed(name, DRAWN_AS["floor-voxels"]))
    points, _ = floor_voxel_points(load_mesh(shared_dataset("tosca") / name), rng)
    vertices, faces, _ = one_view(points, np.zeros(3))  # no sensor placed: from afar
    return clean_mesh(vertices, faces)


def _measure(preset_name: str, label: str, setting: str) -> dict[str, float]:
    from worker.engine import resample
    from worker.engine.presets import get_preset

    if setting == "tried":
        resample.needle_vertices = lambda vertices, faces: 0
    elif setting == "one cube":
        resample.CLUSTER_CELLS = (1.0,)
    return timed_description(_mesh(label), get_preset(preset_name))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default=DEFAULT_PRESET)
    parser.add_argument("--repeat", type=int, default=3, help="runs per file and setting")
    parser.add_argument(
        "--files", nargs="+", choices=FILE_KEYS, default=FILE_KEYS, help="which files (all)"
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--setting", choices=SETTINGS, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(_measure(args.preset, args.child, args.setting)))
        return
    files = [f for f, key in zip(FILES, FILE_KEYS, strict=True) if key in args.files]
    files = [f for f in files if not f.startswith("victoria") or shared_dataset("tosca").is_dir()]
    print(f"preset {args.preset}, median of {args.repeat} runs per file and setting\n")
    print("| file | resampling | vertices | seconds | of which resample | peak RSS MB |")
    print("|---|---|---:|---:|---:|---:|")
    for label in files:
        for setting in SETTINGS:
            arguments = ["--preset", args.preset, "--child", label, "--setting", setting]
            runs = fresh_process_runs("benchmarks.sliver_cost", arguments, args.repeat)
            print(
                f"| {label} | {setting} | {statistics.median(r['vertices'] for r in runs):,.0f} "
                f"| {statistics.median(r['seconds'] for r in runs):.2f} "
                f"| {statistics.median(r['resample'] for r in runs):.2f} "
                f"| {max(r['peak_rss_mb'] for r in runs):,.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
