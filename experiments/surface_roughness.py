"""Which surfaces the engine smooths: the roughness and noise share of noiseless and noisy
single views and wholes.

    python -m experiments.surface_roughness [--every 1] [--jobs 2]

A surface is smoothed when its roughness is above :data:`~worker.engine.denoise.ROUGH_VIEW`
and its noise share above :data:`~worker.engine.denoise.NOISE_LIKE`
(:func:`worker.engine.denoise.surface_fits`): a two-sided view before it is gridded for its
rigid fit, any other surface before it is described. For every TOSCA and SCAPE file (every
``--every``-th): the file itself, and each single-view and noisy copy the partiality
protocol makes of it (:func:`worker.evaluation.variants.make_variant`, seeded as there),
measured as the engine measures it (a range scan without its shortcuts,
:func:`worker.engine.pipeline.without_grid_shortcuts`): per copy kind, the copies, the
smallest, median and largest of each measure, how many are above its threshold and how
many are smoothed. Then each measure's threshold chosen on one collection's copies alone
(the one leaving fewest of them on the wrong side, :func:`fewest_wrong`), and how many of
the other's it puts on the wrong side.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import TOSCA
from worker.engine.denoise import NOISE_LIKE, ROUGH_VIEW, surface_fits
from worker.engine.mesh_io import load_mesh
from worker.engine.pipeline import without_grid_shortcuts
from worker.evaluation.datasets import shared_dataset
from worker.evaluation.variants import make_variant

#: The file itself, and the copies without and with noise.
WHOLE = "whole"
NOISELESS = ("view", "range", "range-cloud", "view-points", WHOLE)
NOISY = ("view-noise-0.25", "view-noise-0.5", "noise-0.25", "noise-0.5", "noise-1")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    collections = {
        "TOSCA": sorted(TOSCA.glob("*.off.gz"))[:: args.every],
        "SCAPE": sorted(shared_dataset("scape").glob("*.off.gz"))[:: args.every],
    }
    # collection -> variant -> (roughness, noise share) of each copy
    measured: dict[str, dict[str, list[tuple[float, float]]]] = {}
    with ProcessPoolExecutor(args.jobs) as pool:
        for collection, files in collections.items():
            measured[collection] = {v: [] for v in (*NOISELESS, *NOISY)}
            for copies in pool.map(fits_of_copies, files):
                for variant, fits in copies.items():
                    measured[collection][variant].append(fits)
    print(
        f"| copies | made | roughness: smallest | median | largest | above {ROUGH_VIEW} | "
        f"noise share: smallest | median | largest | above {NOISE_LIKE} | smoothed |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for variant in (*NOISELESS, *NOISY):
        r, share = np.concatenate([np.array(measured[c][variant]) for c in collections]).T
        rough, noise = r > ROUGH_VIEW, share > NOISE_LIKE
        print(
            f"| {variant} | {len(r)} | {r.min():.4f} | {np.median(r):.4f} | {r.max():.4f} | "
            f"{int(rough.sum())} | {share.min():.3f} | {np.median(share):.3f} | "
            f"{share.max():.3f} | {int(noise.sum())} | {int((rough & noise).sum())} |"
        )
    print()
    print("| measure | chosen on | threshold | wrong there | wrong on the other |")
    print("|---|---|---:|---:|---:|")
    for measure, column in (("roughness", 0), ("noise share", 1)):
        values = {
            c: {v: [fits[column] for fits in found] for v, found in per.items()}
            for c, per in measured.items()
        }
        for chosen, other in (("TOSCA", "SCAPE"), ("SCAPE", "TOSCA")):
            threshold = fewest_wrong(values[chosen])
            print(
                f"| {measure} | {chosen} | {threshold:.4f} | "
                f"{wrong_side(values[chosen], threshold)} | "
                f"{wrong_side(values[other], threshold)} |"
            )


def fits_of_copies(path: Path) -> dict[str, tuple[float, float]]:
    """One file and each copy of it, measured as the engine measures it."""
    mesh = load_mesh(path)
    return {
        variant: surface_fits(
            mesh.vertices
            if variant == WHOLE
            else without_grid_shortcuts(make_variant(mesh, variant, path.name)).mesh.vertices
        )
        for variant in (*NOISELESS, *NOISY)
    }


def wrong_side(values: dict[str, list[float]], threshold: float) -> int:
    """Noiseless copies above ``threshold`` and noisy ones at or under it (of one measure)."""
    wrong = sum(r > threshold for v in NOISELESS for r in values[v])
    return wrong + sum(r <= threshold for v in NOISY for r in values[v])


def fewest_wrong(values: dict[str, list[float]]) -> float:
    """The threshold with the fewest copies on the wrong side: the geometric middle of the
    widest gap between two measured values that leaves fewest."""
    r = np.unique(np.concatenate([np.array(found) for found in values.values()]))
    middles = np.sqrt(r[:-1] * r[1:])
    wrong = np.array([wrong_side(values, t) for t in middles])
    best = np.flatnonzero(wrong == wrong.min())
    # Of the ties, the widest run of consecutive gaps, its middle.
    runs = np.split(best, np.flatnonzero(np.diff(best) > 1) + 1)
    run = max(runs, key=lambda gaps: r[gaps[-1] + 1] / r[gaps[0]])
    return float(np.sqrt(r[run[0]] * r[run[-1] + 1]))


if __name__ == "__main__":
    main()
