"""The parts modality: local intrinsic profiles that a cut or a hole leaves unchanged
away from it, and how much of a query's surface a candidate contains.

Every modality of the paper sees the whole surface at once (the GDM's singular values,
the DDT's core, the spectrum) and is normalized by its whole area, so a query missing a
slab of its surface moves farther than another object does. This one describes a
surface by what is around each of its samples, and compares a part with a whole by
asking whether the whole has, for each sample of the part, a sample that looks the
same.

Profiles
--------
Around each of the ``m`` samples the GDM is computed from (farthest-point samples,
:func:`worker.engine.geodesic.farthest_point_samples`), the area ``a(c, r)`` of the
geodesic ball of radius ``r``, over ``pi r^2`` (1 on a plane, below 1 where the surface
ends or narrows, a thin limb's falling like ``1 / r``), on a grid of radii
``r_i = r_0 2^(i / 8)`` in units of the square root of the surface's area, as its
logarithm (:func:`ball_area_profiles`). These are the geodesic distances of the GDM
itself, summarized per sample instead of by the whole matrix's singular values: intrinsic,
so a pose does not move them, and area-weighted, so the triangulation hardly does.
Beside them, on the same radii, how far each ball's centroid lies from its sample over
the radius (:func:`ball_centroid_profiles`, about ``|H| r / 4``): extrinsic, it sees how
the surface bends where the areas see only its Gaussian curvature. A preset compares the
first ``parts_centroid_radii`` of them, weighted ``parts_centroid_weight``, valid where
the areas are (:func:`compared_profiles`, :func:`samples_at_scale`).

A sample's ball of radius ``r`` is the same on a part as on the whole when it does not
reach the part's open boundary, that is when ``r`` is below the sample's *reach*, its
geodesic distance to the boundary (:func:`boundary_reach`; infinite on a closed
surface). Only those radii of a query's sample are compared; the rest are what the cut
disturbed.

Comparison
----------
A part has less area than its whole, so normalized by its own area it is too large:
by ``1 / sqrt(kappa)`` in length when it keeps ``kappa`` of the area. The query's radii
are therefore tried at the scales ``s_j = 2^(j / 8p)``, ``j = 0 .. J``, ``p`` scales per
step of the grid (its grid column ``j / p + 2 k`` against the gallery's ``2 k``; between
two columns the log profile is interpolated linearly in ``log r``; past the last column
a radius is left out, as one past the sample's reach), with a prior
``lambda log s_j`` against shrinking a whole. For one scale, query sample ``c`` with
valid radii ``V_c`` is as far from candidate ``C`` as the root-mean-square difference
over ``V_c`` to its nearest sample of ``C``; the dissimilarity is the mean of that over
the query's samples, each weighted by ``|V_c|`` (samples far from the cut carry more of
its shape). It asks how much of the query the candidate contains, not the other way
round: a whole is close to each of its parts. The scale is chosen once per query, by its
best match (:func:`part_dissimilarity`); ``1 / s^2`` then estimates the share of the
surface the query has. In a collection of metric units the sizes give that share for
each candidate, ``a / A``, and each is compared near its own scale instead
(:func:`sized_dissimilarity`); a candidate too small to hold the query is not.

Measured on TOSCA's partial copies (docs/evaluation.md, sec. "Partial queries"), with
the paper's and the spectrum's modalities as the complete queries' score
(:func:`worker.engine.compare.query_weights`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .presets import Preset
from .tol import TOL


@dataclass(frozen=True)
class PartsMatch:
    """A query's parts dissimilarity to each candidate, at the scale chosen for it.

    Attributes
    ----------
    dissimilarity : (n,) float, one per candidate (``inf`` when no sample of the query
        has enough radii clear of its boundary).
    scale : the query's scale ``s_j`` (1 for a whole).
    j : its index ``j`` (0 for a whole).
    """

    dissimilarity: np.ndarray
    scale: float
    j: int = 0

    @property
    def kept_share(self) -> float:
        """The share of a whole's surface the query seems to have, ``1 / s^2``."""
        return 1.0 / self.scale**2


#: Radii per doubling of the profiles' grid (the compared radii take every second one,
#: and a query's scales step along it).
GRID_STEPS_PER_OCTAVE = 8


def scale_count(preset: Preset) -> int:
    """The number of query scales tried: ``parts_scale_steps`` per step of the grid, over
    ``parts_scales - 1 + parts_extra_scales`` steps."""
    steps = preset.parts_scales - 1 + preset.parts_extra_scales
    return steps * preset.parts_scale_steps + 1


def grid_radii(preset: Preset) -> np.ndarray:
    """(C,) float, the radii the profiles are stored at, in units of the square root of
    the surface's area: ``r_0 2^(i / 8)``, enough columns for the compared radii at
    every query scale."""
    if preset.parts_first_radius is None:
        return np.zeros(0)
    return _radii(preset.parts_first_radius, 2 * (preset.parts_radii - 1) + preset.parts_scales)


def ball_area_profiles(
    distances: np.ndarray, mass: np.ndarray, first_radius: float, columns: int
) -> np.ndarray:
    """Log of the area of each sample's geodesic balls over ``pi r^2``, at the radii
    ``r_i = first_radius 2^(i / 8)``, ``i < columns``.

    One pass over the distances (:func:`_ball_sums`); :func:`ball_area_profiles_reference`
    is the plain version.

    Parameters
    ----------
    distances : (n, m) float, geodesic distances from ``m`` samples (columns) to every
        vertex.
    mass : (n,) float, lumped vertex areas.
    first_radius : ``r_0``, in the distances' unit.
    columns : number of radii.

    Returns
    -------
    (m, C) float, ``log(max(a(c, r) / (pi r^2), floor))``.
    """
    return ball_profiles(distances, mass, first_radius, columns)[0]


def ball_area_profiles_reference(
    distances: np.ndarray, mass: np.ndarray, first_radius: float, columns: int
) -> np.ndarray:
    """:func:`ball_area_profiles` by summing the vertex areas within each radius."""
    radii = _radii(first_radius, columns)
    d = np.asarray(distances, dtype=np.float64)
    areas = np.stack([mass @ (d <= r) for r in radii], axis=1)
    return _log_ratio(areas, radii)


def ball_centroid_profiles(
    distances: np.ndarray,
    mass: np.ndarray,
    positions: np.ndarray,
    samples: np.ndarray,
    first_radius: float,
    columns: int,
) -> np.ndarray:
    """How far each sample's geodesic ball's centroid lies from the sample, over the
    radius, ``|centroid(c, r) - x_c| / r``, on :func:`ball_area_profiles`' radii.

    An integral invariant (Pottmann et al. 2007, "Principal curvatures from the integral
    invariant viewpoint"): on a smooth surface the centroid of a small geodesic disc lies
    ``|H| r^2 / 4`` from its centre along the normal (``H`` the mean curvature), so this
    ratio is ``|H| r / 4``, scale-free, and averaged over the disc instead of
    differentiated (noise moves it little). The area profiles are intrinsic; this sees
    how the surface bends in space, which tells a limb's section from a flat back
    (docs/decisions.md, "Default v14: the discs' centroids beside their areas").

    Parameters
    ----------
    distances, mass, first_radius, columns : as :func:`ball_area_profiles`.
    positions : (n, 3) float, the vertices, in the distances' unit.
    samples : (m,) int, the vertex of each sample (each column's own).

    Returns
    -------
    (m, C) float; :func:`ball_centroid_profiles_reference` is the plain version.
    """
    centroids = ball_profiles(distances, mass, first_radius, columns, positions, samples)[1]
    assert centroids is not None
    return centroids


def ball_profiles(
    distances: np.ndarray,
    mass: np.ndarray,
    first_radius: float,
    columns: int,
    positions: np.ndarray | None = None,
    samples: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`ball_area_profiles` and, given ``positions`` and ``samples``,
    :func:`ball_centroid_profiles` (else None), from one pass over the distances."""
    weights = np.asarray(mass, dtype=np.float64)[:, None]
    if positions is not None:
        weights = weights * np.column_stack([np.ones(len(positions)), positions])
    sums = _ball_sums(distances, weights, first_radius, columns)  # (m, C, 1 or 4)
    radii = _radii(first_radius, columns)
    areas = _log_ratio(sums[..., 0], radii)
    if positions is None or samples is None:
        return areas, None
    offsets = sums[..., 1:] / sums[..., :1] - np.asarray(positions)[samples][:, None, :]
    centroids: np.ndarray = np.linalg.norm(offsets, axis=2) / radii
    return areas, centroids


def ball_centroid_profiles_reference(
    distances: np.ndarray,
    mass: np.ndarray,
    positions: np.ndarray,
    samples: np.ndarray,
    first_radius: float,
    columns: int,
) -> np.ndarray:
    """:func:`ball_centroid_profiles` by averaging the positions within each radius."""
    d = np.asarray(distances, dtype=np.float64)
    out = np.empty((d.shape[1], columns))
    for i, r in enumerate(_radii(first_radius, columns)):
        for c in range(d.shape[1]):
            inside = d[:, c] <= r
            centroid = mass[inside] @ positions[inside] / mass[inside].sum()
            out[c, i] = np.linalg.norm(centroid - positions[samples[c]]) / r
    return out


def _radii(first_radius: float, columns: int) -> np.ndarray:
    radii: np.ndarray = first_radius * 2.0 ** (np.arange(columns) / GRID_STEPS_PER_OCTAVE)
    return radii


def _ball_sums(
    distances: np.ndarray, weights: np.ndarray, first_radius: float, columns: int
) -> np.ndarray:
    """(m, C, w) the sums of each vertex's ``weights`` (n, w) over each sample's geodesic
    balls of the radii ``first_radius 2^(i / 8)``.

    One pass over the distances: each vertex goes to the first radius that reaches it
    (``ceil(8 log2(d / r_0))`` on this geometric grid, which a binary search takes ten
    times as long to find), and the cumulative sums are the balls'."""
    n, m = distances.shape
    ratio = np.maximum(np.asarray(distances, dtype=np.float64), 0.0) / first_radius
    with np.errstate(divide="ignore"):  # a sample's own vertex: log2(0) = -inf, bin 0
        first = np.ceil(GRID_STEPS_PER_OCTAVE * np.log2(ratio))
    first = np.clip(first, 0, columns).astype(np.int64)
    first += (columns + 1) * np.arange(m, dtype=np.int64)[None, :]
    bins = first.ravel()
    sums = np.stack(
        [
            np.bincount(
                bins,
                weights=np.broadcast_to(weight[:, None], (n, m)).ravel(),
                minlength=m * (columns + 1),
            )
            for weight in np.asarray(weights, dtype=np.float64).T
        ],
        axis=1,
    )
    out: np.ndarray = np.cumsum(sums.reshape(m, columns + 1, -1), axis=1)[:, :columns]
    return out


def _log_ratio(areas: np.ndarray, radii: np.ndarray) -> np.ndarray:
    ratio = areas / (np.pi * radii**2)
    profiles: np.ndarray = np.log(np.maximum(ratio, TOL.parts_ratio_floor))
    return profiles


def boundary_reach(distances: np.ndarray, boundary: np.ndarray) -> np.ndarray:
    """Each sample's geodesic distance to the surface's open boundary.

    Parameters
    ----------
    distances : (n, m) float, from ``m`` samples (columns) to every vertex.
    boundary : (b,) int, the boundary vertices (empty for a closed surface).

    Returns
    -------
    (m,) float, ``inf`` everywhere when there is no boundary.
    """
    if len(boundary) == 0:
        return np.full(distances.shape[1], np.inf)
    reach: np.ndarray = np.asarray(distances[boundary].min(axis=0), dtype=np.float64)
    return reach


def compared_profiles(profiles: np.ndarray, preset: Preset) -> np.ndarray:
    """(..., m, K + K') of wholes' (..., m, C) or (..., m, 2C) profiles: the radii a query's
    are compared with (every second column of the grid; a gallery keeps only these), the
    areas' ``parts_radii`` and, when the preset compares them, the first
    ``parts_centroid_radii`` of the centroids' (:func:`with_centroids`) times their
    weight."""
    areas: np.ndarray = profiles[..., 0 : 2 * preset.parts_radii : 2]
    if not preset.parts_centroid_radii:
        return areas
    first = len(grid_radii(preset))
    centroids = profiles[..., first : first + 2 * preset.parts_centroid_radii : 2]
    return np.concatenate([areas, preset.parts_centroid_weight * centroids], axis=-1)


def with_centroids(areas: np.ndarray, centroids: np.ndarray | None) -> np.ndarray:
    """A descriptor's parts profiles: (m, C) :func:`ball_area_profiles`, followed by the
    (m, C) :func:`ball_centroid_profiles` on the same radii when there are any."""
    return areas if centroids is None else np.concatenate([areas, centroids], axis=-1)


def area_profiles(profiles: np.ndarray, preset: Preset) -> np.ndarray:
    """(..., m, C) the area profiles of a query's (..., m, C) or (..., m, 2C)
    (:func:`with_centroids`): what the passes that shortlist compare."""
    areas: np.ndarray = profiles[..., : len(grid_radii(preset))]
    return areas


#: Samples a coarse comparison keeps of a query and of each candidate (:func:`coarse`).
COARSE_SAMPLES = 64


def clearest(reach: np.ndarray, count: int) -> np.ndarray:
    """The indices, in order, of the ``count`` samples farthest from the query's boundary
    (``reach``; among equals the first: the farthest-point order spreads them)."""
    keep: np.ndarray = np.sort(np.argsort(-reach, kind="stable")[:count])
    return keep


def coarse(
    profiles: np.ndarray, reach: np.ndarray, gallery: np.ndarray, preset: Preset
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A query and candidates cut down for a coarse first comparison that shortlists
    candidates: the query's ``COARSE_SAMPLES`` samples farthest from its boundary
    (:func:`clearest`), and each candidate's first ``COARSE_SAMPLES`` samples (spread over
    its surface by the same farthest-point order), their area profiles alone.

    Returns
    -------
    profiles (q', C), reach (q',), gallery (n, m'', K).
    """
    keep = clearest(reach, COARSE_SAMPLES)
    areas = area_profiles(profiles[keep], preset)
    return areas, reach[keep], gallery[:, :COARSE_SAMPLES, : preset.parts_radii]


def part_dissimilarity(
    profiles: np.ndarray,
    reach: np.ndarray,
    gallery: np.ndarray,
    preset: Preset,
    scales: range | None = None,
) -> PartsMatch:
    """How much of a query's surface each candidate does *not* contain (module docstring).

    Parameters
    ----------
    profiles : (m, C) float, the query's :func:`ball_area_profiles` on :func:`grid_radii`.
    reach : (m,) float, its samples' :func:`boundary_reach`, in the radii's unit.
    gallery : (n, m', K) float, the candidates' :func:`compared_profiles`.
    preset : the radii, the scales and their prior.
    scales : the scale indices ``j`` tried (default all :func:`scale_count` of the
        preset's; ``range(1)`` compares the query as a whole).

    Returns
    -------
    PartsMatch
    """
    return best_scale(scale_scores(profiles, reach, gallery, preset, scales), preset, scales)


#: Candidates a shortlist compares at every scale tried: the best at the scale a coarse
#: pass chose, and those within ``SCALE_RIVAL_MARGIN`` of the best match at the scale they
#: choose (:func:`led_part_dissimilarity`).
SCALE_LEADERS = 8
SCALE_RIVAL_MARGIN = 0.01


def led_part_dissimilarity(
    profiles: np.ndarray,
    reach: np.ndarray,
    gallery: np.ndarray,
    preset: Preset,
    scales: range,
    start: int,
    leaders: int = SCALE_LEADERS,
    margin: float = SCALE_RIVAL_MARGIN,
) -> PartsMatch:
    """:func:`part_dissimilarity` over ``scales`` for a shortlist whose best scale a
    coarse pass put at ``start`` (one of ``scales``), comparing most candidates at one or
    two scales instead of all: every candidate at ``start``, its ``leaders`` best there
    at every scale, then every candidate at the best scale found; a candidate that scores
    within ``margin`` (relative) of the best match there is compared at every scale as
    well, and so on until none is left. The dissimilarities are
    :func:`part_dissimilarity`'s at the scale chosen; the scale is its, unless a
    candidate compared at fewer scales would have matched best at one where it was not
    compared (docs/decisions.md, "The shortlist's scale chosen by its leaders")."""
    start_row = scales.index(start)
    scores = np.full((len(scales), len(gallery)), np.inf)
    done = np.zeros(scores.shape, dtype=bool)

    def compare(rows: range, columns: np.ndarray) -> None:
        if len(rows) and len(columns):
            scores[rows.start : rows.stop, columns] = scale_scores(
                profiles, reach, gallery[columns], preset, scales[rows.start : rows.stop]
            )
            done[rows.start : rows.stop, columns] = True

    compare(range(start_row, start_row + 1), np.arange(len(gallery)))
    leading = np.argsort(scores[start_row], kind="stable")[:leaders]
    compare(range(start_row), leading)
    compare(range(start_row + 1, len(scales)), leading)
    while True:
        row = int(np.argmin(scores.min(axis=1)))
        compare(range(row, row + 1), np.flatnonzero(~done[row]))
        best = scores.min()
        if not np.isfinite(best):  # no sample of the query compared at any scale
            break
        rivals = np.flatnonzero((scores[row] <= best * (1 + margin)) & ~done.all(axis=0))
        if not len(rivals):
            break
        compare(range(row), rivals)  # their row is compared already
        compare(range(row + 1, len(scales)), rivals)
    return best_scale(scores, preset, scales)


def scale_scores(
    profiles: np.ndarray,
    reach: np.ndarray,
    gallery: np.ndarray,
    preset: Preset,
    scales: range | None = None,
    rough: bool = False,
) -> np.ndarray:
    """(J, n) the dissimilarity to each candidate at each scale tried, its prior added
    (``inf`` at a scale where no sample of the query has enough radii clear of its
    boundary). Candidates can be scored in blocks and the blocks' columns joined
    before :func:`best_scale` chooses. Parameters as :func:`part_dissimilarity`;
    ``rough``: each nearest distance as single precision leaves it (off by about 1e-5 in
    each squared distance, :func:`_nearest_squared_rough`), for a pass that only
    shortlists."""
    prior = preset.parts_scale_prior
    whole = np.ascontiguousarray(gallery)
    n, per_shape = whole.shape[:2]
    flat = whole.reshape(n * per_shape, -1)
    tried = range(scale_count(preset)) if scales is None else scales
    out = np.full((len(tried), n), np.inf)
    at_scales = [
        (row, j, *samples_at_scale(profiles, reach, j, preset)) for row, j in enumerate(tried)
    ]
    compared = [(row, j, query, within) for row, j, query, within in at_scales if len(query)]
    if n == 0 or not compared:
        return out
    asked = [(query, within.astype(np.float64)) for _, _, query, within in compared]
    radii = preset.parts_radii
    if rough:
        found = _nearest_squared_rough(flat, asked, per_shape)
    else:
        rows = _GalleryRows(flat, radii)
        found = [_nearest_squared(query, valid, rows, n, per_shape) for query, valid in asked]
    for (row, j, _, within), nearest in zip(compared, found, strict=True):
        used = within[:, :radii].sum(axis=1).astype(np.float64)
        rms = np.sqrt(np.maximum(nearest, 0.0) / used[:, None])
        out[row] = used @ rms / used.sum() + prior * np.log(_scale(j, preset))
    return out


#: Scales either side of the one a candidate's size implies that a query of a collection
#: of metric units is tried at (:func:`sized_dissimilarity`).
SIZED_SCALES = 2


def compared_by_size(preset: Preset, single_view: bool) -> bool:
    """Whether a query is compared with each candidate near the scale their sizes imply
    (:func:`sized_dissimilarity`) rather than at one scale for all: in a collection of
    metric units, unless it is a single view described two-sided, whose unseen side is
    its seen side's mirror image, so that its area does not measure its share."""
    return preset.units == "metric" and not (single_view and preset.two_sided_views)


def sized_scales(query_size: float, sizes: np.ndarray, preset: Preset) -> np.ndarray:
    """(n,) int, the scale index ``j`` at which a query of size ``sqrt(a)`` is the part of
    each candidate of size ``sqrt(A)`` (``sizes``, the same unit) that its area says it
    is: ``s_j = sqrt(A / a)``, ``j = 8 p log2 s`` rounded (it may lie outside the scales
    tried: a query larger than the candidate, or a smaller share than they reach)."""
    ratio = np.asarray(sizes, dtype=np.float64) / query_size
    steps = GRID_STEPS_PER_OCTAVE * preset.parts_scale_steps
    centres: np.ndarray = np.rint(steps * np.log2(ratio)).astype(np.int64)
    return centres


#: A whole whose area is below this share of a query's cannot hold it. Not 1: noise adds
#: area to the resampled surface (at 1% of the diagonal a median third on TOSCA, up to
#: 2.9 times), and a whole that looks smaller than a query is compared with it as a whole.
HOLDING_AREA = 0.5


def can_hold(centres: np.ndarray, preset: Preset) -> np.ndarray:
    """(n,) bool, which candidates of :func:`sized_scales`' ``centres`` are large enough
    to hold the query: an area at least ``HOLDING_AREA`` times the query's."""
    least = sized_scales(1.0, np.array([np.sqrt(HOLDING_AREA)]), preset)[0]
    held: np.ndarray = centres >= least
    return held


def sized_dissimilarity(
    profiles: np.ndarray,
    reach: np.ndarray,
    gallery: np.ndarray,
    preset: Preset,
    centres: np.ndarray,
) -> PartsMatch:
    """:func:`part_dissimilarity` with each candidate's own scales: the best of the
    ``SIZED_SCALES`` either side of its ``centres`` (:func:`sized_scales`), the window cut
    to the scales tried (a candidate that looks smaller than the query, but not too small
    to hold it, is compared with it as a whole), ``inf`` for one too small to hold it
    (:func:`can_hold`). A part in the units of its whole need not guess its share
    (docs/decisions.md, "Parts of metric collections compared at their size"). The
    match's ``scale`` is its best candidate's."""
    last = scale_count(preset) - 1
    holds = can_hold(centres, preset)
    first_scale = np.clip(centres - SIZED_SCALES, 0, last)
    last_scale = np.clip(centres + SIZED_SCALES, 0, last)
    out = np.full(len(gallery), np.inf)
    chosen = np.zeros(len(gallery), dtype=np.int64)
    windows = np.stack([first_scale, last_scale], axis=1)[holds]
    for a, b in np.unique(windows, axis=0):
        members = np.flatnonzero(holds & (first_scale == a) & (last_scale == b))
        scores = scale_scores(profiles, reach, gallery[members], preset, range(a, b + 1))
        out[members] = scores.min(axis=0)
        chosen[members] = a + scores.argmin(axis=0)
    if not np.isfinite(out).any():
        return PartsMatch(out, 1.0)
    best = int(chosen[np.argmin(out)])
    return PartsMatch(out, _scale(best, preset), best)


def scale_columns(j: int, preset: Preset) -> np.ndarray:
    """(K,) float, the grid columns of a query's profiles compared with a whole's radii at
    scale ``j``, ``j / p + 2 k`` (a whole keeps every second column of the grid,
    :func:`compared_profiles`); fractional between two columns."""
    columns: np.ndarray = j / preset.parts_scale_steps + 2.0 * np.arange(preset.parts_radii)
    return columns


def samples_at_scale(
    profiles: np.ndarray, reach: np.ndarray, j: int, preset: Preset
) -> tuple[np.ndarray, np.ndarray]:
    """A query's samples as scale ``j`` compares them: (q', K) their profiles at
    :func:`scale_columns` (linear between two columns of the grid, which is geometric:
    linear in ``log r``) and (q', K) bool, which of those radii are within the sample's
    reach and the profiles' last column (past ``parts_scales``, the largest are not);
    samples with fewer than ``parts_min_radii`` of them left out. Profiles with their
    centroids (:func:`with_centroids`) add the first ``parts_centroid_radii`` of those
    radii's centroid profiles, times their weight, valid where the areas are:
    (q', K + K') both."""
    columns = scale_columns(j, preset)
    first = len(grid_radii(preset))
    last = min(profiles.shape[1], first) - 1
    below = np.minimum(np.floor(columns).astype(np.int64), last)
    above = np.minimum(below + 1, last)
    fraction = columns - np.floor(columns)
    radii = grid_radii(preset)[0] * 2.0 ** (columns / GRID_STEPS_PER_OCTAVE)
    within = (radii[None, :] <= reach[:, None]) & (columns <= last)[None, :]
    keep = within.sum(axis=1) >= preset.parts_min_radii
    kept, within = profiles[keep], within[keep]
    at = kept[:, below] * (1.0 - fraction) + kept[:, above] * fraction
    count = preset.parts_centroid_radii
    if count and profiles.shape[1] > first:
        low, high, share = first + below[:count], first + above[:count], fraction[:count]
        centroids = kept[:, low] * (1.0 - share) + kept[:, high] * share
        at = np.concatenate([at, preset.parts_centroid_weight * centroids], axis=1)
        within = np.concatenate([within, within[:, :count]], axis=1)
    return at, within


def best_scale(scores: np.ndarray, preset: Preset, scales: range | None = None) -> PartsMatch:
    """The query's scale, by its best match over all candidates, and the dissimilarities
    at it, from :func:`scale_scores`' (J, n)."""
    tried = range(scale_count(preset)) if scales is None else scales
    if scores.size == 0 or not np.isfinite(scores).any():
        return PartsMatch(np.full(scores.shape[1], np.inf), 1.0)
    row = int(np.argmin(scores.min(axis=1)))
    return PartsMatch(scores[row], _scale(tried[row], preset), tried[row])


def _scale(j: int, preset: Preset) -> float:
    return float(2.0 ** (j / (GRID_STEPS_PER_OCTAVE * preset.parts_scale_steps)))


#: Distances computed at once, query samples times candidate samples (whole candidates,
#: at least one): the matrix (1 MB) stays in the processor's cache, which matters more
#: than the number of products.
_BLOCK_ENTRIES = 1 << 18


#: A float16's magnitude bits moved to a float32's place are its value times 2^-112.
_HALF_TO_SINGLE = np.float32(2.0**112)


def _to_single(rows: np.ndarray, out: np.ndarray, signs: np.ndarray) -> None:
    """``out[...] = rows`` (out: float32, contiguous; ``signs``: a uint32 buffer of its
    shape). Float16 rows, as a gallery keeps them, are widened by their bits: each
    value's sign and magnitude moved to a float32's places and the magnitude scaled by
    ``_HALF_TO_SINGLE``, exact for every finite value, normal or subnormal (the profiles
    are finite); numpy's own cast from float16 took twice as long (2 ns a value)."""
    if rows.dtype != np.float16:
        np.copyto(out, rows)
        return
    bits = out.view(np.uint32)
    np.copyto(signs, rows.view(np.uint16))
    np.bitwise_and(signs, 0x7FFF, out=bits)
    np.left_shift(bits, 13, out=bits)
    np.multiply(out, _HALF_TO_SINGLE, out=out)
    np.bitwise_and(signs, 0x8000, out=signs)
    np.left_shift(signs, 16, out=signs)
    np.bitwise_or(bits, signs, out=bits)


class _GalleryRows:
    """Candidates' samples as :func:`_nearest_squared` reads them at every scale: (N, K +
    K') as stored (float16 or wider: the exact distances are computed from these values in
    double precision), in single precision, and the single's sums of squares over the
    first radii (the first ``radii`` columns are the areas', any after them the
    centroids' of the first radii), for each count of radii asked for."""

    def __init__(self, rows: np.ndarray, radii: int) -> None:
        self.exact = rows
        self.radii = radii
        self.single = np.empty(rows.shape, dtype=np.float32)
        _to_single(rows, self.single, np.empty(rows.shape, dtype=np.uint32))
        self._running: np.ndarray | None = None  # (K + K', N) running sums

    def squares(self, count: int) -> np.ndarray:
        """(N,) ``sum y_k^2`` in single precision over the first ``count`` radii's
        columns."""
        if self._running is None:  # every count's sums from one pass over the rows
            running = np.square(self.single.T, order="C")  # (K + K', N)
            for k in range(1, len(running)):
                if k != self.radii:  # the centroids' sums start again
                    running[k] += running[k - 1]
            self._running = running
        total: np.ndarray = self._running[count - 1]
        centroids = min(count, len(self._running) - self.radii)
        if centroids:
            total = total + self._running[self.radii + centroids - 1]
        return total


def _nearest_squared(
    query: np.ndarray, valid: np.ndarray, rows: _GalleryRows, n: int, per_shape: int
) -> np.ndarray:
    """(q, n): each query row's smallest masked squared distance to the rows of each
    candidate, ``sum_k valid_ck (query_ck - whole_yk)^2``.

    The nearest row is found in single precision by one matrix product per block, the
    expansion ``|q|^2 - 2 q.y + |y|^2`` (a row's valid radii are the first ones, those
    within its reach, and its valid centroids those radii's, so the candidates'
    ``sum_k valid_ck y_k^2`` is one vector for all
    query rows with as many valid radii: the rows are taken in that order and each group
    adds its vector), and its distance is computed again in double precision from the
    difference: the expansion's rounding never reaches the result, only which of two
    rows within it of each other is nearest.
    """
    counts = valid[:, : rows.radii].sum(axis=1).astype(np.int64)
    order = np.argsort(counts, kind="stable")
    query, valid, counts = query[order], valid[order], counts[order]
    weighted = (-2.0 * valid * query).astype(np.float32)  # |q|^2 left out: the same
    starts = np.flatnonzero(np.diff(counts, prepend=-1))
    groups = [
        (int(a), int(b), rows.squares(int(counts[a])))
        for a, b in zip(starts, np.append(starts[1:], len(counts)), strict=True)
    ]
    nearest = np.empty((len(query), n), dtype=np.int64)
    shapes_per_block = max(1, _BLOCK_ENTRIES // (len(query) * per_shape))
    for first in range(0, n, shapes_per_block):
        last = min(n, first + shapes_per_block)
        block = slice(first * per_shape, last * per_shape)
        squared = weighted @ rows.single[block].T
        for a, b, squares in groups:
            squared[a:b] += squares[block]
        nearest[:, first:last] = squared.reshape(len(query), last - first, per_shape).argmin(axis=2)
    nearest += per_shape * np.arange(n)
    difference = np.asarray(rows.exact[nearest], dtype=np.float64) - query[:, None, :]
    out = np.empty((len(query), n))
    out[order] = np.einsum("qsk,qk->qs", difference * difference, valid)
    return out


def _nearest_squared_rough(
    rows: np.ndarray, asked: list[tuple[np.ndarray, np.ndarray]], per_shape: int
) -> list[np.ndarray]:
    """For each scale's (query, valid) in ``asked``, (q, n) :func:`_nearest_squared`'s
    result as the single-precision expansion gives it, without computing it again:
    ``|q|^2 + min_y (-2 q.y + |y|^2)`` over the valid radii, one product per block and
    scale (the query row ``[-2 valid q, valid]`` against ``[y, y^2]``, so no grouping by
    valid radii) and each candidate's minimum over its rows. A shape's rows are the
    product's consecutive rows, so the minimum runs along whole rows of query values; the
    rounding, about 1e-5 of the squared distance for profiles of a few units, is far below
    what a shortlist tells apart.

    The candidates' (N, K) rows (float16 as a gallery keeps them) are made single
    precision, with their squares, a block at a time into one buffer that stays in the
    processor's cache, and every scale is scored on the block, rather than all rows at
    once, written to memory and read back for each scale."""
    count = rows.shape[1]
    n = len(rows) // per_shape
    picks, squares, out = [], [], []
    for query, valid in asked:
        pick = np.empty((2 * count, len(query)), dtype=np.float32)
        pick[:count] = (-2.0 * valid * query).T
        pick[count:] = valid.T
        picks.append(pick)
        squares.append(np.einsum("qk,qk->q", valid, query * query))
        out.append(np.empty((n, len(query)), dtype=np.float32))
    widest = max(len(query) for query, _ in asked)
    shapes_per_block = max(1, _BLOCK_ENTRIES // (widest * per_shape))
    buffer = np.empty((shapes_per_block * per_shape, 2 * count), dtype=np.float32)
    wide = np.empty((shapes_per_block * per_shape, count), dtype=np.float32)
    signs = np.empty(wide.shape, dtype=np.uint32)
    for first in range(0, n, shapes_per_block):
        last = min(n, first + shapes_per_block)
        size = (last - first) * per_shape
        block, single = buffer[:size], wide[:size]
        _to_single(rows[first * per_shape : last * per_shape], single, signs[:size])
        block[:, :count] = single
        np.multiply(single, single, out=block[:, count:])
        for pick, nearest in zip(picks, out, strict=True):
            product = block @ pick
            nearest[first:last] = _least_row(product.reshape(last - first, per_shape, -1))
    return [nearest.T + square[:, None] for nearest, square in zip(out, squares, strict=True)]


def _least_row(values: np.ndarray) -> np.ndarray:
    """(n, m) ``values.min(axis=1)`` of (n, r, m) values, by halving: the first half of
    the rows against the last (overlapping by one when ``r`` is odd), again and again.
    Each step runs along whole blocks of rows, where numpy's reduction along the middle
    axis steps row by row: half the time for a rough pass's products (64 rows of 64)."""
    half = (values.shape[1] + 1) // 2
    if half == values.shape[1]:
        return values[:, 0]
    least = np.minimum(values[:, :half], values[:, -half:])
    while half > 1:
        length, half = half, (half + 1) // 2
        np.minimum(least[:, :half], least[:, length - half : length], out=least[:, :half])
    smallest: np.ndarray = least[:, 0]
    return smallest


def part_dissimilarity_reference(
    profiles: np.ndarray,
    reach: np.ndarray,
    gallery: np.ndarray,
    preset: Preset,
    scales: range | None = None,
) -> PartsMatch:
    """:func:`part_dissimilarity` by direct differences, one sample pair at a time."""
    grid = grid_radii(preset)
    steps = preset.parts_scale_steps
    areas, centroids = profiles[:, : len(grid)], profiles[:, len(grid) :]

    def value(row: np.ndarray, column: float) -> float:
        i, t = int(column), column - int(column)
        return float(row[i] if t == 0 else (1 - t) * row[i] + t * row[i + 1])

    def at_scale(j: int) -> list[float] | None:
        samples = []
        for c in range(len(profiles)):
            at, clear = [], []
            for k in range(preset.parts_radii):
                column = j / steps + 2 * k
                if column > len(grid) - 1:  # past the profiles' last radius
                    at.append(0.0)
                    clear.append(False)
                    continue
                at.append(value(areas[c], column))
                clear.append(grid[0] * 2.0 ** (column / GRID_STEPS_PER_OCTAVE) <= reach[c])
            if centroids.size:  # the first radii's centroids, valid where their areas are
                for k in range(preset.parts_centroid_radii):
                    column = j / steps + 2 * k
                    centroid = preset.parts_centroid_weight * value(centroids[c], column)
                    at.append(centroid if clear[k] else 0.0)
                    clear.append(clear[k])
            valid = np.array(clear)
            if valid[: preset.parts_radii].sum() >= preset.parts_min_radii:
                samples.append((np.array(at)[valid], valid))
        if not samples:
            return None
        scores = []
        for candidate in gallery:
            total = weight = 0.0
            for values, valid in samples:
                whole = candidate[:, valid]
                used = valid[: preset.parts_radii].sum()
                nearest = np.min(np.sum((whole - values) ** 2, axis=1)) / used
                total += used * np.sqrt(nearest)
                weight += used
            prior = preset.parts_scale_prior * np.log(2.0 ** (j / (steps * GRID_STEPS_PER_OCTAVE)))
            scores.append(total / weight + prior)
        return scores

    best: tuple[float, list[float], int] | None = None
    for j in range(scale_count(preset)) if scales is None else scales:
        scores = at_scale(j)
        if scores is not None and (best is None or min(scores) < best[0]):
            best = (min(scores), scores, j)
    if best is None:
        return PartsMatch(np.full(len(gallery), np.inf), 1.0)
    scale = 2.0 ** (best[2] / (steps * GRID_STEPS_PER_OCTAVE))
    return PartsMatch(np.asarray(best[1]), scale, best[2])
