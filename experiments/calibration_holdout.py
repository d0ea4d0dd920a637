"""Does the calibration hold on pairs it was not fitted on? TOSCA, the service's code.

    python -m experiments.calibration_holdout [--preset smeets2010-surface] [--cache DIR]
        [--far 0.01]

With the calibration the service uses (``worker.recognition.calibration``, on the
preset's fused score), on the TOSCA descriptors of the evaluation cache:

1. all pairs: the EER (the one ``shapes evaluate`` reports, and ``GET /calibration``
   for a gallery of the same labelled meshes);
2. five class-stratified folds: calibrated on the pairs among four folds, the
   threshold at ``--far`` is applied to the impostor pairs that involve a held-out
   object: their measured FAR (the bar: within a factor of two of the target), and
   the held-out genuine pairs' FRR;
3. reliability: the held-out pairs grouped by the confidence the training fit gives
   them (ten bins of predicted confidence, 0-10% .. 90-100%): predicted against
   observed genuine rate (the bar: within 10 points in every bin); the tables are for
   one split into folds (seed 0), and the last lines give the mean FAR and the largest
   bin difference for ``--splits`` splits, since a middle bin holds only 50-250 pairs;
4. open set: each class in turn left out of the gallery (calibrated on the rest),
   its meshes as queries: how often the best match is wrongly accepted at ``--far``.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from benchmarks.common import add_evaluation_cache_arguments, evaluated_tosca
from worker.engine.compare import fuse
from worker.evaluation.compute import descriptor_vectors
from worker.evaluation.scoring import modality_dissimilarity
from worker.recognition.calibration import calibrate
from worker.recognition.fusion import stratified_folds

FOLDS = 5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_evaluation_cache_arguments(parser)
    parser.add_argument("--far", type=float, default=0.01)
    parser.add_argument("--splits", type=int, default=6, help="splits into folds to repeat on")
    args = parser.parse_args()
    preset, computed = evaluated_tosca(args)
    labels = np.array([m.label for m in computed.meshes])
    vectors = descriptor_vectors(computed)
    per = {m: modality_dissimilarity(vectors[m], preset.dissimilarity)[0] for m in vectors}
    weights = {m: preset.weight(m) for m in preset.fused_modalities}
    d = fuse({m: per[m] for m in preset.fused_modalities}, preset.fusion, weights)
    n = len(labels)
    i, j = np.triu_indices(n, 1)
    scores, same = d[i, j], labels[i] == labels[j]

    whole = calibrate(scores[same], scores[~same])
    print(f"preset {preset.name} v{preset.version}, fused score; {n} TOSCA meshes")
    print(f"all pairs: {whole.genuine} genuine, {whole.impostor} impostor, EER {whole.eer:.2%}\n")

    held_out = [
        _held_out(scores, same, i, j, labels, args.far, seed) for seed in range(args.splits)
    ]
    first = held_out[0]
    print(f"held-out pairs, threshold at FAR {args.far:.1%} fitted on the other folds' pairs\n")
    print("| fold | training pairs (g/i) | held-out pairs (g/i) | measured FAR | measured FRR |")
    print("|---|---|---|---:|---:|")
    for f, row in enumerate(first["folds"]):
        print(
            f"| {f} | {row['train_genuine']}/{row['train_impostor']} | "
            f"{row['held_genuine']}/{row['held_impostor']} | {row['far']:.2%} | {row['frr']:.2%} |"
        )
    print(f"| mean | | | {first['far']:.2%} | |\n")

    print("reliability on held-out pairs, by predicted confidence\n")
    print("| predicted | pairs | predicted (mean) | observed genuine rate | difference |")
    print("|---|---:|---:|---:|---:|")
    for k, pairs, pm, om in first["bins"]:
        print(
            f"| {10 * k}-{10 * k + 10}% | {pairs} | {pm:.1%} | {om:.1%} | {100 * (om - pm):+.1f} |"
        )
    print(f"\nlargest difference: {100 * first['worst']:.1f} points\n")
    print(f"the same for {args.splits} splits into folds (seeds 0-{args.splits - 1}):\n")
    print("| | " + " | ".join(str(seed) for seed in range(args.splits)) + " | median |")
    print("|---|" + "---:|" * (args.splits + 1))
    for title, key, unit in (("mean FAR", "far", "%"), ("largest bin difference", "worst", " pt")):
        values = [100 * h[key] for h in held_out]
        cells = " | ".join(f"{v:.2f}{unit}" for v in values)
        print(f"| {title} | {cells} | {np.median(values):.2f}{unit} |")
    print()

    print(
        f"open set: each class left out of the gallery, its meshes as queries, FAR {args.far:.1%}\n"
    )
    print("| class left out | queries | best match accepted (false accept) |")
    print("|---|---:|---:|")
    rates = []
    for c in np.unique(labels):
        gallery = np.flatnonzero(labels != c)
        g_i, g_j = np.triu_indices(len(gallery), 1)
        sub = d[np.ix_(gallery, gallery)][g_i, g_j]
        sub_same = labels[gallery][g_i] == labels[gallery][g_j]
        threshold = calibrate(sub[sub_same], sub[~sub_same]).threshold_at(args.far)
        queries = np.flatnonzero(labels == c)
        best = d[np.ix_(queries, gallery)].min(axis=1)
        rate = float(np.mean(best <= threshold))
        rates.append(rate)
        print(f"| {c} | {len(queries)} | {rate:.1%} |")
    print(f"| mean over classes | | {np.mean(rates):.1%} |")


def _held_out(
    scores: np.ndarray,
    same: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    labels: np.ndarray,
    far: float,
    seed: int,
) -> dict[str, Any]:
    """Calibrate on the pairs among four folds, measure on the pairs that involve the
    fifth, for one split into folds: per-fold FAR and FRR at ``far``, and the
    reliability bins ``(bin, pairs, mean predicted, observed genuine rate)``."""
    fold = stratified_folds(labels, FOLDS, seed=seed)
    folds, predicted, observed = [], [], []
    for f in range(FOLDS):
        out = fold == f
        train = ~out[i] & ~out[j]
        held = out[i] | out[j]
        fit = calibrate(scores[train & same], scores[train & ~same])
        threshold = fit.threshold_at(far)
        folds.append(
            {
                "train_genuine": int((train & same).sum()),
                "train_impostor": int((train & ~same).sum()),
                "held_genuine": int((held & same).sum()),
                "held_impostor": int((held & ~same).sum()),
                "far": float(np.mean(scores[held & ~same] <= threshold)),
                "frr": float(np.mean(scores[held & same] > threshold)),
            }
        )
        predicted.append(fit.confidence(scores[held]))
        observed.append(same[held])
    p, o = np.concatenate(predicted), np.concatenate(observed)
    which = np.minimum((p * 10).astype(int), 9)
    bins = [
        (k, int((which == k).sum()), float(p[which == k].mean()), float(o[which == k].mean()))
        for k in range(10)
        if (which == k).any()
    ]
    return {
        "folds": folds,
        "far": float(np.mean([row["far"] for row in folds])),
        "bins": bins,
        "worst": max(abs(pm - om) for _, _, pm, om in bins),
    }


if __name__ == "__main__":
    main()
