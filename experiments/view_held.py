"""Whether the candidate holding most of a single view names its object.

    python -m experiments.view_held [--variants view range] [--jobs 2] [--cache CACHE]

The partiality protocol's single views of TOSCA and SCAPE (its copies, seeded as there,
described from the evaluation cache: ``shapes partiality`` fills it) are fitted as the
protocol and the service fit them (:func:`worker.engine.rigid.verified_fitness` on the
parts' best ``FEATURE_POOL``, the 154 wholes the gallery). Per variant, by the fittest
candidate's fitness: how many copies, and of those how many the fittest names by class
and by source; then, for each threshold, the copies whose fittest holds at least that
much, with their own source among the candidates and left out (the best of the other
fitted candidates: the object enrolled in other poses only, or not at all), and how many
of them are of the view's class (``HELD_FITNESS`` claims all of them); last, split by
collection (TOSCA's copies, SCAPE's), how many held fittest were of another class over
all the variants, source among the candidates or left out: a threshold chosen on one
collection, checked on the other.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from benchmarks.common import (
    add_evaluation_cache_arguments,
    evaluated_partiality_wholes,
    partiality_copies,
)
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.rigid import (
    FEATURE_POOL,
    HELD_FITNESS,
    Anchors,
    candidate_anchors,
    verified_fitness,
)
from worker.evaluation.compute import single_threaded_blas
from worker.evaluation.partiality import unverified_matrices
from worker.evaluation.robustness import PRESET_ROW

#: Lower edges of the fittest's fitness bands the first table gives.
BANDS = (0.0, 0.5, 0.6, 0.7, 0.8, 0.9)
THRESHOLDS = (0.8, 0.85, HELD_FITNESS, 0.95)

_GALLERY: list[ShapeDescriptor] = []
_ANCHORS: dict[int, Anchors | None] = {}


def _hold(gallery: list[ShapeDescriptor]) -> None:
    single_threaded_blas()
    _GALLERY[:] = gallery


def fitted(task: tuple[ShapeDescriptor, np.ndarray, float]) -> np.ndarray:
    """(FEATURE_POOL,) a view's fitness on its pool (NaN where not fitted), the wholes'
    anchors made once per process."""
    query, pool, scale = task
    for c in pool:
        if int(c) not in _ANCHORS:
            _ANCHORS[int(c)] = candidate_anchors(_GALLERY[int(c)])
    candidates = [_GALLERY[int(c)] for c in pool]
    fitness = verified_fitness(query, candidates, scale, False, [_ANCHORS[int(c)] for c in pool])
    assert fitness is not None  # every copy here is a single view with its surface
    return fitness


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", nargs="+", default=["view", "range"])
    add_evaluation_cache_arguments(parser)  # the partiality run's cache
    args = parser.parse_args()
    preset, wholes = evaluated_partiality_wholes(args)
    labels = np.array([m.label for m in wholes.meshes])
    index = {m.name: i for i, m in enumerate(wholes.meshes)}
    rows = [
        "| variant | fittest's fitness | copies | own class | own source |",
        "|---|---|---:|---:|---:|",
    ]
    held_rows = [
        "| variant | at least | held (source among them) | of the view's class | held (source "
        "left out) | of the view's class |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    scape = labels == labels[-1]  # SCAPE's poses come last
    wrong = {(c, t): 0 for c in (False, True) for t in THRESHOLDS}
    for variant in args.variants:
        done = partiality_copies(variant, preset, args.cache, args.jobs)
        views = [i for i, d in enumerate(done.descriptors) if d.single_view]
        ranked, scales = unverified_matrices(
            done.descriptors, wholes.descriptors, preset, jobs=args.jobs
        )
        pools = [np.argsort(ranked[PRESET_ROW][i], kind="stable")[:FEATURE_POOL] for i in views]
        tasks = [
            (done.descriptors[i], p, float(scales[i])) for i, p in zip(views, pools, strict=True)
        ]
        with ProcessPoolExecutor(
            args.jobs, initializer=_hold, initargs=(list(wholes.descriptors),)
        ) as workers:
            fits = list(workers.map(fitted, tasks))
        best, other, own, source, other_own = [], [], [], [], []
        for i, pool, fitness in zip(views, pools, fits, strict=True):
            src = index[done.meshes[i].name]
            held = np.where(np.isfinite(fitness), fitness, -1.0)
            top = int(pool[np.argmax(held)])  # the first of the fittest, as verified_order
            rest = np.where(pool == src, -1.0, held)
            best.append(held.max())
            own.append(labels[top] == labels[src])
            source.append(top == src)
            other.append(rest.max())
            other_own.append(labels[int(pool[np.argmax(rest)])] == labels[src])
        best_, other_ = np.array(best), np.array(other)
        own_, source_, other_own_ = np.array(own), np.array(source), np.array(other_own)
        for low, high in zip(BANDS, (*BANDS[1:], np.inf), strict=True):
            band = (best_ >= low) & (best_ < high)
            name = f"{low:.1f}+" if high == np.inf else f"{low:.1f}-{high:.1f}"
            rows.append(
                f"| {variant} | {name} | {band.sum()} | {own_[band].sum()} | "
                f"{source_[band].sum()} |"
            )
        collection = scape[[index[done.meshes[i].name] for i in views]]
        for t in THRESHOLDS:
            held, left = best_ >= t, other_ >= t
            for c in (False, True):
                ours = collection == c
                wrong[c, t] += int((held & ~own_ & ours).sum() + (left & ~other_own_ & ours).sum())
            held_rows.append(
                f"| {variant} | {t:.2f} | {held.sum()} of {len(best_)} | {own_[held].sum()} | "
                f"{left.sum()} | {other_own_[left].sum()} |"
            )
    print("\n".join(rows))
    print()
    print("\n".join(held_rows))
    print()
    print("| at least | held of another class: TOSCA's copies | SCAPE's copies |")
    print("|---:|---:|---:|")
    for t in THRESHOLDS:
        print(f"| {t:.2f} | {wrong[False, t]} | {wrong[True, t]} |")


if __name__ == "__main__":
    main()
