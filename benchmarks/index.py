"""Index benchmark: recall@10 against the exhaustive fused ranking, and search latency.

    python -m benchmarks.index                        # TOSCA + 1k/10k/100k synthetic
    python -m benchmarks.index --sizes 1000 10000     # fewer sizes
    python -m benchmarks.index --tosca-presets --sizes 1000000 --queries 100
    python -m benchmarks.index --tosca-presets --sizes 100000 --collections 10

* TOSCA: every mesh is a query against the other 82 (leave-one-out), under the
  default preset and any other ``--tosca-presets``.
* Synthetic: descriptors shaped like real ones (below), N enrolled, 200 fresh
  queries from the same classes.

The reference ranking is the exhaustive one computed with ``worker.engine.compare``
alone (``gallery_sigma`` over the whole gallery, eq. 8/9, ``fuse``), not with
the index's code. Latency is the search step alone (``GalleryIndex.search``),
one query at a time, after one warm-up query. "index MB" is the growth of the
process's resident memory while the index was built (vectors, transformed rows,
faiss); "build s" adds every shape and fits once, "refit s" is one more refit
(what searches wait for after 5 % churn).

With ``--collections C``, each size is also enrolled spread over C indexes (whole
classes each: the service keeps one index per collection, ``app.galleries``, and
a search ranks its own collection only), and every query is searched in its own
collection's index too, interleaved with the one gallery's query by query, so that the
machine's load falls on both alike; recall@10 is against the exhaustive ranking of the
collection.

Synthetic descriptors: every modality is modelled in log space from the real
TOSCA descriptors. A synthetic class centre is the real mean plus a random
combination of the real class-mean deviations plus independent per-element
noise (30 % of the real between-class spread); a member is its centre plus a
random combination of the real within-class residuals (a pose change). So
per-element scales, correlations and the within/between-class ratio follow the
real data. Classes have 10 members.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np

from app.gallery.index import GalleryIndex, SearchStats
from benchmarks.common import (
    Vectors,
    resident_mb,
    synthetic,
    synthetic_model,
    tosca_descriptors,
)
from worker.engine.compare import dissimilarity, fuse, gallery_sigma
from worker.engine.presets import DEFAULT_PRESET, MODALITIES, Preset, get_preset

K = 10
#: Modality -> (N, M) float descriptors of a gallery, or -> (M,) of one query.
#: A table row: what :func:`measure` measured, and ``data`` (what was searched).
Row = dict[str, Any]


def exhaustive_topk(
    preset: Preset, gallery: Vectors, sigma: Vectors | None, queries: list[Vectors], k: int
) -> np.ndarray:
    """(p, k) positions of the best gallery rows per query by the exact fused score,
    computed with ``worker.engine.compare`` alone over the whole gallery."""
    per = {}
    for m in preset.fused_modalities:
        q = np.stack([query[m] for query in queries])
        scale = None if sigma is None else sigma[m]
        per[m] = dissimilarity(q, gallery[m], preset.dissimilarity, scale)
    fused = fuse(per, preset.fusion, {m: preset.weight(m) for m in preset.fused_modalities})
    n = fused.shape[1]
    return np.stack([np.lexsort((np.arange(n), row))[:k] for row in fused])


def build(preset: Preset, gallery: Vectors, ids: np.ndarray) -> GalleryIndex:
    index = GalleryIndex(preset, preset.modality_sizes())
    index.add_many((int(i), {m: gallery[m][j] for m in MODALITIES}) for j, i in enumerate(ids))
    return index


def measure(
    preset: Preset,
    gallery: Vectors,
    queries: list[Vectors],
    exclude: list[tuple[int, ...]] | None = None,
) -> Row:
    """recall@K, latency percentiles (ms), mean candidates and certified fraction."""
    n = len(next(iter(gallery.values())))
    ids = np.arange(n, dtype=np.int64)
    before = resident_mb()
    started = time.perf_counter()
    index = build(preset, gallery, ids)
    build_seconds = time.perf_counter() - started
    index_mb = resident_mb() - before
    started = time.perf_counter()
    index.refit()  # what a refit after 5 % churn costs (searches wait for it)
    refit_seconds = time.perf_counter() - started
    sigma = (
        {m: gallery_sigma(gallery[m]) for m in MODALITIES} if preset.dissimilarity == "D2" else None
    )
    index.search(queries[0], K)  # warm-up
    hits = total = 0
    results: list[set[int]] = []
    times, candidates, scored, certified = [], [], [], 0
    for qi, query in enumerate(queries):
        excluded = exclude[qi] if exclude else ()
        stats = SearchStats()
        start = time.perf_counter()
        found = index.search(query, K, exclude=excluded, stats=stats)
        times.append(time.perf_counter() - start)
        candidates.append(stats.candidates)
        scored.append(stats.scored or stats.candidates)
        certified += stats.certified
        if excluded:
            keep = np.setdiff1d(np.arange(n), np.asarray(excluded))
            sub = {m: gallery[m][keep] for m in MODALITIES}
            # The excluded shape stays enrolled, so it stays in the gallery's sigma.
            ref = keep[exhaustive_topk(preset, sub, sigma, [query], K)[0]]
            hits += len({m.id for m in found} & set(int(i) for i in ref))
            total += len(ref)
        else:
            results.append({m.id for m in found})
    if results:
        refs = exhaustive_topk(preset, gallery, sigma, queries, K)
        for got, ref in zip(results, refs, strict=True):
            hits += len(got & set(int(i) for i in ref))
            total += len(ref)
    ms = np.array(times) * 1000
    return {
        "n": n,
        "recall": hits / total,
        "p50": float(np.percentile(ms, 50)),
        "p95": float(np.percentile(ms, 95)),
        "max": float(ms.max()),
        "candidates": statistics.mean(candidates),
        "scored": statistics.mean(scored),
        "certified": certified / len(queries),
        "build": build_seconds,
        "refit": refit_seconds,
        "index_mb": index_mb,
    }


def tosca_rows(preset_name: str) -> list[Row]:
    preset = get_preset(preset_name)
    descriptors = tosca_descriptors(preset_name)
    names = sorted(descriptors)
    gallery = {m: np.stack([descriptors[n].vector(m) for n in names]) for m in MODALITIES}
    queries = [{m: gallery[m][i] for m in MODALITIES} for i in range(len(names))]
    # Leave-one-out: each mesh queries the rest (it stays in the gallery's sigma).
    row = measure(preset, gallery, queries, exclude=[(i,) for i in range(len(names))])
    row["data"] = f"TOSCA ({preset.name}: {preset.dissimilarity}, {preset.fusion})"
    return [row]


def synthetic_rows(preset_name: str, sizes: list[int], n_queries: int, seed: int) -> list[Row]:
    preset = get_preset(preset_name)
    model = synthetic_model(preset_name)
    rows = []
    for size in sizes:
        rng = np.random.default_rng(seed)
        per_class = 10
        n_classes = max(1, size // per_class)
        # Each class gets one extra member, held out: the queries are unseen poses
        # of enrolled classes.
        data = synthetic(model, n_classes, per_class + 1, rng)
        member = np.arange(n_classes * (per_class + 1)) % (per_class + 1)
        gallery = {m: v[member < per_class][:size] for m, v in data.items()}
        held_out = np.flatnonzero(member == per_class)
        pick = rng.choice(held_out, size=min(n_queries, len(held_out)), replace=False)
        queries = [{m: data[m][i] for m in MODALITIES} for i in pick]
        row = measure(preset, gallery, queries)
        row["data"] = f"synthetic ({preset.name})"
        rows.append(row)
        print(_format(row), flush=True)
    return rows


def collection_rows(
    preset_name: str, size: int, collections: int, n_queries: int, seed: int
) -> list[Row]:
    """``size`` synthetic shapes as one gallery and spread over ``collections`` indexes
    (whole classes each): the same held-out queries searched in both, interleaved."""
    preset = get_preset(preset_name)
    rng = np.random.default_rng(seed)
    per_class = 10
    n_classes = max(1, size // per_class)
    data = synthetic(synthetic_model(preset_name), n_classes, per_class + 1, rng)
    member = np.arange(n_classes * (per_class + 1)) % (per_class + 1)
    collection_of = (np.arange(len(member)) // (per_class + 1)) % collections
    enrolled = np.flatnonzero(member < per_class)
    picks = rng.choice(np.flatnonzero(member == per_class), size=n_queries, replace=False)
    queries = [{m: data[m][i] for m in MODALITIES} for i in picks]
    shards = [enrolled] + [enrolled[collection_of[enrolled] == c] for c in range(collections)]
    built: list[tuple[GalleryIndex, Vectors, np.ndarray, float, Vectors | None]] = []
    for ids in shards:
        gallery = {m: data[m][ids] for m in MODALITIES}
        started = time.perf_counter()
        index = build(preset, gallery, ids)
        seconds = time.perf_counter() - started
        # eq. (9)'s sigma of the reference ranking, once per gallery (not per query).
        sigma = (
            {m: gallery_sigma(gallery[m]) for m in MODALITIES}
            if preset.dissimilarity == "D2"
            else None
        )
        built.append((index, gallery, ids, seconds, sigma))
        index.search(queries[0], K)  # warm-up
    hits = np.zeros(2)
    times: list[list[float]] = [[], []]
    for query, i in zip(queries, picks, strict=True):  # interleaved, query by query
        for j, shard in enumerate((0, 1 + collection_of[i])):
            index, gallery, ids, _, sigma = built[shard]
            ref = {int(ids[r]) for r in exhaustive_topk(preset, gallery, sigma, [query], K)[0]}
            start = time.perf_counter()
            found = index.search(query, K)
            times[j].append((time.perf_counter() - start) * 1000)
            hits[j] += len({m.id for m in found} & ref) / K
    sizes = sorted({len(b[2]) for b in built[1:]})
    rows = []
    for j, what in enumerate(("one gallery", f"its own of {collections} collections")):
        ms = np.array(times[j])
        rows.append(
            {
                "data": f"synthetic ({preset.name}), {what}",
                "n": len(enrolled) if j == 0 else sizes[0],
                "recall": hits[j] / len(queries),
                "p50": float(np.percentile(ms, 50)),
                "p95": float(np.percentile(ms, 95)),
                "max": float(ms.max()),
                "build": built[0][3] if j == 0 else sum(b[3] for b in built[1:]),
            }
        )
    ratio = float(np.median(np.array(times[1]) / np.array(times[0])))
    rows[1]["data"] += f" (median ratio to one gallery {ratio:.2f})"
    return rows


COLLECTION_HEADER = (
    "| data | shapes searched | recall@10 | search p50 ms | p95 ms | max ms | build s |\n"
    "|---|---|---|---|---|---|---|"
)


def _format_collection(row: Row) -> str:
    return (
        f"| {row['data']} | {row['n']:,} | {row['recall']:.4f} | {row['p50']:.2f} | "
        f"{row['p95']:.2f} | {row['max']:.2f} | {row['build']:.1f} |"
    )


HEADER = (
    "| data | enrolled | recall@10 | search p50 ms | p95 ms | max ms | "
    "faiss candidates | scored exactly | certified exact | build s | refit s | index MB |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|"
)


def _format(row: Row) -> str:
    return (
        f"| {row['data']} | {row['n']:,} | {row['recall']:.4f} | {row['p50']:.2f} | "
        f"{row['p95']:.2f} | {row['max']:.2f} | {row['candidates']:.0f} | {row['scored']:.0f} | "
        f"{row['certified']:.0%} | {row['build']:.1f} | {row['refit']:.1f} | "
        f"{row['index_mb']:.0f} |"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[1000, 10_000, 100_000])
    parser.add_argument("--queries", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--preset", default=DEFAULT_PRESET)
    parser.add_argument("--tosca-presets", nargs="*", default=[DEFAULT_PRESET])
    parser.add_argument(
        "--collections", type=int, help="also spread each size over this many collections"
    )
    args = parser.parse_args(argv)
    print(HEADER, flush=True)
    for name in args.tosca_presets:
        for row in tosca_rows(name):
            print(_format(row), flush=True)
    synthetic_rows(args.preset, args.sizes, args.queries, args.seed)
    if args.collections:
        print(f"\n{COLLECTION_HEADER}", flush=True)
        for size in args.sizes:
            for row in collection_rows(
                args.preset, size, args.collections, args.queries, args.seed
            ):
                print(_format_collection(row), flush=True)


if __name__ == "__main__":
    main()
