"""Partial-query search: the index's passes against the exhaustive ranking, and latency.

    python -m benchmarks.partial_search [--variant cut-15] [--sizes 10000 100000]
        [--queries 200] [--exhaustive 20] [--store DIR] [--json FILE]

A query that looks partial is ranked with the parts modality
(:meth:`app.gallery.index.GalleryIndex.partial_search`). On TOSCA (its wholes enrolled,
each whole's ``--variant`` copy a query, through the evaluation cache of ``shapes
partiality``): how often its top 1 and top 10 are the exhaustive ranking's (every sample
of every shape, :func:`worker.engine.parts.part_dissimilarity`, at the query's weights),
and the latency of both.

Then synthetic galleries of ``--sizes`` shapes (:func:`build_gallery`: objects made from
TOSCA's wholes, ``POSES`` poses each; the queries are real partial copies), each made once
and kept under ``--store`` (the million: 8 minutes, a 24 GB parts file), and measured in a process
of its own as a replica would run: the index loaded from its files (every sample's
profiles stay in the parts file, read for a shortlist), ``--queries`` partial queries
and whole queries interleaved, one at a time, one BLAS thread. After them, for the first
``--exhaustive`` queries the partial search is also run with every shape compared
coarsely (the exhaustive two-pass ranking, without the inverted file of the samples'
profiles): top 1 is how often the two agree on the first shape, top 10 the mean overlap
of their ten, "first as good" how often this search's first shape scores no worse than
the exhaustive ranking's (that ranking's coarse pass can miss a scale or a shape the
inverted file finds), and "object first" how often each puts a pose of the query's own object
first (the exhaustive ranking is the bar, not the truth). RSS is the replica process's
resident memory after the queries (the parts file's pages the kernel caches are not in
it).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from app.gallery.index import GalleryIndex, Match
from app.gallery.persistence import FORMAT_VERSION, load_index, save_index
from app.gallery.service import descriptor_vectors, flat_vectors
from app.gallery.words import (
    FIT_ITERATIONS,
    FIT_PROFILES,
    MAX_WORDS,
    SAMPLES_PER_WORD,
    WORD_SAMPLES,
)
from benchmarks.common import (
    REPO,
    TOSCA,
    add_evaluation_cache_arguments,
    resident_mb,
    synthetic,
    synthetic_model,
)
from worker.engine.compare import fuse, partiality, query_weights
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.parts import compared_profiles, grid_radii
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


def p95(values: list[float]) -> float:
    return float(np.quantile(values, 0.95))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_evaluation_cache_arguments(parser)
    parser.add_argument("--variant", default="cut-15")
    parser.add_argument("--sizes", type=int, nargs="*", default=[10_000, 100_000])
    parser.add_argument("--queries", type=int, default=200, help="per synthetic gallery")
    parser.add_argument(
        "--exhaustive", type=int, default=20, help="of them, also ranked exhaustively"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--store",
        type=Path,
        default=REPO / ".cache" / "partial-galleries",
        help="where the synthetic galleries are kept (made once)",
    )
    parser.add_argument("--json", type=Path, help="also write the rows here")
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
    if args.sizes:
        scale_rows(args, preset, wholes.descriptors, copies.descriptors)


# ----------------------------------------------------------------- at scale

#: Poses enrolled per synthetic object (as :mod:`benchmarks.index`'s classes), and the
#: per-sample noise of a pose's profiles.
POSES = 10
POSE_NOISE = 0.02
#: How far apart synthetic objects are, in units of the real wholes' spread.
WARP = 8.0
#: What a stored gallery was made by: one made otherwise is made again.
MODEL_VERSION = 4


class ObjectWarps:
    """What makes synthetic objects of one real whole differ: object ``o`` changes every
    value ``v`` of a descriptor's area profiles (a log of a ball's area ratio) to ``v + s
    (u_o + b_o sin(w_o v + phi_o))``. A change of the value alone, so that it is the same
    whatever radius or scale the value is compared at (a part's columns are a whole's
    shifted); its size ``s`` that of the real wholes' differences (the spread of their
    mean profiles). Centroid profiles change alike in their own units, their spread ``s'``
    taking the place of ``s``: ``v + s' (u_o + b_o sin(w_o v s / s' + phi_o))``."""

    def __init__(
        self,
        objects: int,
        wholes: Sequence[ShapeDescriptor],
        columns: int,
        rng: np.random.Generator,
    ) -> None:
        means = np.stack([d.parts.astype(np.float64).mean(axis=0) for d in wholes])
        kinds = [means[:, a : a + columns] for a in range(0, means.shape[1], columns)]
        self.spread = np.repeat([WARP * float(k.std(axis=0).mean()) for k in kinds], columns)
        self.shift = rng.normal(size=objects)
        self.amplitude = rng.uniform(0.0, 1.0, size=objects)
        self.frequency = rng.uniform(1.0, 4.0, size=objects)
        self.phase = rng.uniform(0.0, 2 * np.pi, size=objects)

    def __call__(self, o: int, profiles: np.ndarray) -> np.ndarray:
        """(m, C) or (m, 2C) ``profiles`` as object ``o``'s."""
        scale = self.spread[: profiles.shape[1]]
        wave = np.sin(self.frequency[o] * profiles * self.spread[0] / scale + self.phase[o])
        warped: np.ndarray = profiles + scale * (self.shift[o] + self.amplitude[o] * wave)
        return warped


def build_gallery(
    size: int,
    store: Path,
    preset: Preset,
    wholes: Sequence[ShapeDescriptor],
    copies: Sequence[ShapeDescriptor],
    n_queries: int,
    seed: int,
) -> dict[str, Any]:
    """Enroll ``size`` synthetic shapes (``size / POSES`` objects), fit, refit once, save
    the index (and its parts file) under ``store``, and the queries beside it.

    Object ``o`` is made from real whole ``b = o mod 83``: its flat vectors a class of
    :func:`benchmarks.common.synthetic` (poses a random combination of the real
    within-class residuals), its profiles ``b``'s plus its offset (:func:`objects_model`),
    each pose's plus ``POSE_NOISE`` per sample. Its query is ``b``'s real partial copy,
    its profiles offset alike, its flat vectors an unseen pose's times the real copy's
    over the real whole's (what the cut does to them).
    """
    rng = np.random.default_rng(seed)
    objects = size // POSES
    flat = synthetic(synthetic_model(preset.name), objects, POSES + 1, rng)
    warps = ObjectWarps(objects, wholes, len(grid_radii(preset)), rng)
    shape = preset.parts_shape()
    assert shape is not None, "the preset has no parts modality"
    bases = [d.parts.astype(np.float64) for d in wholes]

    def shapes() -> Iterator[tuple[int, dict[str, np.ndarray]]]:
        for o in range(objects):
            profiles = compared_profiles(warps(o, bases[o % len(wholes)]), preset)
            for pose in range(POSES):
                noise = POSE_NOISE * rng.standard_normal(shape, dtype=np.float32)
                vectors = {m: v[o * (POSES + 1) + pose] for m, v in flat.items()}
                yield o * POSES + pose, {**vectors, PARTS: profiles + noise}

    directory = store / str(size)
    parts = store / f"{size}.parts"
    parts.unlink(missing_ok=True)
    index = GalleryIndex(preset, preset.modality_sizes(), parts_shape=shape, parts_path=parts)
    start = time.perf_counter()
    index.add_many(shapes())
    built = time.perf_counter() - start
    start = time.perf_counter()
    index.refit()  # what a whole refit after 5 % churn costs (searches wait for it)
    refit = time.perf_counter() - start
    save_index(index, directory)
    picked = rng.choice(objects, size=n_queries, replace=False)
    queries = []
    for o in picked:
        copy, whole = copies[o % len(wholes)], wholes[o % len(wholes)]
        unseen = o * (POSES + 1) + POSES
        queries.append(
            {
                "object": int(o),
                "flat": {
                    m: (v[unseen] * copy.vector(m) / whole.vector(m)).tolist()
                    for m, v in flat.items()
                },
                "profiles": warps(o, copy.parts.astype(np.float64)).tolist(),
                "reach": copy.parts_reach.tolist(),
                "weights": weights_of(copy, preset),
            }
        )
    made = {
        "size": size,
        "build_s": built,
        "refit_s": refit,
        "words": index.words is not None,
        "queries": queries,
    }
    (store / f"{size}.json").write_text(
        json.dumps({"key": gallery_key(size, preset, seed), **made})
    )
    return made


def gallery_key(size: int, preset: Preset, seed: int) -> dict[str, Any]:
    """What a stored gallery must have been made with to be reused."""
    return {
        "size": size,
        "seed": seed,
        "preset": f"{preset.name}-v{preset.version}",
        "model": MODEL_VERSION,
        "index_format": FORMAT_VERSION,
        "words": [WORD_SAMPLES, SAMPLES_PER_WORD, MAX_WORDS, FIT_PROFILES, FIT_ITERATIONS],
    }


def stored_gallery(path: Path, key: dict[str, Any]) -> dict[str, Any] | None:
    """The stored gallery's record if it was made with ``key``."""
    if not path.exists():
        return None
    made: dict[str, Any] = json.loads(path.read_text())
    return made if made.get("key") == key else None


def measure_gallery(
    store: Path, size: int, preset_name: str, exhaustive_queries: int
) -> dict[str, Any]:
    """In a process of its own, as a replica: load the stored index, time every query
    (a whole query's search and a partial query's, interleaved, after one warm-up), then
    for the first ``exhaustive_queries`` compare the partial search with every shape
    compared coarsely (the exhaustive two-pass ranking); its resident memory after."""
    preset = get_preset(preset_name)
    made = json.loads((store / f"{size}.json").read_text())
    with threadpool_limits(1):
        index = load_index(store / str(size), preset)
        loaded_mb = resident_mb()
        whole_ms: list[float] = []
        partial_ms: list[float] = []
        top1: list[bool] = []
        top10: list[float] = []
        as_good: list[bool] = []  # this search's first at most the exhaustive first's score
        own: list[tuple[bool, bool]] = []  # the query's object first: this search, exhaustive
        answers: list[list[Match]] = []  # each timed partial search's matches
        queries = [
            (
                {m: np.asarray(v) for m, v in query["flat"].items()},
                np.asarray(query["profiles"]),
                np.asarray(query["reach"]),
                query["weights"],
                query["object"],
            )
            for query in made["queries"]
        ]
        for q, (flat, profiles, reach, weights, _) in enumerate(queries):
            if q == 0:  # warm-up
                index.search(flat, 10)
                index.partial_search(flat, profiles, reach, weights, 10)
            start = time.perf_counter()
            index.search(flat, 10)
            whole_ms.append(1000 * (time.perf_counter() - start))
            start = time.perf_counter()
            answers.append(index.partial_search(flat, profiles, reach, weights, 10)[0])
            partial_ms.append(1000 * (time.perf_counter() - start))
        # After the timed queries: an exhaustive pass reads every shape's rows and would
        # leave the next timed query's caches cold.
        for (flat, profiles, reach, weights, obj), first in zip(
            queries[:exhaustive_queries], answers, strict=False
        ):
            words, index.words = index.words, None
            best = index.partial_search(flat, profiles, reach, weights, 10)[0]
            index.words = words
            found, every = [m.id for m in first], [m.id for m in best]
            top1.append(found[0] == every[0])
            as_good.append(first[0].score <= best[0].score * (1 + 1e-9))
            top10.append(len(set(found) & set(every)) / len(every))
            own.append((found[0] // POSES == obj, every[0] // POSES == obj))
        return {
            "size": size,
            "p50_ms": float(np.percentile(partial_ms, 50)),
            "p95_ms": float(np.percentile(partial_ms, 95)),
            "top1": float(np.mean(top1)) if top1 else float("nan"),
            "top10": float(np.mean(top10)) if top10 else float("nan"),
            "top1_as_good": float(np.mean(as_good)) if as_good else float("nan"),
            "object_first": np.mean(own, axis=0).tolist() if own else [float("nan")] * 2,
            "rss_mb": resident_mb(),
            "loaded_mb": loaded_mb,
            "whole_p50_ms": float(np.percentile(whole_ms, 50)),
            "whole_p95_ms": float(np.percentile(whole_ms, 95)),
            "exhaustive": len(top1),
            "queries": len(partial_ms),
            "words": index.words is not None,
            "parts_mb_in_memory": (
                index.store.coarse[: len(index)].nbytes
                + (index.words.nbytes if index.words is not None else 0)
            )
            / 2**20,
            "build_s": made["build_s"],
            "refit_s": made["refit_s"],
        }


def agreement(row: dict[str, Any]) -> str:
    """A row's columns that compare it with the exhaustive ranking (dashes without it)."""
    if not row["exhaustive"]:
        return "- | - | - | -"
    return (
        f"{100 * row['top1']:.0f}% of {row['exhaustive']} | {row['top10']:.3f} "
        f"| {100 * row['top1_as_good']:.0f}% | {100 * row['object_first'][0]:.0f}% / "
        f"{100 * row['object_first'][1]:.0f}%"
    )


SCALE_HEADER = (
    "| shapes | inverted file | partial p50 ms | p95 ms | top 1 as exhaustive | top 10 overlap "
    "| first as good | object first, this / exhaustive | whole p50 ms | p95 ms | RSS MB "
    "| parts in RAM, B/shape | build s | refit s |\n"
    "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
)


def scale_rows(
    args: argparse.Namespace,
    preset: Preset,
    wholes: Sequence[ShapeDescriptor],
    copies: Sequence[ShapeDescriptor],
) -> None:
    """Synthetic galleries of ``args.sizes`` shapes, made once under ``args.store``, each
    measured in a process of its own; the rows printed and, with ``--json``, written."""
    args.store.mkdir(parents=True, exist_ok=True)
    rows = []
    print(f"\n{SCALE_HEADER}", flush=True)
    for size in args.sizes:
        key = gallery_key(size, preset, args.seed)
        if stored_gallery(args.store / f"{size}.json", key) is None:
            with threadpool_limits(1):
                build_gallery(size, args.store, preset, wholes, copies, args.queries, args.seed)
        spawn = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(1, mp_context=spawn) as pool:
            row = pool.submit(
                measure_gallery, args.store, size, preset.name, args.exhaustive
            ).result()
        rows.append(row)
        print(
            f"| {size:,} | {'yes' if row['words'] else 'no'} | {row['p50_ms']:.1f} "
            f"| {row['p95_ms']:.1f} | {agreement(row)} "
            f"| {row['whole_p50_ms']:.1f} | {row['whole_p95_ms']:.1f} "
            f"| {row['rss_mb']:,.0f} | {row['parts_mb_in_memory'] * 2**20 / size:,.0f} "
            f"| {row['build_s']:.0f} | {row['refit_s']:.1f} |",
            flush=True,
        )
    if args.json:
        keys = ("size", "p50_ms", "p95_ms", "top1", "top10", "top1_as_good", "rss_mb")
        args.json.write_text(json.dumps([{k: row[k] for k in keys} for row in rows], indent=1))


if __name__ == "__main__":
    main()
