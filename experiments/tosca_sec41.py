"""The paper's TOSCA experiment (sec. 4.1) as the paper ran it: whether TOSCA's poses share
one triangulation, and where the GDM's and the DDT's errors are.

    python -m experiments.tosca_sec41 [--cache DIR] [--jobs 2]

Sec. 4.1 describes about 3,000 vertices per object, "the objects have already the same
scale" and no preprocessing; its subset's poses of one figure shared one triangulation.
Two measurements on ``../shared/datasets/tosca``:

1. **Triangulations**, per class of ``labels.csv`` (one figure each): its files' vertex and
   face counts as the files have them; how many have the face list of the class's first
   file exactly; over the files with its vertex count, the median share of the first
   file's triangles (as sets of vertex ids) they have too; and the median, 5th and 95th
   percentile of the ratio of the lengths of the edges of those shared triangles to the
   first file's (1 where vertex ``i`` is the same point of the figure in every pose).
2. **Errors** of ``smeets2010-tosca`` (no scale normalization) with one resampling per
   figure carried to its poses (``shapes evaluate --resampling figure``, through the same
   cache): for the GDM, the DDT and their sum (D1), the EER, and at the threshold nearest
   FAR = FRR the false rejects per class and the false accepts per pair of classes; per
   class the spread (coefficient of variation) of the GDM's largest singular value and of
   the size ``sqrt(A)``.
"""

from __future__ import annotations

import argparse
from collections import Counter

import numpy as np

from benchmarks.common import TOSCA, add_evaluation_cache_arguments
from worker.engine.compare import fuse
from worker.engine.mesh_io import Mesh, read_numbered_mesh
from worker.engine.presets import SIZE, get_preset
from worker.evaluation.compute import descriptor_vectors
from worker.evaluation.datasets import LabeledMesh, read_labels
from worker.evaluation.figures import compute_by_figure
from worker.evaluation.scoring import modality_dissimilarity
from worker.recognition import metrics


def _lengths(mesh: Mesh, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.asarray(np.linalg.norm(mesh.vertices[a] - mesh.vertices[b], axis=1))


def _pairs(labels: np.ndarray, i: np.ndarray, j: np.ndarray) -> Counter[str]:
    return Counter("-".join(sorted(p)) for p in zip(labels[i], labels[j], strict=True))


def triangulations(meshes: list[LabeledMesh]) -> None:
    print(
        "| class | files | vertices | faces | face list of the first | triangles shared "
        "(median) | shared edges' length ratio: median | 5% | 95% |"
    )
    print("|---|---:|---|---|---:|---:|---:|---:|---:|")
    for label in dict.fromkeys(m.label for m in meshes):
        files = [read_numbered_mesh(m.path) for m in meshes if m.label == label]
        first = files[0]
        own = {tuple(f) for f in np.sort(first.faces, axis=1).tolist()}
        shares, ratios = [], []
        for other in files[1:]:
            if other.n_vertices != first.n_vertices:
                continue
            theirs = {tuple(f) for f in np.sort(other.faces, axis=1).tolist()}
            common = np.array(sorted(own & theirs))
            shares.append(len(common) / len(own))
            for a, b in ((0, 1), (1, 2), (0, 2)):
                ratios.append(
                    _lengths(other, common[:, a], common[:, b])
                    / _lengths(first, common[:, a], common[:, b])
                )
        same = sum(
            f.faces.shape == first.faces.shape and np.array_equal(f.faces, first.faces)
            for f in files
        )
        vertex_counts = dict(sorted(Counter(f.n_vertices for f in files).items()))
        face_counts = dict(sorted(Counter(f.n_faces for f in files).items()))
        r = np.concatenate(ratios) if ratios else np.array([np.nan])
        print(
            f"| {label} | {len(files)} | {vertex_counts} | {face_counts} | {same} | "
            f"{100 * np.median(shares) if shares else float('nan'):.1f}% | "
            f"{np.median(r):.4f} | {np.percentile(r, 5):.3f} | {np.percentile(r, 95):.3f} |"
        )


def errors(name: str, d: np.ndarray, labels: np.ndarray) -> None:
    far, frr, thresholds = metrics.roc_curve(d, labels)
    threshold = thresholds[np.argmin(np.abs(far - frr))]
    i, j = np.triu_indices(len(d), 1)
    same = labels[i] == labels[j]
    rejected = same & (d[i, j] > threshold)
    accepted = ~same & (d[i, j] <= threshold)
    genuine = Counter(labels[i][same].tolist())
    rejects = Counter(labels[i][rejected].tolist())
    accepts = _pairs(labels, i[accepted], j[accepted])
    impostors = _pairs(labels, i[~same], j[~same])
    print(f"\n{name}: EER {100 * metrics.equal_error_rate(d, labels):.2f}%")
    print(
        "  false rejects: " + ", ".join(f"{c} {n}/{genuine[c]}" for c, n in rejects.most_common())
    )
    print(
        "  false accepts: " + ", ".join(f"{p} {n}/{impostors[p]}" for p, n in accepts.most_common())
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_evaluation_cache_arguments(parser)
    parser.set_defaults(preset="smeets2010-tosca")
    args = parser.parse_args()
    meshes = read_labels(TOSCA / "labels.csv", TOSCA)
    print("## Triangulations of TOSCA's poses\n")
    triangulations(meshes)

    preset = get_preset(args.preset)
    computed, about = compute_by_figure(meshes, preset, args.cache, jobs=args.jobs)
    print(f"\n## {preset.name} v{preset.version}, one resampling per figure")
    print(f"resampled on their own: {', '.join(about['resampled_on_their_own'])}")
    labels = np.array([m.label for m in computed.meshes])
    vectors = descriptor_vectors(computed, size=True)
    per = {m: modality_dissimilarity(vectors[m], preset.dissimilarity)[0] for m in ("gdm", "ddt")}
    errors("GDM", per["gdm"], labels)
    errors("DDT", per["ddt"], labels)
    fused = fuse(per, preset.fusion, {m: preset.weight(m) for m in per})
    errors(f"GDM+DDT {preset.fusion}", fused, labels)
    print("\n| class | GDM's largest singular value: CV | size sqrt(A): CV |")
    print("|---|---:|---:|")
    for c in dict.fromkeys(labels):
        spreads = [v[labels == c, 0] for v in (vectors["gdm"], vectors[SIZE])]
        print(f"| {c} | " + " | ".join(f"{100 * x.std() / x.mean():.2f}%" for x in spreads) + " |")


if __name__ == "__main__":
    main()
