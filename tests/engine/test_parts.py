"""The parts modality: profiles against plain sums and closed forms, the comparison
against its plain reference, and a part finding its whole."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh
from conftest import example, random_rotation

from worker.engine.compare import partiality, query_weights
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.mesh_io import Mesh, clean_mesh, load_mesh
from worker.engine.parts import (
    GRID_STEPS_PER_OCTAVE,
    _least_row,
    _to_single,
    ball_area_profiles,
    ball_area_profiles_reference,
    ball_centroid_profiles,
    ball_centroid_profiles_reference,
    best_scale,
    boundary_reach,
    can_hold,
    coarse,
    compared_by_size,
    compared_profiles,
    grid_radii,
    led_part_dissimilarity,
    part_dissimilarity,
    part_dissimilarity_reference,
    scale_count,
    scale_scores,
    sized_dissimilarity,
    sized_scales,
)
from worker.engine.pipeline import describe_mesh
from worker.engine.presets import DEFAULT_PRESET, get_preset, with_units
from worker.evaluation.partial import noisy_surface, planar_cut
from worker.evaluation.variants import decimated, subdivided

DEFAULT = get_preset(DEFAULT_PRESET)
#: Areas alone, and the discs' centroids beside them on the first 9 radii.
AREAS = replace(DEFAULT, parts_centroid_radii=0, parts_centroid_weight=0.0)
CENTROIDS = replace(DEFAULT, parts_centroid_radii=9, parts_centroid_weight=3.0)
#: The engine's profiles are half precision: their rounding, relative.
HALF = 2.0**-10


def test_ball_area_profiles_match_the_plain_sums():
    rng = np.random.default_rng(0)
    distances = rng.uniform(0.0, 3.0, size=(400, 30)).astype(np.float32)
    distances[rng.integers(400, size=30), np.arange(30)] = 0.0  # each sample's own vertex
    mass = rng.uniform(0.5, 1.5, size=400)
    fast = ball_area_profiles(distances, mass, 0.1, 34)
    np.testing.assert_allclose(fast, ball_area_profiles_reference(distances, mass, 0.1, 34))


def test_ball_centroid_profiles_match_the_plain_sums():
    rng = np.random.default_rng(0)
    distances = rng.uniform(0.0, 3.0, size=(400, 30))
    samples = rng.choice(400, size=30, replace=False)
    distances[samples, np.arange(30)] = 0.0
    mass = rng.uniform(0.5, 1.5, size=400)
    positions = rng.normal(size=(400, 3))
    fast = ball_centroid_profiles(distances, mass, positions, samples, 0.1, 34)
    plain = ball_centroid_profiles_reference(distances, mass, positions, samples, 0.1, 34)
    np.testing.assert_allclose(fast, plain, rtol=1e-12)


def _sphere(radius: float = 2.0) -> tuple[trimesh.Trimesh, np.ndarray, np.ndarray]:
    """A fine icosphere, its lumped vertex areas, and the exact geodesic (great-circle)
    distances from 20 of its vertices to all."""
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    mass = np.bincount(sphere.faces.ravel(), np.repeat(sphere.area_faces / 3, 3))
    units = sphere.vertices / radius
    samples = np.arange(0, len(units), len(units) // 20)[:20]
    distances = radius * np.arccos(np.clip(units @ units[samples].T, -1.0, 1.0))
    return sphere, mass, distances


def test_ball_area_profiles_follow_a_spheres_caps():
    radius = 2.0
    _, mass, distances = _sphere(radius)
    # From five edge lengths (0.1 here) up to a cap of nearly a hemisphere.
    profiles = ball_area_profiles(distances, mass, 0.5, 24)
    radii = 0.5 * 2.0 ** (np.arange(24) / GRID_STEPS_PER_OCTAVE)
    caps = 2 * np.pi * radius**2 * (1 - np.cos(radii / radius)) / (np.pi * radii**2)
    # A ball's area counts the vertices inside it: within a few percent at 10k vertices.
    np.testing.assert_allclose(np.exp(profiles), np.broadcast_to(caps, profiles.shape), rtol=0.04)


def test_ball_centroid_profiles_follow_a_spheres_caps():
    """A cap of geodesic radius ``r`` on a sphere of radius ``R``: its centroid lies
    halfway down it (Archimedes: a sphere's zones have areas as their heights), ``R (1 -
    cos(r / R)) / 2`` below its pole, about ``|H| r^2 / 4``."""
    radius = 2.0
    sphere, mass, distances = _sphere(radius)
    samples = np.arange(0, len(sphere.vertices), len(sphere.vertices) // 20)[:20]
    profiles = ball_centroid_profiles(distances, mass, sphere.vertices, samples, 0.5, 24)
    radii = 0.5 * 2.0 ** (np.arange(24) / GRID_STEPS_PER_OCTAVE)
    caps = radius * (1 - np.cos(radii / radius)) / (2 * radii)
    # The vertices inside a small cap jitter its centroid; over the samples it averages out.
    np.testing.assert_allclose(profiles, np.broadcast_to(caps, profiles.shape), rtol=0.1)
    np.testing.assert_allclose(profiles.mean(axis=0), caps, rtol=0.03)


def test_boundary_reach_is_the_distance_to_the_open_boundary():
    radius = 2.0
    sphere, _, distances = _sphere(radius)
    assert np.isinf(boundary_reach(distances, np.zeros(0, dtype=int))).all()
    # The equator as the boundary of a hemisphere: a sample is its latitude away.
    equator = np.flatnonzero(np.abs(sphere.vertices[:, 2]) < 0.02 * radius)
    samples = np.arange(0, len(sphere.vertices), len(sphere.vertices) // 20)[:20]
    latitude = radius * np.abs(np.arcsin(sphere.vertices[samples, 2] / radius))
    np.testing.assert_allclose(boundary_reach(distances, equator), latitude, atol=0.05)


def _profiles(rng: np.random.Generator, shapes: int, samples: int) -> np.ndarray:
    """Smooth, decreasing random profiles on the default grid, as a surface's are."""
    columns = len(grid_radii(DEFAULT))
    steps = rng.uniform(0.0, 0.3, size=(shapes, samples, columns))
    return -np.cumsum(steps, axis=2)


def _with_centroids(rng: np.random.Generator, profiles: np.ndarray) -> np.ndarray:
    """``profiles`` followed by smooth, rising random centroid profiles, as a surface's."""
    steps = rng.uniform(0.0, 0.05, size=profiles.shape)
    return np.concatenate([profiles, np.cumsum(steps, axis=-1)], axis=-1)


@pytest.mark.parametrize(
    ("extra", "base"), [(0, AREAS), (4, AREAS), (0, CENTROIDS), (4, CENTROIDS)]
)
def test_part_dissimilarity_matches_the_plain_reference(extra, base):
    """Scales past the grid's (``parts_extra_scales``) leave out the radii past the
    profiles' last column, in both; the centroids, when compared, where the areas are."""
    preset = replace(base, parts_extra_scales=extra)
    rng = np.random.default_rng(1)
    wholes, query = _profiles(rng, 5, 40), _profiles(rng, 1, 30)[0]
    if preset.parts_centroid_radii:
        wholes, query = _with_centroids(rng, wholes), _with_centroids(rng, query)
    gallery = compared_profiles(wholes, preset)
    assert gallery.shape[2] == preset.parts_radii + preset.parts_centroid_radii
    reach = np.where(rng.random(30) < 0.3, np.inf, rng.uniform(0.05, 1.5, size=30))
    fast = part_dissimilarity(query, reach, gallery, preset)
    plain = part_dissimilarity_reference(query, reach, gallery, preset)
    np.testing.assert_allclose(fast.dissimilarity, plain.dissimilarity, rtol=1e-9)
    assert fast.scale == plain.scale
    rough = scale_scores(query, reach, gallery, preset, rough=True)
    scores = scale_scores(query, reach, gallery, preset)
    np.testing.assert_allclose(rough, scores, rtol=1e-4)
    assert scores.shape[0] == (5 + extra) * preset.parts_scale_steps + 1
    assert np.isfinite(scores).all()  # every scale has samples with enough radii


def test_candidates_scored_in_blocks_choose_the_same_scale():
    """The index scores a gallery in blocks and chooses the scale over all of them."""
    rng = np.random.default_rng(3)
    gallery = compared_profiles(_profiles(rng, 7, 30), DEFAULT)
    query, reach = _profiles(rng, 1, 12)[0], rng.uniform(0.1, 2.0, 12)
    blocks = np.concatenate(
        [scale_scores(query, reach, gallery[a : a + 3], DEFAULT) for a in range(0, 7, 3)], axis=1
    )
    joined = best_scale(blocks, DEFAULT)
    whole = part_dissimilarity(query, reach, gallery, DEFAULT)
    np.testing.assert_allclose(joined.dissimilarity, whole.dissimilarity, rtol=1e-12)
    assert joined.scale == whole.scale


def test_the_exact_pass_over_several_blocks_matches_the_plain_reference():
    """Float16 candidates, as a gallery keeps them, enough of them with enough samples
    that the exact pass finds their nearest rows in three blocks (the last one short)
    before computing the distances again for all of them at once."""
    rng = np.random.default_rng(5)
    gallery = compared_profiles(_profiles(rng, 30, 300), DEFAULT).astype(np.float16)
    query = _profiles(rng, 1, 64)[0]
    reach = np.where(rng.random(64) < 0.3, np.inf, rng.uniform(0.05, 1.5, size=64))
    scales = range(2, 6)
    fast = part_dissimilarity(query, reach, gallery, DEFAULT, scales)
    plain = part_dissimilarity_reference(query, reach, gallery, DEFAULT, scales)
    np.testing.assert_allclose(fast.dissimilarity, plain.dissimilarity, rtol=1e-9)
    assert fast.scale == plain.scale


def test_a_shortlist_led_by_its_best_finds_the_scale_every_scale_finds():
    """Parts of one of 40 candidates (float16, as a gallery keeps them), scaled up as
    their area would be: started from the coarse pass's scale, a few leaders compared at
    every scale find the scale and the dissimilarities of every candidate compared at every
    scale, exactly, including when the coarse pass started them a scale away."""
    rng = np.random.default_rng(8)
    wholes = _profiles(rng, 40, 120)
    gallery = compared_profiles(wholes, DEFAULT).astype(np.float16)
    for trial in range(6):
        part = np.roll(wholes[trial, rng.choice(120, size=60, replace=False)], trial % 3, axis=1)
        reach = np.where(rng.random(60) < 0.5, np.inf, rng.uniform(0.1, 1.5, size=60))
        rough = part_dissimilarity(*coarse(part, reach, gallery, DEFAULT), DEFAULT)
        start = min(rough.j + trial % 2, scale_count(DEFAULT) - 1)
        scales = range(max(0, start - 3), min(scale_count(DEFAULT), start + 4))
        every = part_dissimilarity(part, reach, gallery, DEFAULT, scales)
        led = led_part_dissimilarity(part, reach, gallery, DEFAULT, scales, start, leaders=2)
        assert led.j == every.j
        np.testing.assert_allclose(led.dissimilarity, every.dissimilarity, rtol=1e-12)


def test_a_shortlist_led_by_its_best_compares_a_rival_at_every_scale():
    """A candidate that is no leader at the starting scale but matches best at the scale
    the leaders choose is compared at every scale too: the scale is the one where it
    matches best, as when every candidate is compared at every scale."""
    rng = np.random.default_rng(9)
    wholes = _profiles(rng, 6, 80)
    part = np.roll(wholes[4, :30], 2, axis=1)  # the part of shape 4, two scales up
    gallery = compared_profiles(wholes, DEFAULT)
    reach = np.full(30, np.inf)
    every = part_dissimilarity(part, reach, gallery, DEFAULT)
    assert np.argmin(every.dissimilarity) == 4
    scales = range(scale_count(DEFAULT))
    at_first = scale_scores(part, reach, gallery, DEFAULT, range(1))[0]
    assert np.argmin(at_first) != 4  # at scale 0 another candidate leads
    led = led_part_dissimilarity(part, reach, gallery, DEFAULT, scales, 0, leaders=1)
    assert led.j == every.j
    np.testing.assert_allclose(led.dissimilarity, every.dissimilarity, rtol=1e-12)


def test_a_shortlist_with_no_sample_clear_of_the_boundary_matches_nothing():
    rng = np.random.default_rng(10)
    gallery = compared_profiles(_profiles(rng, 5, 40), DEFAULT)
    part = _profiles(rng, 1, 20)[0]
    led = led_part_dissimilarity(part, np.full(20, 1e-6), gallery, DEFAULT, range(2, 9), 5)
    assert np.isinf(led.dissimilarity).all() and led.scale == 1.0


def test_float16_rows_are_widened_exactly():
    """Every finite float16 (normal, subnormal, both zeros) becomes the float32 numpy's
    cast gives, bit for bit, into a buffer of the rough pass's shape."""
    every = np.arange(1 << 16, dtype=np.uint16).view(np.float16)
    rows = every[np.isfinite(every)].reshape(-1, 16)
    out = np.empty(rows.shape, dtype=np.float32)
    _to_single(rows, out, np.empty(rows.shape, dtype=np.uint32))
    np.testing.assert_array_equal(out.view(np.uint32), rows.astype(np.float32).view(np.uint32))


def test_the_least_row_by_halving_is_numpys_minimum():
    """Every count of rows, odd ones overlapping by one as they are halved."""
    rng = np.random.default_rng(11)
    for rows in range(1, 70):
        values = rng.normal(size=(5, rows, 7)).astype(np.float32)
        np.testing.assert_array_equal(_least_row(values), values.min(axis=1))


def test_a_rough_pass_scores_as_the_exact_one_to_single_precision():
    """The index's shortlisting passes take the single-precision expansion as it comes:
    on float16 profiles as a gallery keeps them, every scale's scores within 1e-4 of the
    exact ones, at every scale including those where few radii are clear, over enough
    candidates that the rough pass converts them in three blocks, the last one short."""
    rng = np.random.default_rng(4)
    gallery = compared_profiles(_profiles(rng, 150, 64), DEFAULT).astype(np.float16)
    query = _profiles(rng, 1, 64)[0]
    reach = np.where(rng.random(64) < 0.3, np.inf, rng.uniform(0.05, 1.5, size=64))
    exact = scale_scores(query, reach, gallery, DEFAULT)
    rough = scale_scores(query, reach, gallery, DEFAULT, rough=True)
    assert np.isfinite(exact).sum() > exact.shape[1]  # more than one scale compared
    np.testing.assert_array_equal(np.isfinite(rough), np.isfinite(exact))
    finite = np.isfinite(exact)
    np.testing.assert_allclose(rough[finite], exact[finite], rtol=1e-4)


def test_the_coarse_pass_compares_the_areas_alone():
    """The passes that shortlist read the areas: a query's centroid columns and a
    candidate's are left out, and the scores are the areas-only preset's."""
    rng = np.random.default_rng(6)
    wholes = _with_centroids(rng, _profiles(rng, 6, 80))
    query = _with_centroids(rng, _profiles(rng, 1, 100))[0]
    reach = rng.uniform(0.1, 2.0, 100)
    profiles, clear, gallery = coarse(query, reach, compared_profiles(wholes, CENTROIDS), CENTROIDS)
    alone = coarse(
        query[:, : len(grid_radii(AREAS))], reach, compared_profiles(wholes, AREAS), AREAS
    )
    for mine, theirs in zip((profiles, clear, gallery), alone, strict=True):
        np.testing.assert_array_equal(mine, theirs)
    with_them = scale_scores(profiles, clear, gallery, CENTROIDS)
    np.testing.assert_array_equal(with_them, scale_scores(*alone, AREAS))


def test_a_whole_contains_every_part_of_itself():
    rng = np.random.default_rng(2)
    gallery = _profiles(rng, 4, 60)
    part = gallery[2, rng.choice(60, size=20, replace=False)]
    match = part_dissimilarity(
        part, np.full(20, np.inf), compared_profiles(gallery, DEFAULT), DEFAULT
    )
    assert match.dissimilarity[2] == pytest.approx(0.0, abs=1e-6)
    assert np.all(np.delete(match.dissimilarity, 2) > 0.05)
    assert match.scale == 1.0 and match.kept_share == 1.0


def test_a_part_normalized_by_its_own_area_is_found_at_its_scale():
    """A part of ``kappa`` of its whole's area, scaled up by ``1 / sqrt(kappa)``, sees at
    grid radius ``i + j`` what the whole sees at ``i``: the search finds that ``j``."""
    rng = np.random.default_rng(3)
    gallery = _profiles(rng, 4, 60)
    shift = 3  # 2^(3/8) = 1.30 in length: the part has 59% of the area
    part = np.roll(gallery[1, :25], shift, axis=1)
    match = part_dissimilarity(
        part, np.full(25, np.inf), compared_profiles(gallery, DEFAULT), DEFAULT
    )
    assert np.argmin(match.dissimilarity) == 1
    assert match.scale == 2.0 ** (shift / GRID_STEPS_PER_OCTAVE)
    assert match.kept_share == pytest.approx(2.0 ** (-2 * shift / 8))


def test_a_part_smaller_than_the_grid_reaches_is_found_past_it():
    """A part of 30% of its whole's area (``2^(7/8)`` in length, two steps past the
    grid's scales): found at its scale with two more steps, its largest radius, past the
    profiles' last column, left out; without them its scale is the grid's last."""
    rng = np.random.default_rng(6)
    gallery = _profiles(rng, 4, 60)
    shift = 7
    part = np.roll(gallery[1, :25], shift, axis=1)
    whole = compared_profiles(gallery, DEFAULT)
    past = part_dissimilarity(
        part, np.full(25, np.inf), whole, replace(DEFAULT, parts_extra_scales=2)
    )
    assert np.argmin(past.dissimilarity) == 1
    assert past.scale == 2.0 ** (shift / GRID_STEPS_PER_OCTAVE)
    assert past.dissimilarity[1] == pytest.approx(
        DEFAULT.parts_scale_prior * np.log(past.scale), abs=1e-9
    )
    within = part_dissimilarity(
        part, np.full(25, np.inf), whole, replace(DEFAULT, parts_extra_scales=0)
    )
    assert within.scale == 2.0 ** ((DEFAULT.parts_scales - 1) / GRID_STEPS_PER_OCTAVE)
    assert within.dissimilarity[1] > past.dissimilarity[1] + 0.05


def test_a_part_between_two_steps_of_the_grid_is_found_between_them():
    """Profiles are stored at the grid's radii; a query scale between two of them
    compares the query's profiles interpolated in ``log r``: a part whose scale lies a
    quarter of a step past a column (profiles linear in ``log r`` there) matches its whole
    exactly, only the prior left."""
    rng = np.random.default_rng(5)
    columns = np.arange(len(grid_radii(DEFAULT)), dtype=np.float64)
    slopes, offsets = rng.uniform(-0.3, -0.01, (4, 40, 1)), rng.uniform(-1.0, 0.0, (4, 40, 1))
    gallery = offsets + slopes * columns
    shift = 2.25  # steps of the grid: 2^(2.25/8) = 1.215 in length
    part = (offsets[2] + slopes[2] * (columns - shift))[:20]
    match = part_dissimilarity(
        part, np.full(20, np.inf), compared_profiles(gallery, DEFAULT), DEFAULT
    )
    assert DEFAULT.parts_scale_steps == 4
    assert match.scale == pytest.approx(2.0 ** (shift / GRID_STEPS_PER_OCTAVE), rel=1e-12)
    prior = DEFAULT.parts_scale_prior * np.log(match.scale)
    assert match.dissimilarity[2] == pytest.approx(prior, abs=1e-9)
    whole_steps = part_dissimilarity(
        part,
        np.full(20, np.inf),
        compared_profiles(gallery, DEFAULT),
        replace(DEFAULT, parts_scale_steps=1),
    )
    assert whole_steps.dissimilarity[2] > match.dissimilarity[2] + 0.01


def test_sized_dissimilarity_is_each_candidates_best_in_its_window():
    """Each candidate scored at the scales within ``SIZED_SCALES`` of its centre, the
    window cut to the scales tried (a centre far past the last: the last alone; below the
    first: the first alone), as the plain reference scores it over that window alone;
    one too small to hold the query (under half its area) at ``inf``."""
    rng = np.random.default_rng(8)
    gallery = compared_profiles(_profiles(rng, 6, 40), DEFAULT).astype(np.float16)
    query = _profiles(rng, 1, 30)[0]
    reach = np.where(rng.random(30) < 0.3, np.inf, rng.uniform(0.05, 1.5, size=30))
    last = scale_count(DEFAULT) - 1
    centres = np.array([-17, -3, 12, 12, last - 1, last + 30])
    windows = [(0, 0), (10, 14), (10, 14), (last - 3, last), (last, last)]
    found = sized_dissimilarity(query, reach, gallery, DEFAULT, centres)
    plain = [
        part_dissimilarity_reference(query, reach, gallery[c : c + 1], DEFAULT, range(a, b + 1))
        for c, (a, b) in enumerate(windows, start=1)
    ]
    assert found.dissimilarity[0] == np.inf
    want = [p.dissimilarity[0] for p in plain]
    np.testing.assert_allclose(found.dissimilarity[1:], want, rtol=1e-9)
    assert found.scale == plain[int(np.argmin(found.dissimilarity)) - 1].scale


def test_sized_scales_are_the_share_the_areas_give():
    """A query of 2^(-3/8) of a candidate's size is 59% of its area: scale 2^(3/8),
    12 quarter steps; of equal size, 0; twice the size, a negative index."""
    sizes = np.array([2.0 ** (3 / 8), 1.0, 0.5])
    np.testing.assert_array_equal(sized_scales(1.0, sizes, DEFAULT), [12, 0, -32])


def test_a_whole_under_half_the_querys_area_cannot_hold_it():
    """Sizes 2^(-1/2) of the query's are half its area: 16 quarter steps below."""
    centres = sized_scales(1.0, np.array([0.7, 2.0**-0.5, 0.72, 1.0]), DEFAULT)
    np.testing.assert_array_equal(centres, [-16, -16, -15, 0])
    np.testing.assert_array_equal(
        can_hold(np.array([-17, -16, -15, 0]), DEFAULT), [False, True, True, True]
    )


def test_a_part_of_a_metric_collection_tells_its_whole_from_a_scaled_copy():
    """Profiles are in units of a surface's own area, so a whole and a copy of it 19%
    larger have the same ones, and a part matches both alike; its size and theirs say
    which one it is 59% of."""
    rng = np.random.default_rng(3)
    profiles = _profiles(rng, 1, 60)[0]
    gallery = compared_profiles(np.stack([profiles, profiles]), DEFAULT)
    part = np.roll(profiles[:25], 3, axis=1)  # 59% of its whole's area (as above)
    reach = np.full(25, np.inf)
    alike = part_dissimilarity(part, reach, gallery, DEFAULT).dissimilarity
    assert alike[0] == alike[1]
    sizes = np.array([1.0, 2.0 ** (2 / 8)])  # the copy: 2 grid steps larger
    centres = sized_scales(2.0 ** (-3 / 8), sizes, DEFAULT)
    found = sized_dissimilarity(part, reach, gallery, DEFAULT, centres)
    assert found.dissimilarity[0] == pytest.approx(alike[0], abs=1e-12)
    assert found.dissimilarity[1] > alike[0] + 0.05
    assert found.scale == 2.0 ** (3 / GRID_STEPS_PER_OCTAVE)


def test_only_a_metric_collection_compares_by_size_and_not_a_two_sided_view():
    metric = with_units(DEFAULT, "metric")
    assert DEFAULT.two_sided_views
    assert compared_by_size(metric, single_view=False)
    assert not compared_by_size(metric, single_view=True)
    assert compared_by_size(replace(metric, two_sided_views=False), single_view=True)
    assert not compared_by_size(DEFAULT, single_view=False)


def test_samples_that_see_the_cut_are_left_out():
    """Radii beyond a sample's reach are what the cut disturbed: garbage there changes
    nothing, and a sample with too few clear radii is not compared at all."""
    rng = np.random.default_rng(4)
    gallery = _profiles(rng, 3, 50)
    part = gallery[0, :20].copy()
    reach = np.full(20, 0.2)  # radii 0.07 .. 0.2 are clear: 4 of the compared ones
    radii = grid_radii(DEFAULT)
    part[:, radii > 0.2] = 5.0
    reach[:5] = 0.08  # a single clear radius: below parts_min_radii
    part[:5] = 7.0
    match = part_dissimilarity(
        part, reach, compared_profiles(gallery, DEFAULT), DEFAULT, scales=range(1)
    )
    assert match.dissimilarity[0] == pytest.approx(0.0, abs=1e-6)
    assert np.isinf(
        part_dissimilarity(
            part, np.full(20, 0.01), compared_profiles(gallery, DEFAULT), DEFAULT
        ).dissimilarity
    ).all()


def test_partiality_rises_with_the_open_boundary_and_the_missing_file():
    start, end = DEFAULT.partial_loop
    assert partiality(None, None, DEFAULT) == 0.0
    assert partiality(0.0, 1.0, DEFAULT) == 0.0
    assert partiality(start, 1.0, DEFAULT) == 0.0
    assert partiality(0.5 * (start + end), 1.0, DEFAULT) == pytest.approx(0.5)
    assert partiality(end + 1.0, 1.0, DEFAULT) == 1.0
    assert partiality(0.0, 0.995, DEFAULT) == 0.0  # a speck of debris left out
    assert partiality(0.0, 0.7, DEFAULT) == 1.0


def test_a_whole_query_is_weighed_as_without_the_parts_modality():
    assert query_weights(DEFAULT, 0.0) == {"ddt": 0.5, "spectrum": 1.0}
    assert query_weights(DEFAULT, 1.0) == {"parts": 1.0}
    halfway = query_weights(DEFAULT, 0.5)
    assert halfway == pytest.approx({"ddt": 0.25, "parts": 0.5, "spectrum": 0.5})
    paper = get_preset("smeets2010-shrec")
    assert query_weights(paper, 1.0) == {"gdm": 1.0, "ddt": 1.0}


# --------------------------------------------------------------------------- meshes


@pytest.fixture(scope="module")
def figures() -> dict[str, ShapeDescriptor]:
    """The default's descriptors of pose 0 of every example class."""
    return {
        name: describe_mesh(load_mesh(example(f"{name}-0")), DEFAULT)
        for name in ("biped", "quadruped", "spider", "bird", "hand")
    }


def _gallery(figures: dict[str, ShapeDescriptor]) -> np.ndarray:
    return compared_profiles(
        np.stack([d.parts.astype(np.float64) for d in figures.values()]), DEFAULT
    )


def _match(query: ShapeDescriptor, figures: dict[str, ShapeDescriptor]) -> dict[str, float]:
    found = part_dissimilarity(
        query.parts.astype(np.float64), query.parts_reach, _gallery(figures), DEFAULT
    )
    return dict(zip(figures, found.dissimilarity.tolist(), strict=True))


@pytest.mark.slow
@pytest.mark.parametrize("share", [0.15, 0.3])
def test_a_cut_copy_of_another_pose_finds_its_figure(figures, share):
    """Another pose of the quadruped with the top of it cut off (along each axis) still
    finds the quadruped first, and says it looks partial."""
    pose = load_mesh(example("quadruped-3"))
    for axis in np.eye(3):
        part = describe_mesh(planar_cut(pose, share, axis), DEFAULT)
        scores = _match(part, figures)
        assert min(scores, key=scores.__getitem__) == "quadruped", scores
        assert partiality(part.longest_open_loop, None, DEFAULT) > 0.0
        assert np.isfinite(part.parts_reach).any()


@pytest.mark.slow
def test_parts_hardly_move_with_the_triangulation(figures):
    """The same surface decimated or subdivided is nearer its whole than any other
    figure is, by half. Not the robustness protocol's bar of 0.1: a part is matched
    sample by sample, and another triangulation puts the samples elsewhere (the
    modality's gap on TOSCA is in docs/evaluation.md)."""
    mesh = load_mesh(example("bird-0"))
    others = {k: v for k, v in figures.items() if k != "bird"}
    nearest_other = min(_match(figures["bird"], others).values())
    for variant in (decimated(mesh, 0.5), subdivided(mesh)):
        moved = _match(describe_mesh(variant, DEFAULT), {"bird": figures["bird"]})["bird"]
        assert moved < 0.5 * nearest_other


@pytest.mark.slow
def test_parts_ignore_rigid_motion_scale_and_vertex_order(figures):
    mesh = load_mesh(example("hand-0"))
    rng = np.random.default_rng(5)
    order = rng.permutation(mesh.n_vertices)
    inverse = np.argsort(order)
    moved = clean_mesh(
        mesh.vertices[order] @ random_rotation(rng).T * 37.0 + 5.0, inverse[mesh.faces]
    )
    other = describe_mesh(moved, DEFAULT)
    want = figures["hand"]
    np.testing.assert_allclose(other.parts_reach, want.parts_reach)
    # Samples are a set: a tie of the farthest-point sampling may place one elsewhere
    # (its profile then differs), the rest are the same to float16's rounding.
    same = np.abs(other.parts.astype(np.float64) - want.parts.astype(np.float64)) <= 8 * HALF
    assert same.all(axis=1).mean() > 0.99
    nearest_other = min(_match(want, {k: v for k, v in figures.items() if k != "hand"}).values())
    assert _match(other, {"hand": want})["hand"] < 0.02 * nearest_other


@pytest.mark.slow
def test_a_descriptor_with_parts_round_trips(figures):
    cut = describe_mesh(planar_cut(load_mesh(example("spider-1")), 0.3, np.eye(3)[0]), DEFAULT)
    for back in (
        ShapeDescriptor.from_npz_bytes(cut.to_npz_bytes()),
        ShapeDescriptor.from_json(cut.to_json()),
    ):
        np.testing.assert_array_equal(back.parts, cut.parts)
        np.testing.assert_array_equal(back.parts_reach, cut.parts_reach)
        assert back.longest_open_loop == cut.longest_open_loop > 0.0
    old = replace(figures["biped"], parts=np.zeros((0, 0), dtype=np.float16))
    assert ShapeDescriptor.from_npz_bytes(old.to_npz_bytes()).parts.shape == (0, 0)


def test_a_preset_without_parts_describes_none():
    mesh = Mesh(*(lambda m: (m.vertices, m.faces))(trimesh.creation.icosphere(3)))
    small = replace(get_preset("smeets2010-shrec"), n_vertices=300, n_eigenpairs=60)
    described = describe_mesh(mesh, small)
    assert described.parts.shape == (0, 0) and described.longest_open_loop == 0.0


@pytest.mark.slow
def test_a_noisy_copy_is_measured_at_its_surfaces_scale(figures):
    """Noise crumples a file's area (at 0.5% of the diagonal, a few times the surface's
    on a fine mesh), and the resampled surface smooths most of it away. The parts' radii
    are in units of the resampled surface's area: the noisy copy finds its figure at
    about its whole's scale, not at one the crumpled area would give."""
    mesh = load_mesh(example("quadruped-0"))
    fine = subdivided(subdivided(mesh))
    rng = np.random.default_rng(7)
    noisy = describe_mesh(noisy_surface(fine, 0.5, rng), DEFAULT)
    found = part_dissimilarity(
        noisy.parts.astype(np.float64), noisy.parts_reach, _gallery(figures), DEFAULT
    )
    scores = dict(zip(figures, found.dissimilarity.tolist(), strict=True))
    assert min(scores, key=scores.__getitem__) == "quadruped", scores
    assert found.kept_share > 0.8
