"""How much of the default's remaining TOSCA error is the size it throws away.

    python -m experiments.size_cue [--preset smeets2010-surface] [--cache DIR] [--jobs 2]

Every descriptor of the service is scale-free (a file in millimetres and the same
file in metres must answer the same; the robustness protocol rescales by up to
100x). TOSCA's figures of different classes also differ in size (david's surface
is about 16,000 area units, michael's 20,700, victoria's 18,000, each within 4%),
and the paper's TOSCA experiment kept that cue ("the objects have already the same
scale"). This puts the size back into the preset's own descriptors, from each
file's surface area ``A``: the spectrum as plain eigenvalues ``lambda`` (the
descriptor stores ``lambda * A``), the GDM in length units (``sigma * A^1/2``; the
descriptor stores the eigenvalues of ``M^1/2 G M^1/2 / A^3/2``), and prints the
TOSCA scores with and without it, per modality and for the preset's fused score
(the DDT has no unit: diffusion times are in units of the area). It measures a
cue, it does not propose one: a descriptor that uses size fails every rescaled copy.
Its last table shows why the scale-free score's EER stays where it is: per class, the
genuine pairs' distances, and the impostor distances between the three human figures,
over the threshold at the EER point.
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import numpy as np
from lapy import TriaMesh

from benchmarks.common import add_evaluation_cache_arguments, evaluated_tosca
from worker.engine.compare import dissimilarity, fuse
from worker.engine.mesh_io import load_mesh
from worker.engine.presets import MODALITIES, get_preset
from worker.evaluation.compute import descriptor_vectors
from worker.recognition import metrics


def surface_area(path: Path) -> float:
    mesh = load_mesh(path)
    return float(TriaMesh(mesh.vertices, mesh.faces).area())


def row(d: np.ndarray, labels: np.ndarray, names: list[str]) -> str:
    d = 0.5 * (d + d.T)
    gallery, probes = metrics.first_instance_split(names, labels)
    values = (
        metrics.nearest_neighbor_rate(d, labels),
        metrics.rank1_rate(d, labels, gallery, probes),
        metrics.equal_error_rate(d, labels),
        metrics.mean_average_precision(d, labels),
    )
    return " | ".join(f"{100 * v:.2f}" for v in values)


def false_accepts_at_eer(d: np.ndarray, labels: np.ndarray) -> Counter[tuple[str, str]]:
    """Impostor pairs accepted at the ROC point nearest FAR = FRR, by pair of classes."""
    far, frr, thresholds = metrics.roc_curve(d, labels)
    threshold = thresholds[np.argmin(np.abs(far - frr))]
    i, j = np.triu_indices(len(d), 1)
    accepted = (labels[i] != labels[j]) & (d[i, j] <= threshold)
    first, second = labels[i][accepted], labels[j][accepted]
    return Counter((min(a, b), max(a, b)) for a, b in zip(first, second, strict=True))


def spread_table(d: np.ndarray, labels: np.ndarray) -> list[str]:
    """Markdown rows: each class's genuine distances and each pair of human figures'
    impostor distances (median, extreme), in units of the ROC point nearest FAR = FRR."""
    far, frr, thresholds = metrics.roc_curve(d, labels)
    threshold = thresholds[np.argmin(np.abs(far - frr))]
    lines = ["| pairs | count | median | extreme (genuine: largest; impostor: smallest) |"]
    lines.append("|---|---:|---:|---:|")
    for c in sorted(set(labels)):
        mine = np.flatnonzero(labels == c)
        block = d[np.ix_(mine, mine)][np.triu_indices(len(mine), 1)] / threshold
        lines.append(
            f"| {c}-{c} (genuine) | {len(block)} | {np.median(block):.2f} | {block.max():.2f} |"
        )
    for a, b in (("david", "michael"), ("david", "victoria"), ("michael", "victoria")):
        block = d[np.ix_(labels == a, labels == b)].ravel() / threshold
        lines.append(
            f"| {a}-{b} (impostor) | {len(block)} | {np.median(block):.2f} | {block.min():.2f} |"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_evaluation_cache_arguments(parser)
    args = parser.parse_args()
    if get_preset(args.preset).measure != "surface":
        parser.error("the size is restored from the surface measure's normalization")
    preset, computed = evaluated_tosca(args)
    labels = np.array([m.label for m in computed.meshes])
    names = [m.name for m in computed.meshes]
    area = np.array([surface_area(m.path) for m in computed.meshes])
    vectors = {m: v for m, v in descriptor_vectors(computed).items() if m in MODALITIES}
    sized = dict(vectors)
    sized["spectrum"] = vectors["spectrum"] / area[:, None]
    sized["gdm"] = vectors["gdm"] * np.sqrt(area)[:, None]

    def matrices(v: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {m: dissimilarity(v[m], v[m], preset.dissimilarity) for m in v}

    free, with_size = matrices(vectors), matrices(sized)
    weights = {m: preset.weight(m) for m in preset.fused_modalities}
    print(f"TOSCA, {len(names)} meshes, preset {preset.name} v{preset.version}")
    print("| | scale | NN | R1RR | EER | mAP |")
    print("|---|---|---:|---:|---:|---:|")
    for title, key in (("GDM", "gdm"), ("Spectrum", "spectrum"), ("the preset's score", None)):
        for scale, mats in (("free (the service)", free), ("with size", with_size)):
            if key is None:
                d = fuse({m: mats[m] for m in preset.fused_modalities}, preset.fusion, weights)
            else:
                d = mats[key]
            print(f"| {title} | {scale} | {row(d, labels, names)} |")
    fused = fuse({m: free[m] for m in preset.fused_modalities}, preset.fusion, weights)
    accepts = false_accepts_at_eer(0.5 * (fused + fused.T), labels)
    pairs = ", ".join(f"{a}-{b} {n}" for (a, b), n in accepts.most_common())
    print(f"\nthe preset's score, scale-free: false accepts at its EER point: {pairs}")
    print("\nthe preset's score, scale-free, in units of its EER threshold:")
    print("\n".join(spread_table(0.5 * (fused + fused.T), labels)))


if __name__ == "__main__":
    main()
