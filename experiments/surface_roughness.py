"""Which surfaces the engine smooths of a scanner's noise: noiseless and noisy single views,
wholes and partial copies, measured as the engine measures them.

    python -m experiments.surface_roughness [--every 1] [--jobs 2]

A single view is smoothed when its roughness is above
:data:`~worker.engine.denoise.ROUGH_VIEW` and its noise share above
:data:`~worker.engine.denoise.NOISE_LIKE` (:func:`worker.engine.denoise.surface_fits`); any
other surface when it is both and Taubin's filter leaves it less than
:data:`~worker.engine.denoise.CRUMPLED_KEPT` of its area
(:func:`worker.engine.denoise.denoised`). For every TOSCA and SCAPE file (every
``--every``-th): the file itself, and each copy of it the partiality and tessellation
protocols make (:func:`worker.evaluation.variants.make_variant`, seeded as there; a range
scan without its shortcuts, :func:`worker.engine.pipeline.without_grid_shortcuts`; a copy
facing one way, as ``shrec-holes``' smallest fragments may, read as a view). Per copy kind:
the copies, each measure's smallest, median and largest, how many pass each threshold, and
how many the engine smooths. Then each threshold chosen on one collection's copies alone
(:func:`fewest_wrong`) and how many of the other's it puts on the wrong side: roughness and
noise share on the views, the area kept on the other copies the first two pass.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import SCAPE, TOSCA, drawn_variant
from worker.engine.denoise import (
    NOISE_LIKE,
    ROUGH_VIEW,
    denoised,
    surface_fits,
    taubin_smoothed,
    view_denoised,
)
from worker.engine.descriptor import ONE_VIEW_FACING
from worker.engine.errors import MeshError
from worker.engine.holes import facing_share
from worker.engine.mesh_io import Mesh, face_areas, load_mesh
from worker.engine.pipeline import without_grid_shortcuts
from worker.evaluation.variants import make_variant

#: The file itself.
WHOLE = "whole"
#: Single views without and with a depth camera's noise.
VIEWS = ("view", "range", "range-cloud", "view-points")
NOISY_VIEWS = ("view-noise-0.25", "view-noise-0.5")
#: Other surfaces without noise (coarse ones among them) and with a scanner's noise.
SURFACES = (WHOLE, "cut-30", "holes-25", "shrec-holes", "decimated-50", "decimated-20")
NOISY_SURFACES = ("noise-0.25", "noise-0.5", "noise-1")
#: The tessellation protocol's noise of a tenth of an edge: reported, judged neither way.
SLIGHT = ("noisy",)
KINDS = (*VIEWS, *NOISY_VIEWS, *SURFACES, *NOISY_SURFACES, *SLIGHT)

#: One copy: (read as a view, roughness, noise share, area kept by smoothing or NaN where
#: the engine does not weigh it, smoothed by the engine).
Copy = tuple[bool, float, float, float, bool]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    collections = {
        "TOSCA": sorted(TOSCA.glob("*.off.gz"))[:: args.every],
        "SCAPE": sorted(SCAPE.glob("*.off.gz"))[:: args.every],
    }
    measured: dict[str, dict[str, list[Copy]]] = {}
    with ProcessPoolExecutor(args.jobs) as pool:
        for collection, files in collections.items():
            measured[collection] = {kind: [] for kind in KINDS}
            for copies in pool.map(copies_of, files):
                for kind, copy in copies.items():
                    measured[collection][kind].append(copy)
    print(
        f"| copies | made | read as views | roughness: smallest | median | largest | above "
        f"{ROUGH_VIEW} | noise share: smallest | median | largest | above {NOISE_LIKE} | "
        f"area kept (both above, not views): smallest | largest | smoothed |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for kind in KINDS:
        view, r, share, kept, smoothed = np.array(
            [c for per in measured.values() for c in per[kind]], dtype=float
        ).T
        weighed = kept[np.isfinite(kept)]
        span = f"{weighed.min():.3f} | {weighed.max():.3f}" if len(weighed) else "- | -"
        print(
            f"| {kind} | {len(r)} | {int(view.sum())} | {r.min():.4f} | {np.median(r):.4f} | "
            f"{r.max():.4f} | {int((r > ROUGH_VIEW).sum())} | {share.min():.3f} | "
            f"{np.median(share):.3f} | {share.max():.3f} | {int((share > NOISE_LIKE).sum())} | "
            f"{span} | {int(smoothed.sum())} |"
        )
    print()
    print("| measure | on | chosen on | threshold | wrong there | wrong on the other |")
    print("|---|---|---|---:|---:|---:|")
    for measure, column, clean, noisy, above in (
        ("roughness", 1, VIEWS, NOISY_VIEWS, True),
        ("noise share", 2, VIEWS, NOISY_VIEWS, True),
        ("area kept", 3, SURFACES, NOISY_SURFACES, False),
    ):
        values = {
            c: {
                kind: [copy[column] for copy in per[kind] if np.isfinite(copy[column])]
                for kind in (*clean, *noisy)
            }
            for c, per in measured.items()
        }
        on = "views" if clean is VIEWS else "other copies rough and noise-like"
        for chosen, other in (("TOSCA", "SCAPE"), ("SCAPE", "TOSCA")):
            threshold = fewest_wrong(values[chosen], clean, noisy, above)
            print(
                f"| {measure} | {on} | {chosen} | {threshold:.4f} | "
                f"{wrong_side(values[chosen], clean, noisy, above, threshold)} | "
                f"{wrong_side(values[other], clean, noisy, above, threshold)} |"
            )


def copies_of(path: Path) -> dict[str, Copy]:
    """One file and each copy of it, measured and smoothed as the engine does."""
    mesh = load_mesh(path)
    copies: dict[str, Copy] = {}
    for kind in KINDS:
        try:
            copy = (
                mesh
                if kind == WHOLE
                else make_variant(mesh, drawn_variant(kind, path.name), path.name)
            )
        except MeshError:  # a shrec-holes copy eroded whole
            continue
        copies[kind] = measured_copy(without_grid_shortcuts(copy).mesh)
    return copies


def measured_copy(surface: Mesh) -> Copy:
    view = facing_share(surface) >= ONE_VIEW_FACING
    rough, share = surface_fits(surface.vertices)
    kept = float("nan")
    if not view and rough > ROUGH_VIEW and share > NOISE_LIKE:
        area = face_areas(surface.vertices, surface.faces).sum()
        kept = float(face_areas(taubin_smoothed(surface).vertices, surface.faces).sum() / area)
    smoothed = (view_denoised if view else denoised)(surface) is not surface
    return view, rough, share, kept, smoothed


def wrong_side(
    values: dict[str, list[float]],
    clean: tuple[str, ...],
    noisy: tuple[str, ...],
    above: bool,
    threshold: float,
) -> int:
    """Clean copies that ``threshold`` would smooth and noisy ones it would not (smoothed
    ``above`` it, or below it)."""
    sign = 1 if above else -1
    wrong = sum(sign * (v - threshold) > 0 for kind in clean for v in values[kind])
    return wrong + sum(sign * (v - threshold) <= 0 for kind in noisy for v in values[kind])


def fewest_wrong(
    values: dict[str, list[float]], clean: tuple[str, ...], noisy: tuple[str, ...], above: bool
) -> float:
    """The threshold with the fewest copies on the wrong side: the geometric middle of the
    widest gap between two measured values that leaves fewest."""
    r = np.unique(np.concatenate([np.array(found) for found in values.values()]))
    middles = np.sqrt(r[:-1] * r[1:])
    wrong = np.array([wrong_side(values, clean, noisy, above, t) for t in middles])
    best = np.flatnonzero(wrong == wrong.min())
    # Of the ties, the widest run of consecutive gaps, its middle.
    runs = np.split(best, np.flatnonzero(np.diff(best) > 1) + 1)
    run = max(runs, key=lambda gaps: r[gaps[-1] + 1] / r[gaps[0]])
    return float(np.sqrt(r[run[0]] * r[run[-1] + 1]))


if __name__ == "__main__":
    main()
