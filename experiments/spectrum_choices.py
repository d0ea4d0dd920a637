"""The spectrum modality's two free choices, measured on TOSCA: how many eigenvalues,
and how they are compared.

    python -m experiments.spectrum_choices [--preset smeets2010-surface] [--cache DIR] [--jobs 2]

The preset keeps ``spectrum_size`` (50, lapy's ``compute_shapedna`` default) non-zero
eigenvalues and compares them with its dissimilarity (D1, eq. 8). This describes TOSCA
once more under the preset with every eigenvalue its eigenproblem computes
(``n_eigenpairs - 1``; the eigenvalues do not depend on how many are kept, so the first
``k`` of them are the spectrum of ``spectrum_size = k``), through the evaluation cache
(about five minutes the first time), and scores, per size ``k``:

* the spectrum alone and the preset's fused score, with the preset's dissimilarity;
* the same with the spectrum compared as ShapeDNA compares it (lapy's
  ``reweight_ev`` and Euclidean distance,
  :func:`~worker.evaluation.shapedna.shapedna_dissimilarity`: eigenvalue ``i`` of
  ``0, lambda_1 A, lambda_2 A, ...`` divided by ``i``).

Then, per comparison, the size chosen with the fusion weights by the class-stratified
cross-validation of ``shapes tune`` (:mod:`worker.recognition.fusion`; the size with the
lowest loss among its weight choices, on four folds; tested on the fifth), for three
splits into folds, and the choice on all meshes.

What the tessellation does to the same choices is the robustness protocol's to say
(``docs/evaluation.md``, sec. "The spectrum's size and comparison").
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
from lapy.shapedna import reweight_ev

from benchmarks.common import TOSCA, add_evaluation_cache_arguments
from worker.engine.compare import fuse
from worker.engine.presets import get_preset
from worker.evaluation.compute import compute_descriptors, descriptor_vectors
from worker.evaluation.datasets import read_labels
from worker.evaluation.scoring import modality_dissimilarity
from worker.evaluation.shapedna import shapedna_dissimilarity
from worker.recognition import metrics
from worker.recognition.fusion import FOLDS, choose_weights, fusion_scores, stratified_folds

SIZES = (10, 15, 20, 25, 30, 40, 50, 70, 99)
SEEDS = (0, 1, 2)


def shapedna_style(spectrum: np.ndarray) -> np.ndarray:
    """All-to-all distances of spectra (rows of ``lambda_i A``, i >= 1) as ShapeDNA's:
    the zero eigenvalue put first, lapy's reweighting, Euclidean distance."""
    with_zero = np.hstack([np.zeros((len(spectrum), 1)), spectrum])
    return shapedna_dissimilarity(np.stack([reweight_ev(row) for row in with_zero]))


def row(name: str, d: np.ndarray, labels: np.ndarray, split: tuple[np.ndarray, np.ndarray]) -> str:
    r = metrics.retrieval_scores(d, labels)
    r1 = metrics.rank1_rate(d, labels, *split)
    eer = metrics.equal_error_rate(d, labels)
    return f"| {name} | {r['nn']:.1%} | {r1:.1%} | {eer:.2%} | {r['map']:.1%} |"


def choose_size(
    spectra: dict[int, np.ndarray], others: dict[str, np.ndarray], labels: np.ndarray, rule: str
) -> tuple[float, int, dict[str, float]]:
    """The size and weights with the lowest :func:`loss` on these objects (ties: the
    smaller size)."""
    best: tuple[float, int, dict[str, float]] | None = None
    for k, spectrum in spectra.items():
        weights, value = choose_weights({**others, "spectrum": spectrum}, labels, rule)
        if best is None or value < best[0]:
            best = (value, k, weights)
    assert best is not None
    return best


def cross_validate(
    spectra: dict[int, np.ndarray], others: dict[str, np.ndarray], labels: np.ndarray, rule: str
) -> None:
    for seed in SEEDS:
        fold = stratified_folds(labels, FOLDS, seed)
        chosen, tests = [], []
        for f in range(FOLDS):
            train, test = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
            sub = {k: d[np.ix_(train, train)] for k, d in spectra.items()}
            _, k, weights = choose_size(
                sub, {m: d[np.ix_(train, train)] for m, d in others.items()}, labels[train], rule
            )
            fused = fuse({**others, "spectrum": spectra[k]}, rule, weights)
            tests.append(fusion_scores(fused, labels, test))
            chosen.append(f"{k} ({', '.join(f'{w:g}' for w in weights.values())})")
        eer, map_ = np.mean([t.eer for t in tests]), np.mean([t.map for t in tests])
        print(f"| {seed} | {'; '.join(chosen)} | {eer:.2%} | {map_:.1%} |")
    value, k, weights = choose_size(spectra, others, labels, rule)
    shown = ", ".join(f"{m} {w:g}" for m, w in weights.items())
    print(f"| all meshes | {k} ({shown}), loss {value:.5f} | | |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_evaluation_cache_arguments(parser)
    args = parser.parse_args()
    preset = get_preset(args.preset)
    if "spectrum" not in preset.fused_modalities:
        parser.error(f"{preset.name} does not fuse the spectrum")
    every = replace(preset, spectrum_size=preset.n_eigenpairs - 1)
    computed = compute_descriptors(
        read_labels(TOSCA / "labels.csv", TOSCA), every, args.cache, jobs=args.jobs
    )
    labels = np.array([m.label for m in computed.meshes])
    names = [m.name for m in computed.meshes]
    split = metrics.first_instance_split(names, labels)
    vectors = descriptor_vectors(computed)
    others = {
        m: modality_dissimilarity(vectors[m], preset.dissimilarity)[0]
        for m in preset.fused_modalities
        if m != "spectrum"
    }
    weights = {m: preset.weight(m) for m in preset.fused_modalities}
    # comparison -> size -> all-to-all distances of the first ``size`` eigenvalues
    spectra = {
        how: {k: compare(vectors["spectrum"][:, :k]) for k in SIZES}
        for how, compare in (
            (preset.dissimilarity, lambda x: modality_dissimilarity(x, preset.dissimilarity)[0]),
            ("ShapeDNA's", shapedna_style),
        )
    }
    print(f"preset {preset.name} v{preset.version}, {len(names)} TOSCA meshes")
    print("| spectrum, k values, compared by | NN | R1RR | EER | mAP |")
    print("|---|---:|---:|---:|---:|")
    for k in SIZES:
        for how, by_size in spectra.items():
            print(row(f"spectrum, {k}, {how}", by_size[k], labels, split))
            fused = fuse({**others, "spectrum": by_size[k]}, preset.fusion, weights)
            print(row(f"the preset's score, {k}, {how}", fused, labels, split))
    baseline = shapedna_dissimilarity(vectors["shapedna"])
    print(row("ShapeDNA (lapy's eigenvalues)", baseline, labels, split))
    for how, by_size in spectra.items():
        print(f"\nthe spectrum compared by {how}: size (weights {', '.join(others)}, spectrum)")
        print("| split | each fold's choice | test EER | test mAP |")
        print("|---|---|---:|---:|")
        cross_validate(by_size, others, labels, preset.fusion)


if __name__ == "__main__":
    main()
