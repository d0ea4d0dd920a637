"""How much of its whole each partial copy keeps, and what the preset finds by that share.

    python -m experiments.kept_share [--variants shrec-holes view] [--jobs 2] [--cache CACHE]

For every TOSCA file and SCAPE pose, each partial copy the partiality protocol makes
(:func:`worker.evaluation.variants.make_variant`, seeded as there) is measured as the
service reads it (a range scan without its shortcuts,
:func:`worker.engine.pipeline.without_grid_shortcuts`) and before its random similarity
(``range``, ``shrec-holes``): its area over its whole's. The copies' descriptors are read
from the evaluation cache (``shapes partiality`` fills it) and ranked by the preset's
score as the protocol ranks them (:func:`.partiality.query_matrices`): own class at rank
1 against the wholes, and SHREC'17's nearest neighbour all to all among the variant's
copies, both by band of the kept share.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from benchmarks.common import (
    add_evaluation_cache_arguments,
    drawn_variant,
    evaluated_partiality_wholes,
    partiality_copies,
)
from worker.engine.errors import MeshError
from worker.engine.mesh_io import Mesh, face_areas, load_mesh
from worker.engine.pipeline import without_grid_shortcuts
from worker.evaluation import partial
from worker.evaluation.partiality import query_matrices, ranked_last, ranking_scores
from worker.evaluation.robustness import PRESET_ROW
from worker.evaluation.variants import make_variant
from worker.recognition.metrics import retrieval_scores

#: Upper edges of the kept-share bands the table gives.
BANDS = (0.1, 0.3, 0.5, 1.0)


def area(mesh: Mesh) -> float:
    """The area of ``mesh`` as the service reads it."""
    read = without_grid_shortcuts(mesh).mesh
    return float(face_areas(read.vertices, read.faces).sum())


@contextmanager
def areas_before_similarity(seen: list[float]) -> Iterator[None]:
    """Record the area of each mesh :func:`.partial.similarity` is given (the copy in its
    whole's units) while the variants are made."""
    moved: Callable[[Mesh, np.random.Generator], Mesh] = partial.similarity

    def recorded(mesh: Mesh, rng: np.random.Generator) -> Mesh:
        seen.append(area(mesh))
        return moved(mesh, rng)

    setattr(partial, "similarity", recorded)  # noqa: B010 (mypy will not let a function be assigned)
    try:
        yield
    finally:
        setattr(partial, "similarity", moved)  # noqa: B010


def kept_shares(variant: str, meshes: dict[str, Mesh]) -> dict[str, float]:
    """File name -> the share of its whole's area the variant's copy keeps."""
    shares = {}
    for name, mesh in meshes.items():
        seen: list[float] = []
        with areas_before_similarity(seen):
            try:
                copy = make_variant(mesh, drawn_variant(variant, name), name)
            except MeshError:  # eroded whole (shrec-holes): left out
                continue
        whole = float(face_areas(mesh.vertices, mesh.faces).sum())
        shares[name] = (seen[0] if seen else area(copy)) / whole
    return shares


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", nargs="+", default=["shrec-holes", "view"])
    add_evaluation_cache_arguments(parser)  # the partiality run's cache
    args = parser.parse_args()
    preset, wholes = evaluated_partiality_wholes(args)
    labels = np.array([m.label for m in wholes.meshes])
    index = {m.name: i for i, m in enumerate(wholes.meshes)}
    meshes = {m.name: load_mesh(m.path) for m in wholes.meshes}
    print("| variant | kept share | copies | own class at rank 1 | all to all NN |")
    print("|---|---|---:|---:|---:|")
    for variant in args.variants:
        shares = kept_shares(variant, meshes)
        done = partiality_copies(variant, preset, args.cache, args.jobs)
        sources = np.array([index[m.name] for m in done.meshes])
        kept = np.array([shares[m.name] for m in done.meshes])
        against = query_matrices(done.descriptors, wholes.descriptors, preset, jobs=args.jobs)
        ranked = against[PRESET_ROW]
        among = query_matrices(
            done.descriptors, done.descriptors, preset, jobs=args.jobs, themselves=True
        )
        ranking = ranked_last(among[PRESET_ROW])
        lower = 0.0
        for upper in BANDS:
            band = np.flatnonzero((kept >= lower) & (kept < upper + (upper == 1.0)))
            nn = retrieval_scores(ranking, labels[sources], band)["nn"] if len(band) else np.nan
            hits = (
                ranking_scores(ranked[band], sources[band], labels)["own_class"]
                if len(band)
                else np.nan
            )
            print(
                f"| {variant} | {lower:.1f}-{upper:.1f} | {len(band)} | {100 * hits:.1f}% | "
                f"{100 * nn:.1f}% |"
            )
            lower = upper
        nn = retrieval_scores(ranking, labels[sources])["nn"]
        print(
            f"| {variant} | all (median {np.median(kept):.3f}) | {len(kept)} | "
            f"{100 * ranking_scores(ranked, sources, labels)['own_class']:.1f}% | {100 * nn:.1f}% |"
        )


if __name__ == "__main__":
    main()
