"""Accuracy experiments on TOSCA: what limits each modality, and weighted fusion.

    python -m experiments.tosca_experiments [--cache .cache/experiments] [--n 2500]

Stage 1 caches, per mesh, the expensive intermediates of the default pipeline
(resampled mesh, GDM, 150 eigenpairs of eq. 3, vertex areas). Stage 2 varies only
the cheap parts (k, core size, spectrum size, dissimilarity, fusion weights) and
prints one table row per variant: NN, R1RR (first-instance gallery), EER, first
tier and mAP, all on the 83 meshes. Weighted fusion is scored by class-stratified
5-fold cross-validation: weights are chosen on the pairs of four folds and the EER
is measured on the pairs of the fifth, so no weight ever sees its test pairs.
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import REPO, TOSCA, tosca_labels
from worker.engine.compare import dissimilarity, fuse
from worker.engine.diffusion import (
    LaplaceBeltrami,
    laplace_beltrami_eigenpairs,
    normalized_spectrum,
)
from worker.engine.geodesic import geodesic_distance_matrix
from worker.engine.intrinsic import IntrinsicMesh, fem_operators, intrinsic_delaunay
from worker.engine.mesh_io import load_mesh
from worker.engine.modal import ddt_core, modal_gdm
from worker.engine.presets import get_preset
from worker.engine.resample import resample_mesh
from worker.recognition import metrics

CACHE = REPO / ".cache" / "experiments"
WEIGHTS = (0.0, 0.25, 0.5, 1.0)


def cache_intermediates(cache: Path, n: int) -> list[dict[str, Any]]:
    preset = get_preset("smeets2010-shrec")
    labels = tosca_labels()
    out = []
    cache.mkdir(parents=True, exist_ok=True)
    for name in sorted(labels, key=metrics.natural_sort_key):
        path = cache / f"{name.split('.')[0]}-n{n}.npz"
        if not path.exists():
            mesh = resample_mesh(load_mesh(TOSCA / name), n)
            intrinsic = intrinsic_delaunay(IntrinsicMesh.from_mesh(mesh.vertices, mesh.faces))
            ops = fem_operators(intrinsic)
            op = LaplaceBeltrami.from_fem(ops)
            values, vectors = laplace_beltrami_eigenpairs(op, preset.n_eigenpairs)
            extrinsic = LaplaceBeltrami.from_fem(
                fem_operators(IntrinsicMesh.from_mesh(mesh.vertices, mesh.faces))
            )
            raw_values, _ = laplace_beltrami_eigenpairs(extrinsic, 51)
            np.savez(
                path,
                gdm=geodesic_distance_matrix(intrinsic, ops).astype(np.float32),
                values=values,
                vectors=vectors,
                spectrum=normalized_spectrum(op, values, 149),
                spectrum_no_flips=normalized_spectrum(extrinsic, raw_values, 50),
            )
        data = dict(np.load(path))
        data["name"], data["label"] = name, labels[name]
        out.append(data)
    return out


def all_to_all(x: np.ndarray, kind: str) -> np.ndarray:
    """(n, n) ``kind`` dissimilarity of n descriptors (any shape per object), sigma over all n."""
    x = x.reshape(len(x), -1)
    return dissimilarity(x, x, kind)


def scores(dis: np.ndarray, names: list[str], labels: np.ndarray) -> dict[str, float]:
    gallery, probes = metrics.first_instance_split(names, labels)
    retrieval = metrics.retrieval_scores(dis, labels)
    return {
        "nn": retrieval["nn"],
        "r1rr": metrics.rank1_rate(dis, labels, gallery, probes),
        "eer": metrics.equal_error_rate(dis, labels),
        "ft": retrieval["first_tier"],
        "map": retrieval["map"],
    }


def row(name: str, s: dict[str, float]) -> str:
    return (
        f"| {name} | {s['nn']:.1%} | {s['r1rr']:.1%} | {s['eer']:.2%} | "
        f"{s['ft']:.1%} | {s['map']:.1%} |"
    )


def stratified_folds(labels: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """The folds this experiment's recorded table was made with: every class dealt out
    from fold 0 (:func:`worker.recognition.fusion.stratified_folds`, which ``shapes tune``
    uses, starts each class at a random fold, so small classes do not pile up in fold 0)."""
    rng = np.random.default_rng(seed)
    fold = np.empty(len(labels), dtype=int)
    for c in np.unique(labels):
        idx = rng.permutation(np.flatnonzero(labels == c))
        fold[idx] = np.arange(len(idx)) % k
    return fold


def cross_validated_fusion(
    mats: dict[str, np.ndarray], labels: np.ndarray, rule: str, k: int = 5
) -> tuple[float, list[dict[str, float]]]:
    """Mean test-fold EER with weights chosen on the training folds, and the weights."""
    fold = stratified_folds(labels, k)
    names = list(mats)
    test_eers, chosen = [], []
    for f in range(k):
        train, test = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        best: tuple[float, dict[str, float]] | None = None
        for w in itertools.product(WEIGHTS, repeat=len(names) - 1):
            weights = dict(zip(names, (*w, 1.0), strict=True))
            if not any(weights.values()):
                continue
            fused = fuse({m: d[np.ix_(train, train)] for m, d in mats.items()}, rule, weights)
            eer = metrics.equal_error_rate(fused, labels[train])
            if best is None or eer < best[0]:
                best = (eer, weights)
        assert best is not None  # the grid holds combinations that are not all zero
        fused = fuse({m: d[np.ix_(test, test)] for m, d in mats.items()}, rule, best[1])
        test_eers.append(metrics.equal_error_rate(fused, labels[test]))
        chosen.append(best[1])
    return float(np.mean(test_eers)), chosen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, default=CACHE)
    parser.add_argument("--n", type=int, default=2500)
    args = parser.parse_args()
    preset = get_preset("smeets2010-shrec")
    data = cache_intermediates(args.cache, args.n)
    names = [d["name"] for d in data]
    labels = np.array([d["label"] for d in data])
    times = preset.diffusion_times

    gdm40 = np.array([modal_gdm(d["gdm"].astype(np.float64), 40) for d in data])
    core = {
        shape: np.array([ddt_core(d["values"], d["vectors"], times, shape) for d in data])
        for shape in ((10, 10, 5), (20, 20, 5), (30, 30, 5), (20, 20, 3))
    }
    spectrum = np.array([d["spectrum"] for d in data])
    print("| variant | NN | R1RR | EER | FT | mAP |\n|---|---|---|---|---|---|")
    for kind in ("D1", "D2"):
        for k in (5, 10, 19, 30, 40):
            print(row(f"GDM k={k}, {kind}", scores(all_to_all(gdm40[:, :k], kind), names, labels)))
        for shape, cores in core.items():
            label = "x".join(map(str, shape))
            print(row(f"DDT core {label}, {kind}", scores(all_to_all(cores, kind), names, labels)))
        for size in (10, 20, 50, 100, 149):
            print(
                row(
                    f"spectrum {size}, {kind}",
                    scores(all_to_all(spectrum[:, :size], kind), names, labels),
                )
            )
    raw = np.array([d["spectrum_no_flips"] for d in data])
    print(
        row(
            "spectrum 50, D1, cotan L of the decimated triangles (no intrinsic flips)",
            scores(all_to_all(raw, "D1"), names, labels),
        )
    )

    mats = {
        "gdm": all_to_all(gdm40[:, :19], "D1"),
        "ddt": all_to_all(core[(20, 20, 5)], "D1"),
        "spectrum": all_to_all(spectrum[:, :50], "D1"),
    }
    print(
        "\nFusion (D1 per modality)\n\n"
        "| fusion | NN | R1RR | EER | FT | mAP |\n|---|---|---|---|---|---|"
    )
    for rule in ("sum", "product"):
        for combo in (("gdm", "ddt"), ("gdm", "ddt", "spectrum"), ("gdm", "spectrum")):
            fused = fuse({m: mats[m] for m in combo}, rule)
            print(row(f"{' + '.join(combo)}, {rule}, equal weights", scores(fused, names, labels)))
    print(
        "\nWeighted fusion, weights by class-stratified 5-fold cross-validation (grid "
        f"{WEIGHTS} for gdm and ddt, spectrum weight 1)\n"
    )
    print("| rule | mean test-fold EER | weights chosen per fold |\n|---|---|---|")
    for rule in ("sum", "product"):
        eer, chosen = cross_validated_fusion(mats, labels, rule)
        shown = "; ".join(f"gdm {w['gdm']}, ddt {w['ddt']}" for w in chosen)
        print(f"| {rule} | {eer:.2%} | {shown} |")
    only = {"spectrum": mats["spectrum"]}
    eer, _ = cross_validated_fusion(only, labels, "sum")
    print(f"| spectrum alone (same folds) | {eer:.2%} | - |")


if __name__ == "__main__":
    main()
