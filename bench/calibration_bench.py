"""Does the calibration hold on pairs it was not fitted on? TOSCA, the service's code.

    python bench/calibration_bench.py [--preset smeets2010-surface] [--cache DIR] [--far 0.01]

With the calibration the service uses (``worker.evaluation.calibration``, on the
preset's fused score), on the TOSCA descriptors of the evaluation cache:

1. all pairs: the EER (the one ``shapes evaluate`` reports, and ``GET /calibration``
   for a gallery of the same labelled meshes);
2. five class-stratified folds: calibrated on the pairs among four folds, the
   threshold at ``--far`` is applied to the impostor pairs that involve a held-out
   object: their measured FAR (the bar: within a factor of two of the target), and
   the held-out genuine pairs' FRR;
3. reliability: the held-out pairs grouped by the confidence the training fit gives
   them (ten bins of predicted confidence, 0-10% .. 90-100%): predicted against
   observed genuine rate (the bar: within 10 points in every bin);
4. open set: each class in turn left out of the gallery (calibrated on the rest),
   its meshes as queries: how often the best match is wrongly accepted at ``--far``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from worker.engine.compare import fuse
from worker.evaluation.calibration import calibrate
from worker.evaluation.compute import descriptor_vectors
from worker.evaluation.scoring import modality_dissimilarity, stratified_folds

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._tosca import add_evaluation_cache_arguments, evaluated_tosca  # noqa: E402

FOLDS = 5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_evaluation_cache_arguments(parser)
    parser.add_argument("--far", type=float, default=0.01)
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

    fold = stratified_folds(labels, FOLDS)
    print(f"held-out pairs, threshold at FAR {args.far:.1%} fitted on the other folds' pairs\n")
    print("| fold | training pairs (g/i) | held-out pairs (g/i) | measured FAR | measured FRR |")
    print("|---|---|---|---:|---:|")
    measured, predicted, observed = [], [], []
    for f in range(FOLDS):
        out = fold == f
        train = ~out[i] & ~out[j]
        held = out[i] | out[j]
        fit = calibrate(scores[train & same], scores[train & ~same])
        threshold = fit.threshold_at(args.far)
        far = float(np.mean(scores[held & ~same] <= threshold))
        frr = float(np.mean(scores[held & same] > threshold))
        measured.append(far)
        predicted.append(fit.confidence(scores[held]))
        observed.append(same[held])
        print(
            f"| {f} | {int((train & same).sum())}/{int((train & ~same).sum())} | "
            f"{int((held & same).sum())}/{int((held & ~same).sum())} | {far:.2%} | {frr:.2%} |"
        )
    print(f"| mean | | | {np.mean(measured):.2%} | |\n")

    p, o = np.concatenate(predicted), np.concatenate(observed)
    print("reliability on held-out pairs, by predicted confidence\n")
    print("| predicted | pairs | predicted (mean) | observed genuine rate | difference |")
    print("|---|---:|---:|---:|---:|")
    worst = 0.0
    bins = np.minimum((p * 10).astype(int), 9)
    for k in range(10):
        inside = bins == k
        if not inside.any():
            continue
        pm, om = float(p[inside].mean()), float(o[inside].mean())
        worst = max(worst, abs(pm - om))
        print(
            f"| {10 * k}-{10 * k + 10}% | {int(inside.sum())} | {pm:.1%} | {om:.1%} | "
            f"{100 * (om - pm):+.1f} |"
        )
    print(f"\nlargest difference: {100 * worst:.1f} points\n")

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


if __name__ == "__main__":
    main()
