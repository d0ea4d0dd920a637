"""Fusion weights by class-stratified cross-validation (the paper's future work, sec. 5).

    python bench/fusion_weights.py [--preset smeets2010-surface] [--cache DIR] [--jobs 2]

The preset's modalities are fused by its rule with one weight per modality
(``prod_m D_m ** w_m`` or ``sum_m w_m D_m``); the last fused modality keeps weight 1
(the product's ranking only depends on the weights' ratios). Five class-stratified
folds: on the objects of four folds every weight combination of the grid is scored
by the mean of its EER and 1 - mAP (verification and retrieval errors weigh
equally), and the chosen weights are measured on the pairs that involve an object
of the fifth fold (EER) and with the fifth fold's objects as queries against all
others (NN, mAP), so no weight ever sees its test pairs. The table shows each
fold's choice and test scores; then the choice on all meshes, the weights a preset
takes, and the loss on all meshes with each weight moved over the grid (the others as
chosen), which shows how sharply TOSCA decides it. Descriptors come from (and go to)
the evaluation cache that ``shapes evaluate`` uses, so after an evaluation this takes
seconds.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

from worker.engine.compare import fuse
from worker.evaluation.compute import descriptor_vectors
from worker.evaluation.scoring import modality_dissimilarity
from worker.recognition import metrics
from worker.recognition.fusion import stratified_folds

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._tosca import add_evaluation_cache_arguments, evaluated_tosca  # noqa: E402

GRID = (0.0, 0.125, 0.25, 0.5, 1.0)
FOLDS = 5


def scores(d: np.ndarray, labels: np.ndarray, held_out: np.ndarray | None = None) -> dict:
    """EER, NN and mAP of a dissimilarity matrix; with ``held_out`` (indices), over
    the pairs that involve a held-out object and the held-out objects as queries
    (each ranking everything else), the pairs no weight was chosen on."""
    if held_out is None:
        retrieval = metrics.retrieval_scores(d, labels)
        return {"eer": metrics.equal_error_rate(d, labels), **retrieval}
    i, j = np.triu_indices(len(d), 1)
    tested = np.isin(i, held_out) | np.isin(j, held_out)
    same = labels[i] == labels[j]
    eer = metrics.pair_equal_error_rate(d[i, j][tested & same], d[i, j][tested & ~same])
    return {"eer": eer, **metrics.retrieval_scores(d, labels, queries=held_out)}


def loss(s: dict) -> float:
    """What the weights minimize: verification and retrieval errors, equally."""
    return 0.5 * (s["eer"] + (1.0 - s["map"]))


def choose(mats: dict[str, np.ndarray], labels: np.ndarray, rule: str) -> dict[str, float]:
    """The grid weights with the lowest :func:`loss` on these objects (ties: the
    smaller weights, i.e. the earlier grid point)."""
    names = list(mats)
    best: tuple[float, dict[str, float]] | None = None
    for w in itertools.product(GRID, repeat=len(names) - 1):
        weights = dict(zip(names, (*w, 1.0), strict=True))
        value = loss(scores(fuse(mats, rule, weights), labels))
        if best is None or value < best[0]:
            best = (value, weights)
    assert best is not None
    return best[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_evaluation_cache_arguments(parser)
    preset, computed = evaluated_tosca(parser.parse_args())
    labels = np.array([m.label for m in computed.meshes])
    vectors = descriptor_vectors(computed)
    mats = {
        m: modality_dissimilarity(vectors[m], preset.dissimilarity)[0]
        for m in preset.fused_modalities
    }
    fold = stratified_folds(labels, FOLDS)
    names = list(mats)
    print(f"preset {preset.name} v{preset.version}, {preset.fusion} rule, grid {GRID}")
    print("| fold | weights (" + ", ".join(names) + ") | test EER | test NN | test mAP |")
    print("|---|---|---:|---:|---:|")
    tests = []
    for f in range(FOLDS):
        train, test = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        training = {m: d[np.ix_(train, train)] for m, d in mats.items()}
        weights = choose(training, labels[train], preset.fusion)
        s = scores(fuse(mats, preset.fusion, weights), labels, test)
        alone = scores(mats[names[-1]], labels, test)
        tests.append((s, alone))
        shown = ", ".join(f"{weights[m]:g}" for m in names)
        print(f"| {f} | {shown} | {s['eer']:.2%} | {s['nn']:.1%} | {s['map']:.1%} |")
    for label, k in (("fused", 0), (f"{names[-1]} alone", 1)):
        mean = {key: np.mean([t[k][key] for t in tests]) for key in ("eer", "nn", "map")}
        print(
            f"| mean over folds, {label} | | {mean['eer']:.2%} | {mean['nn']:.1%} | "
            f"{mean['map']:.1%} |"
        )
    weights = choose(mats, labels, preset.fusion)
    print("chosen on all meshes: " + ", ".join(f"{m} {weights[m]:g}" for m in names))
    # How sharply TOSCA decides: each weight moved over the grid, the others as chosen.
    print("\n| on all meshes | " + " | ".join(f"{w:g}" for w in GRID) + " |")
    print("|---|" + "---:|" * len(GRID))
    for m in names[:-1]:
        losses = [loss(scores(fuse(mats, preset.fusion, {**weights, m: w}), labels)) for w in GRID]
        print(f"| loss, {m} weight | " + " | ".join(f"{x:.5f}" for x in losses) + " |")


if __name__ == "__main__":
    main()
