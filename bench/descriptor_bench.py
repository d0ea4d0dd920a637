"""Descriptor engine benchmark: median seconds per stage and peak memory, vs ShapeDNA.

    python bench/descriptor_bench.py [--sizes 1000 2500 5000] [--repeats 3]

For each size N, a fresh process describes a few TOSCA meshes resampled to N
(stages: load+resample, GDM, eigenproblem+DDT, modal) and, on the very same
resampled meshes in the same process, lapy's ShapeDNA (k=50), so the ratio is
measured side by side. Peak memory is the process's maximum resident set size.
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

from worker.evaluation.datasets import shared_dataset

TOSCA = shared_dataset("tosca")
MESHES = ("michael0.off.gz", "cat0.off.gz", "horse0.off.gz")


def _measure(n: int, repeats: int) -> dict:
    import numpy as np
    from lapy import TriaMesh
    from lapy.shapedna import compute_shapedna

    from worker.engine.diffusion import (
        LaplaceBeltrami,
        laplace_beltrami_eigenpairs,
        normalized_spectrum,
    )
    from worker.engine.geodesic import geodesic_distance_matrix
    from worker.engine.intrinsic import IntrinsicMesh, fem_operators, intrinsic_delaunay
    from worker.engine.mesh_io import load_mesh
    from worker.engine.modal import ddt_core, modal_gdm
    from worker.engine.presets import get_preset
    from worker.engine.resample import resample_mesh

    preset = replace(get_preset("smeets2010-shrec"), n_vertices=n)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    samples: dict[str, list[float]] = {}
    vertex_counts = []
    for name in MESHES:
        for _ in range(repeats):
            t0 = time.perf_counter()
            mesh = resample_mesh(load_mesh(TOSCA / name), n)
            t1 = time.perf_counter()
            intrinsic = intrinsic_delaunay(IntrinsicMesh.from_mesh(mesh.vertices, mesh.faces))
            ops = fem_operators(intrinsic)
            gdm = geodesic_distance_matrix(intrinsic, ops, preset.heat_time_factor)
            t2 = time.perf_counter()
            op = LaplaceBeltrami.from_fem(ops)
            values, vectors = laplace_beltrami_eigenpairs(op, preset.n_eigenpairs)
            ddt_core(values, vectors, preset.diffusion_times, preset.ddt_core_shape)
            normalized_spectrum(op, values, preset.spectrum_size)
            t3 = time.perf_counter()
            modal_gdm(gdm, preset.gdm_singular_values)
            t4 = time.perf_counter()
            compute_shapedna(TriaMesh(mesh.vertices, mesh.faces), k=50)
            t5 = time.perf_counter()
            for stage, seconds in (
                ("load_resample", t1 - t0),
                ("gdm", t2 - t1),
                ("eigen_ddt", t3 - t2),
                ("modal", t4 - t3),
                ("descriptor", t4 - t1),
                ("shapedna", t5 - t4),
            ):
                samples.setdefault(stage, []).append(seconds)
            vertex_counts.append(mesh.n_vertices)
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
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 2500, 5000])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(_measure(args.child, args.repeats)))
        return
    rows = []
    for n in args.sizes:
        out = subprocess.run(
            [sys.executable, __file__, "--child", str(n), "--repeats", str(args.repeats)],
            check=True,
            capture_output=True,
            text=True,
        )
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    print(f"meshes: {', '.join(MESHES)}; {args.repeats} repeats each; medians in seconds\n")
    print(
        "| N | load+resample | GDM | eigen+DDT | modal | descriptor (GDM+DDT+modal) "
        "| ShapeDNA (lapy) | ratio | peak RSS MB |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['vertices']} | {r['load_resample']:.3f} | {r['gdm']:.3f} | "
            f"{r['eigen_ddt']:.3f} | {r['modal']:.3f} | {r['descriptor']:.3f} | "
            f"{r['shapedna']:.3f} | {r['ratio']:.1f}x | {r['peak_rss_mb']:.0f} |"
        )


if __name__ == "__main__":
    main()
