"""The fusion weights for a collection without labels, chosen across every labelled
collection the project has, by leave-one-collection-out.

    python -m experiments.fusion_default [--preset smeets2010-surface] [--cache DIR] [--jobs 2]

Three disjoint collections, described through the evaluation cache (SCAPE's 71 poses take
a few minutes the first time):

* animals: TOSCA's non-human figures (cat, centaur, dog, gorilla, horse, wolf);
* humans: SCAPE's scanned person (71 poses) and TOSCA's david, michael and victoria;
* samples: the bundled examples (five figures, four poses each).

For every grid point of the preset's rule (the service's comparison; the spectrum keeps
weight 1, as ``shapes tune``), the loss on each collection (the mean of EER and 1 - mAP,
all-to-all). Leaving each collection out in turn, the weights with the lowest mean loss on
the other two are scored on it, beside the preset's weights and equal weights. The last
line is the choice on all three: the candidate for the default.
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from benchmarks.common import EXAMPLES, TOSCA, add_evaluation_cache_arguments
from worker.engine.compare import dissimilarity, fuse
from worker.engine.presets import get_preset
from worker.evaluation.compute import compute_descriptors, descriptor_vectors
from worker.evaluation.datasets import LabeledMesh, pose_set, read_labels, shared_dataset
from worker.recognition.fusion import GRID, fusion_scores

SCAPE = shared_dataset("scape")
HUMANS = ("david", "michael", "victoria")


def collections(args: argparse.Namespace) -> dict[str, tuple[dict[str, np.ndarray], np.ndarray]]:
    """Collection -> (modality -> (n, n) dissimilarity, labels)."""
    preset = get_preset(args.preset)
    tosca = read_labels(TOSCA / "labels.csv", TOSCA)
    scape = [LabeledMesh(name=m.name, label="scape", path=m.path) for m in pose_set(SCAPE)]
    sets: dict[str, list[LabeledMesh]] = {
        "animals": [m for m in tosca if m.label not in HUMANS],
        "humans": scape + [m for m in tosca if m.label in HUMANS],
        "samples": read_labels(EXAMPLES / "labels.csv", EXAMPLES),
    }
    out = {}
    for name, meshes in sets.items():
        computed = compute_descriptors(meshes, preset, args.cache, jobs=args.jobs)
        vectors = descriptor_vectors(computed)
        mats = {}
        for m in preset.fused_modalities:
            d = dissimilarity(vectors[m], vectors[m], preset.dissimilarity)
            mats[m] = 0.5 * (d + d.T)
            np.fill_diagonal(mats[m], 0.0)
        out[name] = (mats, np.array([m.label for m in computed.meshes]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_evaluation_cache_arguments(parser)
    args = parser.parse_args()
    preset = get_preset(args.preset)
    data = collections(args)
    fused = list(preset.fused_modalities)
    grid = [
        dict(zip(fused, (*w, 1.0), strict=True))
        for w in itertools.product(GRID, repeat=len(fused) - 1)
    ]
    loss = {
        name: [fusion_scores(fuse(mats, preset.fusion, w), labels).loss for w in grid]
        for name, (mats, labels) in data.items()
    }
    own = {m: preset.weight(m) for m in fused}
    equal = dict.fromkeys(fused, 1.0)

    def scored(name: str, weights: dict[str, float]) -> str:
        mats, labels = data[name]
        s = fusion_scores(fuse(mats, preset.fusion, weights), labels)
        return f"{100 * s.nn:.1f} / {100 * s.eer:.2f} / {100 * s.map:.2f}"

    def shown(weights: dict[str, float]) -> str:
        return ", ".join(f"{m} {w:g}" for m, w in weights.items())

    sizes = ", ".join(f"{n} {len(labels)} meshes {len(set(labels))} classes"
                      for n, (_, labels) in data.items())  # fmt: skip
    print(f"{preset.name} v{preset.version}, {preset.fusion} rule, {preset.dissimilarity}; {sizes}")
    print("NN / EER / mAP on the collection left out")
    print("| left out | chosen on the others | chosen | preset's | equal |\n|---|---|---|---|---|")
    for name in data:
        others = [o for o in data if o != name]
        best = int(np.argmin(np.mean([loss[o] for o in others], axis=0)))
        print(
            f"| {name} | {shown(grid[best])} | {scored(name, grid[best])} | "
            f"{scored(name, own)} | {scored(name, equal)} |"
        )
    best = int(np.argmin(np.mean([loss[o] for o in data], axis=0)))
    print(f"chosen on all three: {shown(grid[best])}")
    print("| collection | chosen on all | preset's |\n|---|---|---|")
    for name in data:
        print(f"| {name} | {scored(name, grid[best])} | {scored(name, own)} |")


if __name__ == "__main__":
    main()
