"""Spectrum accuracy: the 2,500-vertex resample's eigenvalues against the surface's.

    python -m experiments.spectrum_accuracy [--variants decimated-20,remeshed-8k,noisy]

For the first mesh of every TOSCA class, the reference is the full-resolution
file's spectrum (its first 50 non-zero eigenvalues times its area, with the
averaged mass; the lumped mass at full resolution is printed next to it as the
reference's own uncertainty). The original and each variant of the robustness
protocol are then resampled as the default preset does (canonical frame, 2,500
vertices) and their spectra computed with eq. (3)'s lumped mass and with the
averaged mass (the default's, Ritz values in the span of eq. (3)'s eigenvectors).
Relative errors: median over the 50 eigenvalues, and the 50th's.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from benchmarks.common import TOSCA, first_of_each_class, full_resolution_spectra
from worker.engine.mesh_io import Mesh, load_mesh
from worker.engine.pipeline import describe_mesh
from worker.engine.presets import get_preset
from worker.evaluation.variants import make_variant

PRESET = get_preset("smeets2010-surface")
SIZE = PRESET.spectrum_size


def resampled_spectra(mesh: Mesh) -> dict[str, np.ndarray]:
    """The default preset's spectrum of ``mesh``, and the same pipeline's with the lumped mass."""
    return {
        mass: describe_mesh(mesh, replace(PRESET, spectrum_mass=mass)).spectrum
        for mass in ("lumped", "averaged")
    }


def errors(spectrum: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    relative = np.abs(spectrum / reference - 1.0)
    return float(np.median(relative)), float(relative[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", default="decimated-20,remeshed-8k,noisy")
    args = parser.parse_args()
    variants = [None, *args.variants.split(",")]
    print("| mesh (vertices) | input | lumped: median | 50th | averaged: median | 50th |")
    print("|---|---|---:|---:|---:|---:|")
    summary: dict[str, list[float]] = {"lumped": [], "averaged": []}
    for name in first_of_each_class():
        mesh = load_mesh(TOSCA / name)
        reference = full_resolution_spectra(mesh, SIZE)
        own = errors(reference["lumped"], reference["averaged"])
        label = f"{name.split('.')[0]} ({mesh.n_vertices:,})"
        print(f"| {label} | full resolution, lumped | {own[0]:.2%} | {own[1]:.2%} | | |")
        for variant in variants:
            source = mesh if variant is None else make_variant(mesh, variant, name)
            spectra = resampled_spectra(source)
            cells = []
            for mass in ("lumped", "averaged"):
                median, last = errors(spectra[mass], reference["averaged"])
                summary[mass].append(median)
                cells += [f"{median:.2%}", f"{last:.2%}"]
            print(f"| {label} | {variant or 'original'} at 2,500 | " + " | ".join(cells) + " |")
    print()
    for mass, medians in summary.items():
        print(
            f"{mass}: median error over meshes and inputs {np.median(medians):.2%} "
            f"(range {min(medians):.2%}-{max(medians):.2%})"
        )


if __name__ == "__main__":
    main()
