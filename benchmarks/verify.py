"""A single view's rigid verification: seconds per query, on one thread and on several.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m benchmarks.verify [--queries 40]
        [--threads 2]

The partiality protocol's ``view`` copies of TOSCA (seeded as there, described through
the evaluation cache: seconds after ``shapes partiality`` has run with it) each verified
on its ``FEATURE_POOL`` best wholes by the parts (all 83 of TOSCA's), as the service
verifies one (:func:`worker.engine.rigid.verified_fitness` on stored descriptors: every
candidate's features compared, ``VERIFIED`` and up to ``FEATURE_PICKS`` more fitted): the
candidates' anchors made anew (the service's first query on them), then kept from an
earlier query (:func:`worker.engine.rigid.candidate_anchors`, as the service keeps them in
memory), each on one thread and on ``--threads`` (the service's
``SHAPES_VERIFY_THREADS``), query by query in one process. The table gives, over the first
``--queries`` copies, the median and 90th percentile seconds of each, and the median of
the per-query ratios to one thread made anew.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from worker.engine.rigid import FEATURE_POOL, Anchors, candidate_anchors, verified_fitness
from worker.evaluation.compute import compute_descriptors
from worker.evaluation.partiality import parts_matches

from .common import add_evaluation_cache_arguments, evaluated_tosca


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--queries", type=int, default=40)
    parser.add_argument("--threads", type=int, default=2)
    add_evaluation_cache_arguments(parser)
    args = parser.parse_args()
    preset, wholes = evaluated_tosca(args)
    views = compute_descriptors(
        wholes.meshes, preset, args.cache, jobs=args.jobs, progress=False, variant="view"
    )
    queries = views.descriptors[: args.queries]
    parts, scales = parts_matches(queries, wholes.descriptors, preset, args.jobs)
    kept: dict[int, Anchors | None] = {}
    runs = [("made anew", 1), ("made anew", args.threads), ("kept", 1), ("kept", args.threads)]
    seconds: dict[tuple[str, int], list[float]] = {run: [] for run in runs}
    fitted = []
    for q, query in enumerate(queries):
        shortlist = np.argsort(parts[q], kind="stable")[:FEATURE_POOL]
        candidates = [wholes.descriptors[c] for c in shortlist]
        metric, scale = preset.units == "metric", float(scales[q])
        fitnesses = []
        for anchors, threads in runs:
            if anchors == "kept":
                for c in shortlist:
                    if c not in kept:
                        kept[c] = candidate_anchors(wholes.descriptors[c])
            given = [kept[c] for c in shortlist] if anchors == "kept" else None
            start = time.perf_counter()
            fitness = verified_fitness(query, candidates, scale, metric, given, threads)
            seconds[anchors, threads].append(time.perf_counter() - start)
            if fitness is None:
                raise SystemExit(f"copy {q}: not verified")
            fitnesses.append(fitness)
        if not all(np.array_equal(f, fitnesses[0], equal_nan=True) for f in fitnesses):
            raise SystemExit(f"copy {q}: kept anchors or threads fitted otherwise")
        fitted.append(int(np.isfinite(fitnesses[0]).sum()))
    print(
        f"{len(queries)} view copies of TOSCA, {len(shortlist)} candidates each "
        f"(a median {np.median(fitted):.0f} fitted)\n"
    )
    first = np.array(seconds[runs[0]])
    print("| candidates' anchors | threads | median s | p90 s | over made anew, one thread |")
    print("|---|---:|---:|---:|---:|")
    for anchors, threads in runs:
        taken = np.array(seconds[anchors, threads])
        print(
            f"| {anchors} | {threads} | {np.median(taken):.3f} | "
            f"{np.percentile(taken, 90):.3f} | {np.median(taken / first):.2f} |"
        )


if __name__ == "__main__":
    main()
