"""What the resample's edge bound costs on CAD-style cylinders, side by side.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.cad_cost [--preset smeets2010-surface]

Each file (trimesh's cylinders: few long strips, two fans whose centres have one
neighbour per side, or thousands of slivers) is described ``--repeat`` times, each in a
fresh process, with the preset as it is and with ``max_edge=None`` (the decimated mesh
as it is, the default before v8), so the peak resident memory is that file's. Prints
the vertex count, the median seconds of the whole description and of its GDM stage,
and the largest peak RSS.
"""

from __future__ import annotations

import argparse
import json
import statistics
from dataclasses import replace

from benchmarks.common import fresh_process_runs, timed_description
from worker.engine.presets import DEFAULT_PRESET

#: label -> (radius, height, sections) of trimesh.creation.cylinder
CYLINDERS = {
    "cylinder 1:2, 96 sides": (0.5, 2.0, 96),
    "cylinder 1:20, 64 sides": (0.5, 20.0, 64),
    "cylinder 1:2, 512 sides": (0.5, 2.0, 512),
    "cylinder 1:2, 2,048 sides": (0.5, 2.0, 2048),
}


def _measure(preset_name: str, label: str, bounded: bool) -> dict[str, float]:
    import trimesh

    from worker.engine.mesh_io import clean_mesh
    from worker.engine.presets import get_preset

    preset = get_preset(preset_name)
    if not bounded:
        preset = replace(preset, max_edge=None)
    radius, height, sections = CYLINDERS[label]
    shape = trimesh.creation.cylinder(radius, height, sections=sections)
    return timed_description(clean_mesh(shape.vertices, shape.faces), preset)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default=DEFAULT_PRESET)
    parser.add_argument("--repeat", type=int, default=3, help="runs per file and setting")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--unbounded", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(_measure(args.preset, args.child, not args.unbounded)))
        return
    print(f"preset {args.preset}, median of {args.repeat} runs per file and setting\n")
    print("| file | edge bound | vertices | seconds | of which GDM | peak RSS MB |")
    print("|---|---|---:|---:|---:|---:|")
    for label in CYLINDERS:
        for bounded in (False, True):
            arguments = ["--preset", args.preset, "--child", label]
            if not bounded:
                arguments.append("--unbounded")
            runs = fresh_process_runs("benchmarks.cad_cost", arguments, args.repeat)
            seconds = statistics.median(r["seconds"] for r in runs)
            gdm = statistics.median(r["gdm"] for r in runs)
            rss = max(r["peak_rss_mb"] for r in runs)
            print(
                f"| {label} | {'preset' if bounded else 'none'} | {runs[0]['vertices']:,} | "
                f"{seconds:.2f} | {gdm:.2f} | {rss:,.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
