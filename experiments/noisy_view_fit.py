"""Whether a noisy view's rigid fit recovers when the view is smoothed first.

    OPENBLAS_NUM_THREADS=1 python -m experiments.noisy_view_fit [--every 8] [--iterations 10]

The partiality protocol's ``view-noise-0.5`` copies (``view``'s very views, depth noise
along the ray) lose the rigid fit's gain (docs/evaluation.md, "Partial queries"). For
every ``--every``-th TOSCA whole: its ``view`` copy, its ``view-noise-0.5`` copy, and that
copy smoothed by Taubin's filter (``--iterations`` steps, trimesh's defaults otherwise),
each described and fitted to its own source as the protocol fits it (the parts' scale
against the 154 wholes, :func:`worker.engine.rigid.verified_fitness`): the surface's
area, the parts' scale and the fitness.
"""

from __future__ import annotations

import argparse

import numpy as np
import trimesh

from benchmarks.common import add_evaluation_cache_arguments, evaluated_partiality_wholes
from worker.engine.mesh_io import Mesh, face_areas, load_mesh
from worker.engine.pipeline import describe_mesh
from worker.engine.rigid import HELD_FITNESS, verified_fitness, whole_anchors
from worker.evaluation.partiality import unverified_matrices
from worker.evaluation.variants import make_variant

NOISY = "view-noise-0.5"
TOSCA_WHOLES = 83  # the protocol's first wholes; SCAPE's poses follow


def taubin(mesh: Mesh, iterations: int) -> Mesh:
    """``mesh`` smoothed by Taubin's filter, its faces kept."""
    smoothed = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    # no-untyped-call: trimesh's smoothing filters carry no annotations.
    trimesh.smoothing.filter_taubin(smoothed, iterations=iterations)  # type: ignore[no-untyped-call]
    return Mesh(np.asarray(smoothed.vertices), mesh.faces)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=int, default=8)
    parser.add_argument("--iterations", type=int, default=10)
    add_evaluation_cache_arguments(parser)  # the partiality run's cache
    args = parser.parse_args()
    preset, wholes = evaluated_partiality_wholes(args)
    print("| whole | copy | area | parts' scale | fitness to its source |")
    print("|---|---|---:|---:|---:|")
    fits: dict[str, list[float]] = {}
    for index in range(0, TOSCA_WHOLES, args.every):
        whole = wholes.meshes[index]
        source = wholes.descriptors[index]
        anchors = whole_anchors(source)  # one per whole, for its three copies
        mesh = load_mesh(whole.path)
        copies = {
            "view": make_variant(mesh, "view", whole.name),
            NOISY: make_variant(mesh, NOISY, whole.name),
        }
        copies[f"{NOISY}, smoothed"] = taubin(copies[NOISY], args.iterations)
        for copy, surface in copies.items():
            described = describe_mesh(surface, preset)
            scale = float(unverified_matrices([described], wholes.descriptors, preset)[1][0])
            fitness = verified_fitness(described, [source], scale, False, [anchors])
            assert fitness is not None  # a single view with its surface
            fits.setdefault(copy, []).append(float(fitness[0]))
            area = float(face_areas(surface.vertices, surface.faces).sum())
            print(f"| {whole.name} | {copy} | {area:.0f} | {scale:.2f} | {fitness[0]:.2f} |")
    for copy, values in fits.items():
        held = np.mean(np.array(values) >= HELD_FITNESS)
        median = np.median(values)
        print(f"{copy}: median fitness {median:.2f}, held at {HELD_FITNESS}: {100 * held:.0f}%")


if __name__ == "__main__":
    main()
