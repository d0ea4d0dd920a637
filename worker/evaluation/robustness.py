"""How much a descriptor cares about the triangles: the tessellation-robustness protocol.

Pure functions on descriptor arrays (the describing is :mod:`.compute`'s, the
variants :mod:`.variants`'). For every mesh of a labelled collection and each of
its variants (same surface, other triangles), per modality, for the preset's own
fused score and for the ShapeDNA baseline:

* **class retrieval**: the variant's nearest *original*, its own source left out of
  the gallery, is of its class (a user uploading another file of an enrolled kind
  of object gets the right kind);
* **self retrieval**: with its own source in the gallery, the nearest original is
  its source (reported without a bar: a fully pose-invariant descriptor may rightly
  tie two poses of one figure);
* **tessellation gap**: the median distance between a mesh and its variants over the
  median distance from a mesh to the nearest original of another class. Below 1 a
  file's tessellation moves its descriptor less than the nearest other kind of object
  is away; the bar is 0.1.

And on a set of poses of one object (SCAPE), next to the labelled collection in one
gallery, the **pose invariance**: the median distance between two poses over the
median distance between two objects of different classes of the collection, and
how many poses have their nearest neighbour outside the pose set; and, with the
poses remeshed at two resolutions, the **cross-resolution pose retrieval**: every
pose at one resolution queries the same poses at the other, and should find its own
pose first (one body in many poses is the hardest gallery there is for a file's
tessellation to confuse).

Distances are the preset's: D1 or D2 per modality (for D2, sigma over the gallery
of originals), fused with the preset's rule and weights. A product ``prod_m D_m^w_m``
is measured on its ``sum_m w_m``-th root, the weighted geometric mean of the
modalities' distances: the same ranking, on the scale of one modality's distance. The
product itself multiplies ratios (two modalities at a gap of 0.05 each make a product
at 0.0025), so its gaps and ratios would shrink with the weights alone and could not be
compared with a modality's, nor between two choices of weights.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from worker.engine.compare import dissimilarity, fuse, gallery_sigma
from worker.engine.presets import MODALITIES, PARTS, Preset

from .shapedna import BASELINE, shapedna_dissimilarity

#: The bar on the tessellation gap.
GAP_BAR = 0.1
#: Row key of the preset's own fused score.
PRESET_ROW = "preset"
#: The variants of every pose that the cross-resolution pose retrieval compares.
POSE_RESOLUTIONS = ("remeshed-8k", "remeshed-15k")


def row_titles(preset: Preset) -> dict[str, str]:
    """Row key -> title, in table order (the parts modality's row when the preset has it:
    the tessellation protocol only; a whole query's score does not use it)."""
    fused = "+".join(m.upper() if m != "spectrum" else "Spectrum" for m in preset.fused_modalities)
    parts = {PARTS: "Parts"} if preset.has_parts else {}
    return {
        "gdm": "GDM",
        "ddt": "DDT",
        "spectrum": "Spectrum",
        **parts,
        PRESET_ROW: f"{fused} {preset.fusion} (the preset's score)",
        BASELINE: "ShapeDNA (lapy)",
    }


def protocol_distance(per: Mapping[str, np.ndarray], preset: Preset) -> np.ndarray:
    """The preset's fused score on the protocol's scale: its sum, or the
    ``sum_m w_m``-th root of its product (the modalities' weighted geometric mean;
    the same ranking as the product, in the units of one modality's distance).

    Parameters
    ----------
    per : modality -> dissimilarities (any shape, the same for every modality).
    preset : the fusion rule and weights.
    """
    weights = {m: preset.weight(m) for m in preset.fused_modalities}
    fused = fuse({m: per[m] for m in preset.fused_modalities}, preset.fusion, weights)
    total = sum(weights.values())
    if preset.fusion == "product" and total > 0:
        fused = fused ** (1.0 / total)
    return fused


def cross_dissimilarities(
    queries: Mapping[str, np.ndarray],
    gallery: Mapping[str, np.ndarray],
    preset: Preset,
) -> dict[str, np.ndarray]:
    """Row key -> (p, q) dissimilarity of every query to every gallery object (and
    ShapeDNA's, when both sides have ``BASELINE``)."""
    per: dict[str, np.ndarray] = {}
    for m in MODALITIES:
        sigma = gallery_sigma(gallery[m]) if preset.dissimilarity == "D2" else None
        per[m] = dissimilarity(queries[m], gallery[m], preset.dissimilarity, sigma)
    out = dict(per)
    out[PRESET_ROW] = protocol_distance(per, preset)
    if BASELINE in queries and BASELINE in gallery:
        q, g = queries[BASELINE], gallery[BASELINE]
        both = shapedna_dissimilarity(np.concatenate([q, g]))
        out[BASELINE] = both[: len(q), len(q) :]
    return out


def tessellation_scores(
    originals: Mapping[str, np.ndarray],
    labels: Sequence[str],
    variants: Mapping[str, tuple[np.ndarray, Mapping[str, np.ndarray]]],
    preset: Preset,
    parts: tuple[np.ndarray, Mapping[str, np.ndarray]] | None = None,
) -> dict[str, dict[str, Any]]:
    """The protocol's numbers per row.

    Parameters
    ----------
    originals : modality -> (n, M) float, and optionally ``BASELINE`` -> (n, k).
    labels : (n,) class of each original.
    variants : variant name -> (sources (v,) int, modality -> (v, M) float
        [and ``BASELINE``]), ``sources[j]`` the index of the original variant ``j``
        was made from.
    preset : the dissimilarity, fusion rule and weights.
    parts : the parts modality's dissimilarities, originals to originals (n, n) and
        per variant to the originals (v, n) (:func:`.partiality.parts_matrix`); its row
        is left out without them.

    Returns
    -------
    row key -> {"class_retrieval", "self_retrieval", "gap", "passes",
    "variants": {name: {"count", "class_retrieval", "self_retrieval", "gap"}}};
    rates are fractions, ``passes`` says whether class retrieval is 100% and the gap
    below ``GAP_BAR``.
    """
    labels_arr = np.asarray([str(x) for x in labels])
    among = cross_dissimilarities(originals, originals, preset)
    n = len(labels_arr)
    other_class = labels_arr[:, None] != labels_arr[None, :]
    cross = {}
    for name, (sources, vectors) in variants.items():
        cross[name] = (np.asarray(sources), cross_dissimilarities(vectors, originals, preset))
    if parts is not None:
        among[PARTS] = parts[0]
        for name, (_, matrices) in cross.items():
            matrices[PARTS] = parts[1][name]
    scores: dict[str, dict[str, Any]] = {}
    for row, matrix in among.items():
        nearest_other = np.where(other_class, matrix, np.inf).min(axis=1)
        scale = float(np.median(nearest_other))
        per_variant: dict[str, dict[str, Any]] = {}
        all_self, all_class, all_distance = [], [], []
        for name, (sources, matrices) in cross.items():
            d = matrices[row]
            rows = np.arange(len(sources))
            own = d[rows, sources]
            self_hit = np.argmin(d, axis=1) == sources
            without = d.copy()
            without[rows, sources] = np.inf
            class_hit = labels_arr[np.argmin(without, axis=1)] == labels_arr[sources]
            per_variant[name] = {
                "count": len(sources),
                "class_retrieval": float(class_hit.mean()),
                "self_retrieval": float(self_hit.mean()),
                "gap": float(np.median(own) / scale),
            }
            all_self.append(self_hit)
            all_class.append(class_hit)
            all_distance.append(own)
        class_rate = float(np.concatenate(all_class).mean())
        gap = float(np.median(np.concatenate(all_distance)) / scale)
        scores[row] = {
            "class_retrieval": class_rate,
            "self_retrieval": float(np.concatenate(all_self).mean()),
            "gap": gap,
            "passes": bool(class_rate == 1.0 and gap < GAP_BAR),
            "nearest_other_class_median": scale,
            "originals": n,
            "variants": per_variant,
        }
    return scores


def pose_invariance(
    poses: Mapping[str, np.ndarray],
    collection: Mapping[str, np.ndarray],
    labels: Sequence[str],
    preset: Preset,
    pose_names: Sequence[str],
    names: Sequence[str],
) -> dict[str, dict[str, Any]]:
    """Poses of one object against a labelled collection, in one gallery.

    Parameters
    ----------
    poses : modality -> (p, M) float [and ``BASELINE``], poses of one object.
    collection : modality -> (n, M) float [and ``BASELINE``].
    labels : (n,) classes of the collection.
    preset : the dissimilarity, fusion rule and weights.
    pose_names : (p,) names of the poses; names : (n,) of the collection's meshes.

    Returns
    -------
    row key -> {"ratio": median pose-pose distance / median between-class distance
    of the collection, "foreign_nearest": poses whose nearest neighbour in the
    combined gallery is not another pose, "foreign": [pose, its nearest mesh] for
    each of them, "poses"}.
    """
    keys = [k for k in collection if k in poses]
    combined = {k: np.concatenate([poses[k], collection[k]]) for k in keys}
    matrices = cross_dissimilarities(combined, combined, preset)
    p = len(next(iter(poses.values())))
    labels_arr = np.asarray([str(x) for x in labels])
    between = labels_arr[:, None] != labels_arr[None, :]
    out: dict[str, dict[str, Any]] = {}
    for row, d in matrices.items():
        d = 0.5 * (d + d.T)
        within = d[:p, :p][np.triu_indices(p, 1)]
        coll = d[p:, p:][np.triu_indices(len(labels_arr), 1)]
        coll_between = coll[between[np.triu_indices(len(labels_arr), 1)]]
        np.fill_diagonal(d, np.inf)
        nearest = np.argmin(d[:p], axis=1)
        foreign = [[pose_names[i], names[j - p]] for i, j in enumerate(nearest.tolist()) if j >= p]
        out[row] = {
            "ratio": float(np.median(within) / np.median(coll_between)),
            "foreign_nearest": len(foreign),
            "foreign": foreign,
            "poses": p,
        }
    return out


def cross_resolution(
    first: Mapping[str, np.ndarray], second: Mapping[str, np.ndarray], preset: Preset
) -> dict[str, dict[str, Any]]:
    """The same poses at two resolutions: each queries the poses at the other one.

    Parameters
    ----------
    first, second : modality -> (p, M) float [and ``BASELINE``]; row ``i`` of both
        is pose ``i``.
    preset : the dissimilarity, fusion rule and weights.

    Returns
    -------
    row key -> {"rank1": fraction of the ``2 p`` queries (each pose at each
    resolution) whose nearest pose at the other resolution is its own, "ratio":
    median over those queries of the distance to its own pose at the other
    resolution over the distance to the nearest other pose at its own resolution
    (below 1: the resolution moves a pose less than the nearest other pose is away),
    "poses": p}.
    """

    # Per direction: the queries against the other resolution, and against their own.
    directions = [
        (cross_dissimilarities(first, second, preset), cross_dissimilarities(first, first, preset)),
        (
            cross_dissimilarities(second, first, preset),
            cross_dissimilarities(second, second, preset),
        ),
    ]
    out: dict[str, dict[str, Any]] = {}
    for row in directions[0][0]:
        hits, ratios = [], []
        for across, same in directions:
            d = across[row]
            own = np.diagonal(d)
            hits.append(np.argmin(d, axis=1) == np.arange(len(d)))
            others = same[row].copy()
            np.fill_diagonal(others, np.inf)
            ratios.append(own / others.min(axis=1))
        out[row] = {
            "rank1": float(np.concatenate(hits).mean()),
            "ratio": float(np.median(np.concatenate(ratios))),
            "poses": len(hits[0]),
        }
    return out
