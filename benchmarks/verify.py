"""A single view's rigid verification: seconds per query.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m benchmarks.verify [--queries 40]

The partiality protocol's ``view`` copies of TOSCA (seeded as there, described through
the evaluation cache: seconds after ``shapes partiality`` has run with it) each verified
on its ``VERIFIED`` best wholes by the parts, as the service verifies one
(:func:`worker.engine.rigid.verified_fitness` on stored descriptors, their anchors made
anew). The table gives, over the first ``--queries`` copies, the median and 90th
percentile seconds of the verification, in one process.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from worker.engine.rigid import VERIFIED, verified_fitness
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
    verify = []
    for q, query in enumerate(queries):
        shortlist = [wholes.descriptors[c] for c in np.argsort(parts[q], kind="stable")[:VERIFIED]]
        start = time.perf_counter()
        verified_fitness(query, shortlist, float(scales[q]), preset.units == "metric")
        verify.append(time.perf_counter() - start)
    print(f"{len(queries)} view copies of TOSCA, {VERIFIED} candidates each, one thread\n")
    print("| median s | p90 s | per candidate, median s |")
    print("|---:|---:|---:|")
    print(
        f"| {np.median(verify):.3f} | {np.percentile(verify, 90):.3f} | "
        f"{np.median(verify) / VERIFIED:.3f} |"
    )


if __name__ == "__main__":
    main()
