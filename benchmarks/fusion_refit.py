"""Does learning the fusion weights slow the searches down? Search latency idle and while
a gallery's fusion fit runs, side by side in one process.

    python -m benchmarks.fusion_refit [--shapes 2000] [--queries 300]

A gallery of ``--shapes`` synthetic descriptors (the default preset's sizes, 40 labelled
classes) in the service's index (:class:`app.gallery.index.GalleryIndex`); the same
queries are searched (k = 10) with no fit running, then while
:func:`app.gallery.weights.learn_gallery_fusion` runs again and again in a thread (as the
service runs it, beside the searches), then idle again. Prints the median and p95 of each
phase, their ratio to idle, and the fit's duration.
"""

from __future__ import annotations

import argparse
import statistics
import threading
import time

import numpy as np

from app.gallery.index import GalleryIndex
from app.gallery.weights import learn_gallery_fusion
from worker.engine.presets import DEFAULT_PRESET, MODALITIES, get_preset

CLASSES = 40
K = 10


def _gallery(n: int, seed: int = 0) -> tuple[dict[str, np.ndarray], dict[int, str]]:
    rng = np.random.default_rng(seed)
    classes = rng.integers(0, CLASSES, size=n)
    vectors = {}
    for m, d in get_preset(DEFAULT_PRESET).modality_sizes().items():
        centres = rng.normal(size=(CLASSES, d))
        vectors[m] = np.exp(centres[classes] + 0.5 * rng.normal(size=(n, d)))
    return vectors, {i: f"class-{c}" for i, c in enumerate(classes)}


def _latencies(index: GalleryIndex, queries: list[dict[str, np.ndarray]]) -> list[float]:
    out = []
    for query in queries:
        start = time.perf_counter()
        index.search(query, K)
        out.append(time.perf_counter() - start)
    return out


def run(shapes: int, n_queries: int) -> tuple[list[tuple[str, float, float, float]], list[float]]:
    preset = get_preset(DEFAULT_PRESET)
    vectors, labels = _gallery(shapes)
    index = GalleryIndex(preset, preset.modality_sizes())
    index.add_many((i, {m: vectors[m][i] for m in MODALITIES}) for i in range(shapes))
    index.refit()
    rng = np.random.default_rng(1)
    picks = rng.choice(shapes, size=n_queries)
    queries = [
        {m: vectors[m][i] * np.exp(0.05 * rng.normal(size=vectors[m].shape[1])) for m in MODALITIES}
        for i in picks
    ]
    _latencies(index, queries[:20])  # warm up
    idle = _latencies(index, queries)

    fits: list[float] = []
    stop = threading.Event()

    def refit() -> None:
        while not stop.is_set():
            start = time.perf_counter()
            learn_gallery_fusion(index, labels, preset, max_shapes=300, version=0)
            fits.append(time.perf_counter() - start)

    fitter = threading.Thread(target=refit, daemon=True)
    fitter.start()
    time.sleep(0.2)  # the fit under way
    during = _latencies(index, queries)
    stop.set()
    fitter.join()
    after = _latencies(index, queries)
    base = statistics.median(idle)
    rows = []
    for name, times in (("idle", idle), ("during a fusion fit", during), ("idle again", after)):
        median, p95 = statistics.median(times), float(np.percentile(times, 95))
        rows.append((name, 1000 * median, 1000 * p95, median / base))
    return rows, fits


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shapes", type=int, default=2000)
    parser.add_argument("--queries", type=int, default=300)
    args = parser.parse_args()
    rows, fits = run(args.shapes, args.queries)
    print(f"{args.shapes} shapes, {args.queries} queries, k = {K}")
    print("| searches | median (ms) | p95 (ms) | median / idle |\n|---|---|---|---|")
    for name, median, p95, ratio in rows:
        print(f"| {name} | {median:.2f} | {p95:.2f} | {ratio:.2f} |")
    print(f"fusion fits while searching: {len(fits)}, median {statistics.median(fits):.2f} s")


if __name__ == "__main__":
    main()
