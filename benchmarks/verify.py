"""A single view's rigid verification: seconds per query.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m benchmarks.verify [--queries 40]

The partiality protocol's ``view`` copies of TOSCA (seeded as there, described through
the evaluation cache: seconds after ``shapes partiality`` has run with it) each verified
on its ``FEATURE_POOL`` best wholes by the parts (all 83 of TOSCA's), as the service
verifies one (:func:`worker.engine.rigid.verified_fitness` on stored descriptors: every
candidate's features compared, ``VERIFIED`` and up to ``FEATURE_PICKS`` more fitted): the
candidates' anchors made anew (the service's first query on them), then kept from an
earlier query (:func:`worker.engine.rigid.whole_anchors`, as the service keeps them in
memory), alternating query by query. The table gives, over the first ``--queries``
copies, the median and 90th percentile seconds of either, in one process, and their
ratio.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from worker.engine.rigid import FEATURE_POOL, verified_fitness, whole_anchors
from worker.evaluation.compute import compute_descriptors
from worker.evaluation.partiality import parts_matches

from .common import add_evaluation_cache_arguments, evaluated_tosca


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--queries", type=int, default=40)
    add_evaluation_cache_arguments(parser)
    args = parser.parse_args()
    preset, wholes = evaluated_tosca(args)
    views = compute_descriptors(
        wholes.meshes, preset, args.cache, jobs=args.jobs, progress=False, variant="view"
    )
    queries = views.descriptors[: args.queries]
    parts, scales = parts_matches(queries, wholes.descriptors, preset, args.jobs)
    kept = {}
    made, reused, fitted = [], [], []
    for q, query in enumerate(queries):
        shortlist = np.argsort(parts[q], kind="stable")[:FEATURE_POOL]
        candidates = [wholes.descriptors[c] for c in shortlist]
        metric, scale = preset.units == "metric", float(scales[q])
        start = time.perf_counter()
        fresh = verified_fitness(query, candidates, scale, metric)
        made.append(time.perf_counter() - start)
        for c in shortlist:
            if c not in kept:
                kept[c] = whole_anchors(wholes.descriptors[c])
        anchors = [kept[c] for c in shortlist]
        start = time.perf_counter()
        again = verified_fitness(query, candidates, scale, metric, anchors)
        reused.append(time.perf_counter() - start)
        if fresh is None or again is None or not np.array_equal(fresh, again, equal_nan=True):
            raise SystemExit(f"copy {q}: not verified, or kept anchors fitted otherwise")
        fitted.append(int(np.isfinite(again).sum()))
    print(
        f"{len(queries)} view copies of TOSCA, {len(shortlist)} candidates each "
        f"(a median {np.median(fitted):.0f} fitted), one thread\n"
    )
    print("| candidates' anchors | median s | p90 s |")
    print("|---|---:|---:|")
    for name, seconds in (("made anew", made), ("kept", reused)):
        print(f"| {name} | {np.median(seconds):.3f} | {np.percentile(seconds, 90):.3f} |")
    print(
        f"\nkept / made anew, median of per-query ratios: "
        f"{np.median(np.array(reused) / np.array(made)):.2f}"
    )


if __name__ == "__main__":
    main()
