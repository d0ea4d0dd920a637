"""Whether a part finds its whole: the partiality protocol.

Pure functions on descriptors (the describing is :mod:`.compute`'s, the partial copies
:mod:`.partial`'s). Every partial copy of a mesh of a labelled collection queries the
collection's whole meshes, its own source among them. Per modality, for the parts
modality, for the preset's own score (each query weighed by how partial it looks,
:func:`worker.engine.compare.query_weights`) and for the ShapeDNA baseline:

* **own class**: the nearest whole is of the query's class;
* **own source**: the nearest whole is the mesh the query was cut from;
* **mAP**: the mean over queries of the average precision of the whole ranking, the
  meshes of the query's class (its source included) relevant.

And, as SHREC'17 ranks partial shapes (Rodola et al., "Deformable shape retrieval with
missing parts", 3DOR 2017), all to all among the copies of one variant: each copy
queries the others (its class relevant), scored by nearest neighbour, first and second
tier, DCG and mAP (:func:`worker.recognition.metrics.retrieval_scores`).

Rankings are per query, so the product rule is used as it is (no root): only the order
of each query's candidates counts here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from contextlib import nullcontext
from functools import partial
from typing import Any

import numpy as np

from worker.engine.compare import (
    fuse,
    partiality,
    preset_dissimilarity,
    query_weights,
)
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.parts import (
    best_scale,
    compared_by_size,
    compared_profiles,
    part_dissimilarity,
    scale_scores,
    sized_dissimilarity,
    sized_scales,
)
from worker.engine.presets import MODALITIES, PARTS, SIZE, Preset
from worker.engine.rigid import (
    FEATURE_POOL,
    Anchors,
    candidate_anchors,
    verified_fitness,
    verified_order,
)
from worker.recognition import metrics

from .compute import single_threaded_blas
from .robustness import PRESET_ROW, cross_dissimilarities, row_titles
from .shapedna import BASELINE


def partial_row_titles(preset: Preset) -> dict[str, str]:
    """Row key -> title, in table order: the robustness protocol's, the preset's score
    weighing the parts by partiality."""
    titles = row_titles(preset)
    titles[PRESET_ROW] = titles[PRESET_ROW].replace(" (", ", parts by partiality (")
    return titles


def query_partiality(descriptors: Sequence[ShapeDescriptor], preset: Preset) -> np.ndarray:
    """(q,) how partial each descriptor's surface looks (:func:`partiality`)."""
    return np.array(
        [partiality(d.longest_open_loop, d.kept_area_fraction, preset) for d in descriptors]
    )


def parts_matrix(
    queries: Sequence[ShapeDescriptor],
    gallery: Sequence[ShapeDescriptor],
    preset: Preset,
    jobs: int = 1,
    themselves: bool = False,
) -> np.ndarray:
    """(q, n) the parts dissimilarity of every query to every gallery shape (every
    sample of every shape), the queries shared among ``jobs`` processes.

    ``themselves``: the queries are the gallery, and each is left out of its own
    candidates (as a service's query is never in its gallery): its scale is chosen by
    its best match among the others (it would match itself best, at scale 1). Its own
    entry is then 0, as every modality's distance of a shape to itself.

    In a collection of metric units a query is compared with each shape near the scale
    their sizes imply, as the service compares it (:func:`compared_by_size`).
    """
    return parts_matches(queries, gallery, preset, jobs, themselves)[0]


def parts_matches(
    queries: Sequence[ShapeDescriptor],
    gallery: Sequence[ShapeDescriptor],
    preset: Preset,
    jobs: int = 1,
    themselves: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`parts_matrix` and (q,) the scale the parts chose for each query (its best
    match's)."""
    whole = compared_profiles(np.stack([g.parts.astype(np.float64) for g in gallery]), preset)
    profiles = [q.parts.astype(np.float64) for q in queries]
    reach = [q.parts_reach for q in queries]
    own: list[int | None] = list(range(len(queries))) if themselves else [None] * len(queries)
    sizes = np.array([g.vector(SIZE)[0] for g in gallery]) if preset.units == "metric" else None
    centres = [
        sized_scales(float(q.vector(SIZE)[0]), sizes, preset)
        if sizes is not None and compared_by_size(preset, q.single_view)
        else None
        for q in queries
    ]
    rows = (profiles, reach, own, centres)
    if jobs <= 1 or len(queries) < 2:
        found = [_parts_row(whole, preset, *row) for row in zip(*rows, strict=True)]
    else:
        with ProcessPoolExecutor(
            max_workers=jobs, initializer=_hold_gallery, initargs=(whole, preset)
        ) as pool:
            found = list(pool.map(_held_row, *rows, chunksize=4))
    return np.stack([row for row, _ in found]), np.array([scale for _, scale in found])


_HELD: dict[str, tuple[np.ndarray, Preset]] = {}


def _hold_gallery(whole: np.ndarray, preset: Preset) -> None:
    """A worker process's gallery, sent once rather than with every query."""
    single_threaded_blas()
    _HELD["gallery"] = (whole, preset)


def _held_row(
    profiles: np.ndarray, reach: np.ndarray, own: int | None, centres: np.ndarray | None
) -> tuple[np.ndarray, float]:
    return _parts_row(*_HELD["gallery"], profiles, reach, own, centres)


def _parts_row(
    whole: np.ndarray,
    preset: Preset,
    profiles: np.ndarray,
    reach: np.ndarray,
    own: int | None,
    centres: np.ndarray | None,
) -> tuple[np.ndarray, float]:
    if centres is not None:  # each shape at its own scales: its own entry has no say
        match = sized_dissimilarity(profiles, reach, whole, preset, centres)
        row = match.dissimilarity
        if own is not None:
            row[own] = 0.0
        return row, match.scale
    if own is None:
        match = part_dissimilarity(profiles, reach, whole, preset)
        return match.dissimilarity, match.scale
    scores = scale_scores(profiles, reach, whole, preset)
    scores[:, own] = np.inf
    match = best_scale(scores, preset)
    row = match.dissimilarity
    row[own] = 0.0
    return row, match.scale


def verified_ranking(
    d: np.ndarray,
    queries: Sequence[ShapeDescriptor],
    gallery: Sequence[ShapeDescriptor],
    scales: np.ndarray,
    preset: Preset,
    jobs: int = 1,
    themselves: bool = False,
) -> np.ndarray:
    """``d`` (q, n) with the candidates each single view is fitted on, of its best
    ``FEATURE_POOL``, ranked by their rigid fitness
    (:func:`worker.engine.rigid.verified_fitness`, as the service ranks them): their
    scores handed out again, the lowest to the candidate holding most of the query.
    ``scales``: each query's parts scale; ``themselves`` as :func:`parts_matrix` (a query
    is not its own candidate)."""
    out = d.copy()
    tasks = []
    for i, query in enumerate(queries):
        if not query.single_view:
            continue
        order = np.argsort(d[i], kind="stable")
        shortlist = order[order != i][:FEATURE_POOL] if themselves else order[:FEATURE_POOL]
        tasks.append((i, shortlist))
    # A candidate's anchors are the same for every query's fit: made once, and handed to
    # each worker once with its share of the queries (a hundred candidates' anchors a
    # query, about a megabyte each).
    shortlisted = sorted({int(c) for _, shortlist in tasks for c in shortlist})
    parallel = jobs > 1 and len(tasks) > 1
    with (
        ProcessPoolExecutor(max_workers=jobs, initializer=single_threaded_blas)
        if parallel
        else nullcontext()
    ) as pool:
        run = map if pool is None else partial(pool.map, chunksize=2)
        anchors = run(candidate_anchors, [gallery[c] for c in shortlisted])
        made = dict(zip(shortlisted, anchors, strict=True))
        held = {c: gallery[c] for c in shortlisted}
        shares = [tasks[start::jobs] for start in range(jobs)] if parallel else [tasks]
        # one share a worker (``run``'s chunks of two would hand both shares to one)
        fits = (map if pool is None else pool.map)(
            partial(
                _verified_share,
                queries=queries,
                scales=scales,
                metric=preset.units == "metric",
                gallery=held,
                anchors=made,
            ),
            shares,
        )
        fitted = {i: fitness for share in fits for i, fitness in share}
    for i, shortlist in tasks:
        if (fitness := fitted[i]) is not None:
            out[i, shortlist[verified_order(fitness)]] = np.sort(d[i, shortlist], kind="stable")
    return out


def _verified_share(
    tasks: Sequence[tuple[int, np.ndarray]],
    queries: Sequence[ShapeDescriptor],
    scales: np.ndarray,
    metric: bool,
    gallery: Mapping[int, ShapeDescriptor],
    anchors: Mapping[int, Anchors | None],
) -> list[tuple[int, np.ndarray | None]]:
    """:func:`verified_fitness` of each task's query (its position and its candidates'
    positions in the gallery) on its candidates, for :func:`verified_ranking`."""
    return [
        (
            i,
            verified_fitness(
                queries[i],
                [gallery[int(c)] for c in shortlist],
                float(scales[i]),
                metric,
                [anchors[int(c)] for c in shortlist],
            ),
        )
        for i, shortlist in tasks
    ]


def query_matrices(
    queries: Sequence[ShapeDescriptor],
    gallery: Sequence[ShapeDescriptor],
    preset: Preset,
    baselines: tuple[np.ndarray, np.ndarray] | None = None,
    jobs: int = 1,
    themselves: bool = False,
) -> dict[str, np.ndarray]:
    """Row key -> (q, n) dissimilarity of every query to every gallery shape.

    Parameters
    ----------
    queries, gallery : descriptors of the preset (with the parts modality).
    preset : the dissimilarity (D2's sigma over the gallery), fusion and partial weights.
    baselines : ShapeDNA descriptors of the queries and of the gallery; the baseline row
        is left out without them.
    themselves : the queries are the gallery (:func:`parts_matrix`).
    """
    out, scales = unverified_matrices(queries, gallery, preset, baselines, jobs, themselves)
    out[PRESET_ROW] = verified_ranking(
        out[PRESET_ROW], queries, gallery, scales, preset, jobs, themselves
    )
    return out


def unverified_matrices(
    queries: Sequence[ShapeDescriptor],
    gallery: Sequence[ShapeDescriptor],
    preset: Preset,
    baselines: tuple[np.ndarray, np.ndarray] | None = None,
    jobs: int = 1,
    themselves: bool = False,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """:func:`query_matrices` before its single views are verified (the preset's row as
    the parts and the whole modalities rank), and (q,) the scale the parts chose for each
    query."""
    flat = [
        {m: np.stack([d.vector(m) for d in side]) for m in MODALITIES}
        for side in (queries, gallery)
    ]
    if baselines is not None:
        flat[0][BASELINE], flat[1][BASELINE] = baselines
    out = cross_dissimilarities(flat[0], flat[1], preset)
    out[PARTS], scales = parts_matches(queries, gallery, preset, jobs, themselves=themselves)
    per = dict(out)
    if preset.units == "metric":
        asked, held = (np.stack([d.vector(SIZE) for d in side]) for side in (queries, gallery))
        per[SIZE] = preset_dissimilarity(SIZE, asked, held, preset)
    out[PRESET_ROW] = weighed_by_partiality(per, query_partiality(queries, preset), preset)
    return out, scales


def collection_matrices(
    descriptors: Sequence[ShapeDescriptor],
    per_modality: Mapping[str, np.ndarray],
    preset: Preset,
    jobs: int = 1,
) -> dict[str, np.ndarray]:
    """The parts modality and the preset's partiality-weighted score, all to all.

    Parameters
    ----------
    descriptors : (n,) of one collection.
    per_modality : modality -> (n, n) dissimilarity of the flat modalities.
    preset : with the parts modality.

    Returns
    -------
    {"parts": (n, n), PRESET_ROW: (n, n)}; row ``i`` weighed by query ``i``'s
    partiality (a single view's best verified, :func:`verified_ranking`), so neither is
    symmetric; a pair the parts cannot compare (:func:`ranked_last`)
    at the largest float.
    """
    parts, scales = parts_matches(descriptors, descriptors, preset, jobs, themselves=True)
    per = {**per_modality, PARTS: parts}
    shares = query_partiality(descriptors, preset)
    fused = weighed_by_partiality(per, shares, preset)
    fused = verified_ranking(fused, descriptors, descriptors, scales, preset, jobs, True)
    return {PARTS: ranked_last(parts), PRESET_ROW: ranked_last(fused)}


def ranked_last(d: np.ndarray) -> np.ndarray:
    """``d`` with its infinite entries at the largest float, so that the metrics rank them
    after every other: a query with no sample clear of its boundary, or in metric units a
    shape too small to hold it, is infinitely far by the parts."""
    finite: np.ndarray = np.where(np.isfinite(d), d, np.finfo(np.float64).max)
    return finite


def weighed_by_partiality(
    per: Mapping[str, np.ndarray], shares: np.ndarray, preset: Preset
) -> np.ndarray:
    """(q, n) the product rule of each query row ``i`` with the exponents of its
    partiality ``shares[i]`` (:func:`query_weights`; the preset's rule for a preset
    without partial weights)."""
    rule = "product" if preset.partial_weights else preset.fusion
    fused = np.empty_like(next(iter(per.values())))
    for i, share in enumerate(shares):
        weights = query_weights(preset, float(share))
        fused[i] = fuse({m: per[m][i] for m in weights}, rule, weights)
    return fused


def ranking_scores(d: np.ndarray, sources: np.ndarray, labels: np.ndarray) -> dict[str, float]:
    """Own class and own source at rank 1 and mAP of queries ``i`` made from gallery
    shape ``sources[i]`` (labels (n,) of the gallery); and own class at rank 1 averaged
    over the queries' classes (``class_mean``: each class's queries weigh alike, so a
    large class does not carry it; always answering one class scores one over the
    number of classes)."""
    nearest = np.argmin(d, axis=1)  # ties -> lower index
    own = labels[sources]
    hits = labels[nearest] == own
    return {
        "own_class": float(np.mean(hits)),
        "class_mean": float(np.mean([np.mean(hits[own == c]) for c in np.unique(own)])),
        "own_source": float(np.mean(nearest == sources)),
        "map": metrics.query_mean_average_precision(d, own, labels),
    }


def partiality_scores(
    gallery: Sequence[ShapeDescriptor],
    labels: Sequence[str],
    variants: Mapping[str, tuple[np.ndarray, Sequence[ShapeDescriptor]]],
    preset: Preset,
    baselines: tuple[np.ndarray, Mapping[str, np.ndarray]] | None = None,
    jobs: int = 1,
) -> dict[str, Any]:
    """The protocol's numbers.

    Parameters
    ----------
    gallery : descriptors of the whole meshes; labels : (n,) their classes.
    variants : variant name -> (sources (v,) int, descriptors of the partial copies),
        ``sources[j]`` the index of the whole copy ``j`` was made from.
    preset : the comparison.
    baselines : ShapeDNA of the wholes (n, k) and per variant (v, k).
    jobs : processes comparing the parts.

    Returns
    -------
    {"scores": {row: {variant: {"own_class", "class_mean", "own_source", "map"}}},
    "all_to_all": {row: {variant: {"nn", "first_tier", "second_tier", "dcg", "map",
    ..., "misses"}}}, "variants": {variant: {"count", "partiality_median", "looks_partial",
    "largest_class"}}}; ``looks_partial`` is the share of the variant's copies whose
    partiality is above 0 (weighed by the parts modality), ``largest_class`` the share of
    its copies in their largest class (the own class of a ranking that always answers
    it); ``misses`` counts, per class, the copies whose nearest other copy is of each
    other class (:func:`~worker.recognition.metrics.nearest_neighbor_misses`). A variant
    whose copies leave a class with a single copy has no all-to-all scores (nothing
    relevant to find).
    """
    labels_arr = np.asarray([str(x) for x in labels])
    rows: dict[str, dict[str, dict[str, float]]] = {}
    among: dict[str, dict[str, dict[str, Any]]] = {}
    about: dict[str, dict[str, Any]] = {}
    for name, (sources, copies) in variants.items():
        pair = None if baselines is None else (baselines[1][name], baselines[0])
        matrices = query_matrices(copies, gallery, preset, pair, jobs)
        for row, d in matrices.items():
            rows.setdefault(row, {})[name] = ranking_scores(d, np.asarray(sources), labels_arr)
        copy_labels = labels_arr[np.asarray(sources, dtype=np.int64)]
        if len(copies) and np.unique(copy_labels, return_counts=True)[1].min() >= 2:
            pair = None if baselines is None else (baselines[1][name], baselines[1][name])
            each = query_matrices(copies, copies, preset, pair, jobs, themselves=True)
            for row, d in each.items():
                # A copy the parts cannot compare ranks the others by index, as against
                # the wholes.
                ranking = ranked_last(d)
                among.setdefault(row, {})[name] = {
                    **metrics.retrieval_scores(ranking, copy_labels),
                    "misses": metrics.nearest_neighbor_misses(ranking, copy_labels),
                }
        shares = query_partiality(copies, preset)
        about[name] = {
            "count": len(copies),
            "partiality_median": float(np.median(shares)),
            "looks_partial": float(np.mean(shares > 0)),
            "largest_class": float(np.unique(copy_labels, return_counts=True)[1].max())
            / max(len(copies), 1),
        }
    return {"scores": rows, "all_to_all": among, "variants": about}
