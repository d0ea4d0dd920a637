"""Rigid verification of a single view's shortlist (:mod:`worker.engine.rigid`).

    python -m experiments.rigid_verification [--variants view range] [--shortlist 10]
        [--ranking preset] [--voxel 0.02] [--window 1.5] [--jobs 2]

The partiality protocol's copies of TOSCA and SCAPE (:func:`make_variant`, seeded as
there) query the 154 whole meshes by the preset's score (``shapes partiality``'s preset
row, from the evaluation cache) or, with ``--ranking parts``, by the parts modality's
alone. The best ``--shortlist`` of each are then verified rigidly: the copy's vertices
and normals brought to each candidate's unit (the square root of its area) by the scale
the parts modality chose for the copy (``1 / s`` of a two-sided view's unit,
:mod:`worker.engine.parts`), both anchored at ``--voxel`` of that unit, and fitted within
``--window`` of that scale (:func:`worker.engine.rigid.rigid_fit`). The candidate
holding most of the copy comes first.

Per variant: own class and own source at rank 1 by the ranking and after verification,
with the copy's source in the gallery and left out of its shortlist (then only the other
poses of its class can find it; the parts' scale is still chosen over every whole), and
the share of queries whose source was shortlisted.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import trimesh

from benchmarks.common import drawn_variant, partiality_copies, partiality_wholes
from worker.engine.mesh_io import Mesh, load_mesh
from worker.engine.parts import compared_profiles, part_dissimilarity
from worker.engine.presets import PARTS, get_preset
from worker.engine.rigid import Anchors, rigid_fit, surface_anchors
from worker.evaluation.compute import compute_descriptors, single_threaded_blas
from worker.evaluation.datasets import DEFAULT_CACHE
from worker.evaluation.partiality import query_matrices
from worker.evaluation.robustness import PRESET_ROW
from worker.evaluation.variants import make_variant

PRESET = "smeets2010-surface"


def surface_normals(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """A mesh's vertices and area-weighted vertex normals (its faces' winding)."""
    shape = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    return np.asarray(mesh.vertices), np.asarray(shape.vertex_normals)


_WHOLES: list[Mesh] = []
_ANCHORED: dict[int, tuple[float, Anchors]] = {}


def _hold(wholes: list[Mesh]) -> None:
    single_threaded_blas()
    _WHOLES[:] = wholes


def anchored(c: int, voxel: float) -> tuple[float, Anchors]:
    """Whole ``c``'s unit and anchors at ``voxel`` of it (once per process)."""
    if c not in _ANCHORED:
        whole = _WHOLES[c]
        unit = float(np.sqrt(trimesh.Trimesh(whole.vertices, whole.faces).area))
        _ANCHORED[c] = unit, surface_anchors(*surface_normals(whole), voxel * unit)
    return _ANCHORED[c]


def verify(
    copy: Mesh, query_unit: float, candidates: np.ndarray, voxel: float, window: float
) -> np.ndarray:
    """(k,) the fitness of ``copy`` on each candidate (indices into the held wholes), the
    copy taken at ``query_unit`` of each candidate's unit."""
    points, normals = surface_normals(copy)
    fitness = []
    for c in candidates:
        unit, held = anchored(int(c), voxel)
        query = surface_anchors(points * unit / query_unit, normals, voxel * unit)
        fitness.append(rigid_fit(query, held, voxel * unit, (1 / window, window)).fitness)
    return np.array(fitness)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", nargs="+", default=["view", "range"])
    parser.add_argument("--shortlist", type=int, default=10)
    parser.add_argument("--ranking", choices=["preset", "parts"], default="preset")
    parser.add_argument("--voxel", type=float, default=0.02)
    parser.add_argument("--window", type=float, default=1.5)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    preset = get_preset(PRESET)
    meshes = partiality_wholes()
    cache = DEFAULT_CACHE
    computed = compute_descriptors(meshes, preset, cache, jobs=args.jobs, progress=False)
    labels = np.array([m.label for m in computed.meshes])
    index = {m.name: i for i, m in enumerate(computed.meshes)}
    wholes = [load_mesh(m.path) for m in computed.meshes]
    gallery = compared_profiles(
        np.stack([d.parts.astype(np.float64) for d in computed.descriptors]), preset
    )
    print(
        "| copies | queries | source shortlisted | own class: ranked | verified "
        "| own source: ranked | verified | source left out, own class: ranked | verified |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for variant in args.variants:
        done = partiality_copies(variant, preset, cache, args.jobs)
        sources = np.array([index[m.name] for m in done.meshes])
        score = query_matrices(done.descriptors, computed.descriptors, preset, jobs=args.jobs)
        d = score[PRESET_ROW if args.ranking == "preset" else PARTS]
        copies, units, candidates = [], [], []
        for q, (m, desc) in enumerate(zip(done.meshes, done.descriptors, strict=True)):
            copies.append(make_variant(wholes[sources[q]], drawn_variant(variant, m.name), m.name))
            scale = part_dissimilarity(
                desc.parts.astype(np.float64), desc.parts_reach, gallery, preset
            ).scale
            assert desc.area is not None, "the preset records each shape's size"
            sides = 2.0 if desc.single_view else 1.0  # a view's parts are two-sided
            units.append(float(np.sqrt(sides * desc.area)) * scale)
            # one more than the shortlist: the shortlist with the source left out, too
            candidates.append(np.argsort(d[q], kind="stable")[: args.shortlist + 1])
        n = len(copies)
        with ProcessPoolExecutor(args.jobs, initializer=_hold, initargs=(wholes,)) as pool:
            fits = list(
                pool.map(verify, copies, units, candidates, [args.voxel] * n, [args.window] * n)
            )
        first, verified, first_out, verified_out = (np.empty(n, dtype=np.int64) for _ in range(4))
        listed = np.zeros(n, dtype=bool)
        for q in range(n):
            kept = np.arange(args.shortlist)
            out = np.flatnonzero(candidates[q] != sources[q])[: args.shortlist]
            listed[q] = sources[q] in candidates[q][kept]
            first[q], first_out[q] = candidates[q][kept[0]], candidates[q][out[0]]
            verified[q] = candidates[q][kept[np.argmax(fits[q][kept])]]
            verified_out[q] = candidates[q][out[np.argmax(fits[q][out])]]
        own = labels[sources]
        cells = [
            100 * np.mean(labels[first] == own),
            100 * np.mean(labels[verified] == own),
            100 * np.mean(first == sources),
            100 * np.mean(verified == sources),
            100 * np.mean(labels[first_out] == own),
            100 * np.mean(labels[verified_out] == own),
        ]
        print(
            f"| {variant} | {n} | {100 * listed.mean():.1f} | "
            + " | ".join(f"{c:.1f}" for c in cells)
            + " |"
        )


if __name__ == "__main__":
    main()
