"""The size cue of a collection in metric units: its comparison and its weight, chosen by
class-stratified cross-validation.

    python -m experiments.size_weight [--preset smeets2010-surface] [--cache DIR] [--jobs 2]

Every shape descriptor is scale-free; a collection whose files share one calibrated unit
(``--units metric``) also compares each file's size ``s = sqrt(A)``, ``A`` the area of its
described surface (:attr:`~worker.engine.descriptor.ShapeDescriptor.area`), fused with the
preset's score of the shape at a weight of its own. This chooses how the size is compared
and that weight with the code ``shapes tune --units metric`` runs
(:func:`worker.evaluation.size.size_tuning`: the size on its grid against the preset's
score of the shape at 1, five class-stratified folds), each fold choosing the size's
comparison too: the engine's, eq. (8) D1 of ``[sqrt(A)]`` at least the preset's
``size_tolerance`` (:func:`worker.engine.compare.size_dissimilarity`; D1 is
``2 tanh(|log(s_k / s_l)| / 2)``), or D1 at least another of :data:`TOLERANCES` (0: eq. 8
itself), eq. (9) D2 (sigma over the collection), the log-ratio ``|log(s_k / s_l)|``.

Collections whose sizes mean something:

* TOSCA, 83 meshes, 9 classes: one scale for all (the paper's sec. 4.1), centimetres by
  its human figures' heights (printed);
* TOSCA and SCAPE's 71 poses of one scanned person (154 meshes, 10 classes). SCAPE's files
  are in metres (printed): its areas are multiplied by 1e4 to put it in TOSCA's unit, as a
  collection in one unit would hold them;
* of those, the humans: TOSCA's david, michael and victoria and SCAPE's person (110
  meshes, 4 people), where the size decides least (SCAPE's person is michael's height).

A preset that keeps the scale in its shape descriptors (sec. 4.1's) is measured on TOSCA
only: SCAPE's descriptors would be in metres.

Prints, per collection: the files' heights and sizes per class; each fold's choice and its
held-out EER / NN / mAP beside the preset's own size weight's; the choice on all meshes
and the loss at each grid weight; the metric score's figures on all meshes at the chosen
weight and without the size.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from benchmarks.common import TOSCA, add_evaluation_cache_arguments
from worker.engine.compare import fuse
from worker.engine.mesh_io import load_mesh
from worker.engine.presets import SIZE, get_preset, with_units
from worker.evaluation.compute import compute_descriptors, descriptor_vectors
from worker.evaluation.datasets import LabeledMesh, pose_set, read_labels, shared_dataset
from worker.evaluation.size import SHAPE, shape_and_size, size_tuning
from worker.recognition.fusion import FusionScores, all_to_all, fusion_scores

SCAPE = shared_dataset("scape")
HUMANS = ("david", "michael", "victoria")
#: SCAPE's metres in TOSCA's centimetres, for areas.
SCAPE_AREA_FACTOR = 1e4
#: The floors of eq. (8) on the size offered beside the preset's.
TOLERANCES = (0.0, 0.01, 0.02, 0.03, 0.05)


def _figures(scores: FusionScores) -> str:
    return f"{100 * scores.eer:.2f} | {100 * scores.nn:.1f} | {100 * scores.map:.2f}"


def heights(meshes: Sequence[LabeledMesh]) -> str:
    """The first file of each class: its bounding box's largest extent, in file units."""
    firsts: dict[str, LabeledMesh] = {}
    for m in meshes:
        firsts.setdefault(m.label, m)
    return ", ".join(
        f"{c} {float(np.ptp(load_mesh(m.path).vertices, axis=0).max()):.4g}"
        for c, m in firsts.items()
    )


def report(
    title: str, vectors: dict[str, np.ndarray], labels: np.ndarray, args: argparse.Namespace
) -> None:
    preset = with_units(get_preset(args.preset), "metric")
    sizes = vectors[SIZE][:, 0]
    print(f"\n## {title}: {len(labels)} meshes, preset {preset.name} v{preset.version}\n")
    print("| class | meshes | size sqrt(A): mean | min | max |")
    print("|---|---:|---:|---:|---:|")
    for c in dict.fromkeys(labels):
        s = sizes[labels == c]
        print(f"| {c} | {len(s)} | {s.mean():.4g} | {s.min():.4g} | {s.max():.4g} |")
    s = vectors[SIZE]
    alternatives = {
        (t := replace(preset, size_tolerance=floor)).comparison(SIZE): shape_and_size(vectors, t)[1]
        for floor in TOLERANCES
        if floor != preset.size_tolerance
    }
    alternatives["D2"] = all_to_all(s, "D2", np.std(s, axis=0))
    alternatives["log-ratio"] = np.abs(np.log(s) - np.log(s).T)
    tuning = size_tuning(vectors, labels, preset, alternatives=alternatives)
    print(
        "\n| fold | meshes | size weight (comparison) | EER | NN | mAP | preset's "
        f"({preset.weight(SIZE):g}, {preset.comparison(SIZE)}) EER | NN | mAP |"
    )
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|")
    for f, fold in enumerate(tuning.folds):
        print(
            f"| {f} | {fold.held_out_objects} | {fold.weights[SIZE]:g} "
            f"({fold.comparisons[SIZE]}) | {_figures(fold.held_out)} | {_figures(fold.preset)} |"
        )
    print(f"| mean | | | {_figures(tuning.held_out)} | {_figures(tuning.preset_held_out)} |")
    print(
        f"\nchosen on all meshes: size {tuning.weights[SIZE]:g} "
        f"({tuning.comparisons[SIZE]}), {SHAPE} 1 (loss {tuning.loss:.5f})"
    )
    print("| loss on all meshes | " + " | ".join(f"{w:g}" for w in tuning.grid) + " |")
    print("|---|" + "---:|" * len(tuning.grid))
    print("| size weight | " + " | ".join(f"{x:.5f}" for x in tuning.sensitivity[SIZE]) + " |")
    shape, size = shape_and_size(vectors, preset)
    print("\n| on all meshes | EER | NN | mAP |\n|---|---:|---:|---:|")
    print(f"| the shape alone (units any) | {_figures(fusion_scores(shape, labels))} |")
    print(
        f"| the size alone ({preset.comparison(SIZE)}) | {_figures(fusion_scores(size, labels))} |"
    )
    for w in (tuning.weights[SIZE], preset.weight(SIZE)):
        fused = fuse({SHAPE: shape, SIZE: size}, preset.fusion, {SHAPE: 1.0, SIZE: w})
        print(f"| shape and size at {w:g} | {_figures(fusion_scores(fused, labels))} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_evaluation_cache_arguments(parser)
    args = parser.parse_args()
    preset = get_preset(args.preset)
    tosca = read_labels(TOSCA / "labels.csv", TOSCA)
    scape = [LabeledMesh(name=m.name, label="scape", path=m.path) for m in pose_set(SCAPE)]
    print(f"heights (largest extent of a class's first file): TOSCA {heights(tosca)}")
    print(f"SCAPE {heights(scape)}")

    done = compute_descriptors(tosca, preset, args.cache, jobs=args.jobs)
    vectors = descriptor_vectors(done, size=True)
    labels = np.array([m.label for m in done.meshes])
    report("TOSCA", vectors, labels, args)
    if not preset.normalize_scale:
        print(
            f"\n{preset.name} describes the shape in the file's unit: SCAPE's metres cannot join."
        )
        return

    posed = compute_descriptors(scape, preset, args.cache, jobs=args.jobs)
    areas = [d.area for d in posed.descriptors]
    if any(a is None for a in areas):
        parser.error("a SCAPE descriptor has no area: clear its cache entry")
    resized = [replace(d, area=SCAPE_AREA_FACTOR * float(d.area or 0.0)) for d in posed.descriptors]
    in_centimetres = replace(posed, descriptors=resized)
    scape_vectors = descriptor_vectors(in_centimetres, size=True)
    scape_labels = np.array([m.label for m in posed.meshes])
    both = {m: np.concatenate([vectors[m], scape_vectors[m]]) for m in vectors}
    report(
        "TOSCA and SCAPE (SCAPE in centimetres)", both, np.concatenate([labels, scape_labels]), args
    )
    human = np.isin(labels, HUMANS)
    people = {m: np.concatenate([vectors[m][human], scape_vectors[m]]) for m in vectors}
    people_labels = np.concatenate([labels[human], scape_labels])
    report("humans (TOSCA's and SCAPE's, SCAPE in centimetres)", people, people_labels, args)


if __name__ == "__main__":
    main()
