"""Which partial copies the service calls one view: their ``facing_share``.

    python -m experiments.view_facing [--variants view range cut-30] [--every 1]

A query is one view of its object when the largest share of its area facing one
direction (:func:`worker.engine.holes.facing_share`) is at least
:data:`~worker.engine.descriptor.ONE_VIEW_FACING`. For every TOSCA and SCAPE file (every
``--every``-th), the file itself and each partial copy the partiality protocol makes of it
(:func:`worker.evaluation.variants.make_variant`, seeded as there): per variant, the
copies made, the smallest, median and largest share, and how many are called one view.
Each is measured as the service measures it: a range scan written as a grid without its
shortcuts (:func:`worker.engine.pipeline.without_grid_shortcuts`).
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.common import SCAPE, TOSCA, drawn_variant
from worker.engine.descriptor import ONE_VIEW_FACING
from worker.engine.errors import MeshError
from worker.engine.holes import facing_share
from worker.engine.mesh_io import load_mesh
from worker.engine.pipeline import without_grid_shortcuts
from worker.evaluation.partial import PARTIAL_VARIANTS
from worker.evaluation.variants import make_variant

WHOLE = "whole"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", nargs="+", default=list(PARTIAL_VARIANTS))
    parser.add_argument("--every", type=int, default=1)
    args = parser.parse_args()
    files = sorted(TOSCA.glob("*.off.gz")) + sorted(SCAPE.glob("*.off.gz"))
    shares: dict[str, list[float]] = {v: [] for v in (WHOLE, *args.variants)}
    for path in files[:: args.every]:
        mesh = load_mesh(path)
        shares[WHOLE].append(facing_share(mesh))
        for variant in args.variants:
            try:
                copy = make_variant(mesh, drawn_variant(variant, path.name), path.name)
            except MeshError:  # eroded whole (shrec-holes): the protocol leaves it out
                continue
            shares[variant].append(facing_share(without_grid_shortcuts(copy).mesh))
    print("| copies | made | smallest | median | largest | called one view |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, values in shares.items():
        s = np.array(values)
        print(
            f"| {name} | {len(s)} | {s.min():.3f} | {np.median(s):.3f} | {s.max():.3f} | "
            f"{int((s >= ONE_VIEW_FACING).sum())} |"
        )


if __name__ == "__main__":
    main()
