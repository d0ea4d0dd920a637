"""Partial-query search: the index's two passes against the exhaustive ranking, and latency.

    python -m benchmarks.partial_search [--variant cut-15] [--sizes 1000 10000] [--queries 20]

A query that looks partial is ranked with the parts modality
(:meth:`app.gallery.index.GalleryIndex.partial_search`: a coarse pass over every shape,
every sample only for a shortlist). On TOSCA (its wholes enrolled, each whole's
``--variant`` copy a query, through the evaluation cache of ``shapes partiality``): how
often its top 1 and top 10 are the exhaustive ranking's (every sample of every shape,
:func:`worker.engine.parts.part_dissimilarity`, at the query's weights), and the
latency of both. Then galleries of ``--sizes`` shapes (TOSCA's wholes repeated, each
copy's profiles and vectors perturbed by 2 % noise): the partial search's latency beside
a whole query's (``GalleryIndex.search``) on the same index, and the memory the parts
profiles take. One query at a time, one BLAS thread, after a warm-up query.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from app.gallery.index import GalleryIndex
from app.gallery.service import descriptor_vectors, flat_vectors
from benchmarks.common import TOSCA, add_evaluation_cache_arguments
from worker.engine.compare import fuse, partiality, query_weights
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.presets import PARTS, Preset, get_preset
from worker.evaluation.compute import compute_descriptors
from worker.evaluation.datasets import read_labels
from worker.evaluation.partiality import query_matrices


def weights_of(query: ShapeDescriptor, preset: Preset) -> dict[str, float]:
    """The query's weights, as the service gives them, with the parts at least at 1/2 (a
    query of the benchmark is ranked as a part even where the preset would not)."""
    share = partiality(query.longest_open_loop, query.kept_area_fraction, preset)
    return query_weights(preset, max(share, 0.5))


def exhaustive(
    query: ShapeDescriptor, wholes: Sequence[ShapeDescriptor], preset: Preset
) -> np.ndarray:
    """(n,) the fused product over every sample of every whole."""
    weights = weights_of(query, preset)
    per = query_matrices([query], wholes, preset)
    return np.asarray(fuse({m: per[m][0] for m in weights}, "product", weights))


def index_of(preset: Preset, vectors: list[dict[str, np.ndarray]]) -> GalleryIndex:
    index = GalleryIndex(preset, preset.modality_sizes(), parts_shape=preset.parts_shape())
    index.add_many(enumerate(vectors))
    return index


def seconds_of(index: GalleryIndex, query: ShapeDescriptor, preset: Preset) -> tuple[float, float]:
    """A whole query's and a partial query's search time, each after a warm-up."""
    flat = flat_vectors(query, preset)
    profiles, reach = query.parts.astype(np.float64), query.parts_reach
    weights = weights_of(query, preset)
    out = []
    for search in (
        lambda: index.search(flat, 10),
        lambda: index.partial_search(flat, profiles, reach, weights, 10),
    ):
        search()
        start = time.perf_counter()
        search()
        out.append(time.perf_counter() - start)
    return out[0], out[1]


def p95(values: list[float]) -> float:
    return float(np.quantile(values, 0.95))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_evaluation_cache_arguments(parser)
    parser.add_argument("--variant", default="cut-15")
    parser.add_argument("--sizes", type=int, nargs="*", default=[1000, 10_000])
    parser.add_argument("--queries", type=int, default=20)
    args = parser.parse_args(argv)
    preset = get_preset(args.preset)
    meshes = read_labels(TOSCA / "labels.csv", TOSCA)
    wholes = compute_descriptors(meshes, preset, args.cache, jobs=args.jobs, progress=False)
    copies = compute_descriptors(
        wholes.meshes, preset, args.cache, jobs=args.jobs, progress=False, variant=args.variant
    )
    vectors = [descriptor_vectors(d, preset) for d in wholes.descriptors]
    with threadpool_limits(1):
        index = index_of(preset, vectors)
        top1, top10 = 0, 0.0
        fast, slow = [], []
        for query in copies.descriptors:
            weights = weights_of(query, preset)
            flat = flat_vectors(query, preset)
            start = time.perf_counter()
            want = exhaustive(query, wholes.descriptors, preset)
            slow.append(time.perf_counter() - start)
            start = time.perf_counter()
            found, _ = index.partial_search(
                flat, query.parts.astype(np.float64), query.parts_reach, weights, 10
            )
            fast.append(time.perf_counter() - start)
            order = np.argsort(want, kind="stable")[:10]
            top1 += found[0].id == order[0]
            top10 += len({m.id for m in found} & set(order.tolist())) / 10
        n = len(copies.meshes)
        print(f"TOSCA, {n} {args.variant} copies against {len(vectors)} wholes")
        print("| search | top 1 as exhaustive | top 10 as exhaustive | median s | p95 s |")
        print("|---|---:|---:|---:|---:|")
        print(f"| exhaustive | 100% | 100% | {statistics.median(slow):.3f} | {p95(slow):.3f} |")
        print(
            f"| two passes | {100 * top1 / n:.1f}% | {100 * top10 / n:.1f}% | "
            f"{statistics.median(fast):.3f} | {p95(fast):.3f} |"
        )
        rng = np.random.default_rng(0)
        queries = rng.choice(n, size=min(args.queries, n), replace=False)
        print(
            "\n| shapes | parts MB | whole query median s | p95 s | partial query median s "
            "| p95 s | partial / whole (median) |"
        )
        print("|---:|---:|---:|---:|---:|---:|---:|")
        for size in args.sizes:
            grown = []
            for i in range(size):
                base = vectors[i % len(vectors)]
                grown.append(
                    {
                        k: v + 0.02 * rng.normal(size=v.shape)
                        if k == PARTS
                        else v * np.exp(0.02 * rng.normal(size=v.shape))
                        for k, v in base.items()
                    }
                )
            big = index_of(preset, grown)
            whole_s, part_s = zip(
                *(seconds_of(big, copies.descriptors[q], preset) for q in queries), strict=True
            )
            mb = big.store.parts[:size].nbytes / 2**20
            print(
                f"| {size:,} | {mb:,.0f} | {statistics.median(whole_s):.4f} "
                f"| {p95(list(whole_s)):.4f} "
                f"| {statistics.median(part_s):.3f} | {p95(list(part_s)):.3f} "
                f"| {statistics.median(part_s) / statistics.median(whole_s):.0f}x |"
            )


if __name__ == "__main__":
    main()
