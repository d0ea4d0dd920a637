"""SHREC'17's range challenge on TOSCA: many scans of every whole, each the query of all
the others, ranked by the service's partial search.

    python -m experiments.shrec_range [--copies 10] [--limit N] [--queries N] [--jobs 2]
        [--cache CACHE] [--search-only] [--exhaustive]

SHREC'17 (Rodolà et al., 3DOR 2017) shot every model 20 times (5 rotations x 4
elevations) and ranked each of its 882 range scans against all the others. The
partiality protocol's all-to-all mode does the same with exhaustive matrices (``shapes
partiality --variants range --copies N``), which grow with the square of the copies: 20
copies of 18 of TOSCA's wholes take some 46 minutes here, of all 83 some 16 hours. Here
every TOSCA whole (``--limit`` a class) is scanned ``--copies`` times as the protocol
scans it (:func:`worker.evaluation.variants.copy_name`, through the protocol's cache),
the scans are enrolled in one :class:`app.gallery.index.GalleryIndex` as the service
enrolls files, and each scan queries it as the service asks (its own weights, the parts'
two passes, ``FEATURE_POOL`` answers), itself left out, then is verified on them as the
service verifies a single view (:func:`worker.engine.rigid.verified_fitness`, each
candidate's anchors kept; ``--search-only`` leaves that out and asks the search for its
first answer only). ``--exhaustive`` also ranks them by the protocol's all-to-all
matrices (verified as well), to measure what the index's two passes change.

Printed: the class of the first answer (SHREC'17's NN), and with every scan of the
query's own whole left out as well (the same class in another pose only).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from threadpoolctl import threadpool_limits

from app.gallery.index import GalleryIndex
from app.gallery.service import descriptor_vectors, flat_vectors
from benchmarks.common import TOSCA, add_evaluation_cache_arguments
from worker.engine.compare import partiality, query_weights
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.presets import Preset, get_preset
from worker.engine.rigid import (
    FEATURE_POOL,
    Anchors,
    candidate_anchors,
    verified_fitness,
    verified_order,
)
from worker.evaluation.datasets import read_labels
from worker.evaluation.partiality import query_matrices, ranked_last
from worker.evaluation.robustness import PRESET_ROW
from worker.evaluation.run import described_copies
from worker.evaluation.variants import copy_name


def nearest_classes(d: np.ndarray, labels: np.ndarray, sources: np.ndarray) -> dict[str, float]:
    """From an all-to-all matrix (its diagonal ignored): the share of queries whose
    nearest other copy is of their class, and whose nearest copy of another whole is."""
    d = d.copy()
    np.fill_diagonal(d, np.inf)
    nn = float(np.mean(labels[np.argmin(d, axis=1)] == labels))
    d[sources[:, None] == sources[None, :]] = np.inf
    other = float(np.mean(labels[np.argmin(d, axis=1)] == labels))
    return {"nn": nn, "other_whole": other}


def answers(
    index: GalleryIndex,
    query: ShapeDescriptor,
    descriptors: list[ShapeDescriptor],
    anchors: dict[int, Anchors | None],
    left_out: list[int],
    preset: Preset,
    verify: bool,
) -> tuple[int, int | None]:
    """The first of ``query``'s partial search in ``index`` (``left_out`` excluded), and
    with ``verify`` the first once a single view is verified on the search's
    ``FEATURE_POOL`` best, as the service verifies it (``anchors``: each candidate's, kept
    across queries)."""
    share = partiality(query.longest_open_loop, query.kept_area_fraction, preset)
    found, scale = index.partial_search(
        flat_vectors(query, preset),
        query.parts.astype(np.float64),
        query.parts_reach,
        query_weights(preset, share),
        FEATURE_POOL if verify else 1,
        exclude=left_out,
    )
    ids = [m.id for m in found]
    if not verify:
        return ids[0], None
    for c in ids:
        if c not in anchors:
            anchors[c] = candidate_anchors(descriptors[c])
    candidates = [descriptors[c] for c in ids]
    kept = [anchors[c] for c in ids]
    fitness = verified_fitness(query, candidates, scale, False, kept, threads=2)
    order = np.arange(len(ids)) if fitness is None else verified_order(fitness)
    return ids[0], ids[int(order[0])]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_evaluation_cache_arguments(parser)
    parser.add_argument("--copies", type=int, default=10, help="scans of every whole")
    parser.add_argument("--limit", type=int, help="wholes a class")
    parser.add_argument(
        "--queries", type=int, help="only so many scans query (a seeded draw; all enrolled)"
    )
    parser.add_argument(
        "--search-only", action="store_true", help="no verification (minutes, not hours)"
    )
    parser.add_argument("--exhaustive", action="store_true")
    args = parser.parse_args()
    preset = get_preset(args.preset)
    wholes = read_labels(TOSCA / "labels.csv", TOSCA, per_class_limit=args.limit)
    start = time.perf_counter()
    at = {m.name: i for i, m in enumerate(wholes)}
    sources, descriptors = [], []
    for copy in range(args.copies):
        done = described_copies(wholes, copy_name("range", copy), preset, args.cache, args.jobs)
        for mesh, descriptor in zip(done.meshes, done.descriptors, strict=True):
            sources.append(at[mesh.name])
            descriptors.append(descriptor)
    labels = np.array([wholes[s].label for s in sources])
    source = np.array(sources)
    described = time.perf_counter() - start
    n = len(descriptors)
    searched: dict[str, list[int]] = {
        "the service's partial search": [],
        "then verified, as the service verifies": [],
    }
    anchors: dict[int, Anchors | None] = {}
    seconds = []
    with threadpool_limits(1):
        index = GalleryIndex(preset, preset.modality_sizes(), parts_shape=preset.parts_shape())
        index.add_many(enumerate(descriptor_vectors(d, preset) for d in descriptors))
        asking = np.arange(n)
        if args.queries is not None and args.queries < n:
            asking = np.sort(np.random.default_rng(0).choice(n, args.queries, replace=False))
        for i in asking.tolist():
            query = descriptors[i]
            begun = time.perf_counter()
            for left_out in ([i], np.flatnonzero(source == source[i]).tolist()):
                parts, verified = answers(
                    index, query, descriptors, anchors, left_out, preset, not args.search_only
                )
                searched["the service's partial search"].append(parts)
                if verified is not None:
                    searched["then verified, as the service verifies"].append(verified)
            seconds.append(time.perf_counter() - begun)
    print(
        f"TOSCA, {len(wholes)} wholes x {args.copies} range scans = {n}, {len(asking)} of them "
        f"queries (described or read in {described:.0f} s; a query's searches and fits, "
        f"median {float(np.median(seconds)):.2f} s)"
    )
    print("| ranking | NN | NN among other wholes' scans |")
    print("|---|---:|---:|")
    for name, firsts in searched.items():
        if not firsts:
            continue
        first = np.array(firsts).reshape(len(asking), 2)
        nn, other = np.mean(labels[first] == labels[asking, None], axis=0)
        print(f"| {name} | {100 * nn:.1f} | {100 * other:.1f} |")
    if args.exhaustive:
        d = query_matrices(descriptors, descriptors, preset, None, args.jobs, themselves=True)
        scores = nearest_classes(ranked_last(d[PRESET_ROW]), labels, source)
        print(
            f"| the protocol's matrices | {100 * scores['nn']:.1f} | "
            f"{100 * scores['other_whole']:.1f} |"
        )


if __name__ == "__main__":
    main()
