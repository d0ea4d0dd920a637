"""Descriptor engine benchmark: median seconds per stage and peak memory, vs ShapeDNA.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.descriptor [--preset smeets2010-surface]
        [--sizes 1000 2500 5000] [--repeats 2]

For each size N, a fresh process describes one TOSCA mesh of every class with the
preset resampled to N, through ``describe_file`` (its own stage timings: load,
resample, gdm, eigen_ddt, modal, parts, surface), and, on the very same resampled mesh in
the same process, lapy's ShapeDNA (k=50), so the ratio is measured side by side. Peak
memory is the process's maximum resident set size after describing (imports
included; the line "after imports" is the process before its first mesh).
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from dataclasses import replace

from worker.engine.presets import DEFAULT_PRESET
from worker.evaluation.datasets import shared_dataset

# Not benchmarks.common's: a child's memory is measured after its imports, which stay
# the engine's and lapy's.
TOSCA = shared_dataset("tosca")
#: One mesh of each TOSCA class (4,344 to 52,565 vertices).
MESHES = (
    "cat0.off.gz",
    "centaur0.off.gz",
    "david0.off.gz",
    "dog0.off.gz",
    "gorilla1.off.gz",
    "horse0.off.gz",
    "michael0.off.gz",
    "victoria0.off.gz",
    "wolf0.off.gz",
)
STAGES = ("load", "resample", "gdm", "eigen_ddt", "modal", "parts", "surface")
#: The stages after the resample, whose sum is the descriptor's time.
DESCRIBING = ("gdm", "eigen_ddt", "modal", "parts", "surface")


def _measure(preset_name: str, n: int, repeats: int) -> dict[str, float]:
    import numpy as np
    from lapy import TriaMesh
    from lapy.shapedna import compute_shapedna

    from worker.engine.mesh_io import load_mesh
    from worker.engine.pipeline import describe_file, resampled_surface
    from worker.engine.presets import get_preset

    preset = replace(get_preset(preset_name), n_vertices=n)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    samples: dict[str, list[float]] = {}
    vertex_counts = []
    for name in MESHES:
        for _ in range(repeats):
            descriptor = describe_file(TOSCA / name, preset)
            surface = resampled_surface(load_mesh(TOSCA / name), preset)
            start = time.perf_counter()
            compute_shapedna(TriaMesh(surface.vertices, surface.faces), k=50)
            shapedna = time.perf_counter() - start
            t = descriptor.timings
            for stage in STAGES:  # a preset without the parts modality has no such stage
                samples.setdefault(stage, []).append(t.get(stage, 0.0))
            samples.setdefault("descriptor", []).append(sum(t.get(s, 0.0) for s in DESCRIBING))
            samples.setdefault("shapedna", []).append(shapedna)
            vertex_counts.append(descriptor.vertices)
    ratios = [d / s for d, s in zip(samples["descriptor"], samples["shapedna"], strict=True)]
    return {
        "n": n,
        "vertices": int(np.median(vertex_counts)),
        **{stage: statistics.median(v) for stage, v in samples.items()},
        "ratio": statistics.median(ratios),
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "rss_before_mb": rss_before / 1024,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default=DEFAULT_PRESET)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 2500, 5000])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(_measure(args.preset, args.child, args.repeats)))
        return
    rows = []
    for n in args.sizes:
        out = subprocess.run(
            [
                sys.executable,
                "-m",
                "benchmarks.descriptor",
                "--preset",
                args.preset,
                "--child",
                str(n),
                "--repeats",
                str(args.repeats),
            ],
            check=True,
            capture_output=True,
            text=True,
        )
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    print(
        f"preset {args.preset}; {len(MESHES)} TOSCA meshes (one per class), "
        f"{args.repeats} repeats each; medians in seconds\n"
    )
    print(
        "| N | load | resample | GDM | eigen+DDT | modal | parts | surface | descriptor "
        "(GDM+eigen+modal+parts+surface) | ShapeDNA (lapy) | ratio | peak RSS MB (after imports) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['vertices']} | {r['load']:.3f} | {r['resample']:.3f} | {r['gdm']:.3f} | "
            f"{r['eigen_ddt']:.3f} | {r['modal']:.3f} | {r['parts']:.3f} | {r['surface']:.3f} | "
            f"{r['descriptor']:.3f} | "
            f"{r['shapedna']:.3f} | {r['ratio']:.2f}x | "
            f"{r['peak_rss_mb']:.0f} ({r['rss_before_mb']:.0f}) |"
        )


if __name__ == "__main__":
    main()
