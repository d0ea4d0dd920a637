"""Eqs. (8) and (9) on hand-computed cases, and the fusion rules."""

from __future__ import annotations

import numpy as np
import pytest
from lapy.shapedna import compute_distance, reweight_ev

from worker.engine.compare import (
    D1_BLOCK,
    dissimilarity,
    fuse,
    fused_dissimilarity,
    gallery_sigma,
    mean_normalized_manhattan,
    normalized_euclidean,
    paired_dissimilarity,
    paired_preset_dissimilarity,
    paired_size_dissimilarity,
    preset_dissimilarity,
    query_weights,
    reweighted_euclidean,
    size_dissimilarity,
)
from worker.engine.presets import (
    DEFAULT_PRESET,
    PRESETS,
    REWEIGHTED,
    SIZE,
    get_preset,
    with_fusion,
    with_units,
)


def test_d1_hand_computed():
    a = np.array([[1.0, 2.0, 0.0]])
    b = np.array([[3.0, 2.0, 0.0], [1.0, 2.0, 0.0]])
    # vs b0: 2|1-3|/(1+3) = 1, 0, 0 (both zero) -> mean 1/3; vs b1: 0.
    np.testing.assert_allclose(mean_normalized_manhattan(a, b), [[1 / 3, 0.0]])


def test_d1_is_symmetric_and_scale_free():
    rng = np.random.default_rng(0)
    x = rng.random((5, 8))
    d = mean_normalized_manhattan(x, x)
    np.testing.assert_allclose(d, d.T)
    np.testing.assert_allclose(np.diag(d), 0.0)
    np.testing.assert_allclose(mean_normalized_manhattan(3 * x, 3 * x), d)


def test_d1_in_blocks_is_the_pairwise_formula_for_every_row():
    """More gallery rows than a block, single precision as a gallery stores them, zeros in
    both: each entry equals eq. (8) computed pair by pair."""
    rng = np.random.default_rng(1)
    gallery = rng.random((2 * D1_BLOCK + 7, 12)).astype(np.float32)
    queries = rng.random((3, 12))
    gallery[:9, :4] = 0.0
    queries[0, :2] = 0.0
    d = mean_normalized_manhattan(queries, gallery)
    for i, row in enumerate(queries):
        pairwise = paired_dissimilarity(np.broadcast_to(row, gallery.shape), gallery, "D1")
        np.testing.assert_array_equal(d[i], pairwise)


def test_d2_hand_computed():
    gallery = np.array([[0.0, 0.0], [2.0, 4.0]])
    sigma = gallery_sigma(gallery)
    np.testing.assert_allclose(sigma, [1.0, 2.0])
    # ((2-0)/1)^2 + ((4-0)/2)^2 = 8
    np.testing.assert_allclose(normalized_euclidean(gallery, gallery, sigma)[0, 1], np.sqrt(8))


def test_constant_element_gets_unit_sigma():
    sigma = gallery_sigma(np.array([[1.0, 5.0], [3.0, 5.0]]))
    np.testing.assert_allclose(sigma, [1.0, 1.0])


def test_fusion_rules():
    d = {"gdm": np.array([[1.0, 2.0]]), "ddt": np.array([[3.0, 0.5]])}
    np.testing.assert_allclose(fuse(d, "sum"), [[4.0, 2.5]])
    np.testing.assert_allclose(fuse(d, "product"), [[3.0, 1.0]])
    np.testing.assert_allclose(fuse(d, "sum", {"ddt": 2.0}), [[7.0, 3.0]])
    np.testing.assert_allclose(fuse(d, "product", {"gdm": 2.0}), [[3.0, 2.0]])
    with pytest.raises(ValueError, match="fusion rule"):
        fuse(d, "max")
    with pytest.raises(ValueError, match="fusion rule"):
        fuse({}, "max")
    with pytest.raises(ValueError, match="at least one"):
        fuse({}, "sum")


@pytest.mark.parametrize("kind", ["D1", "D2", REWEIGHTED])
def test_paired_dissimilarity_is_the_diagonal_of_the_matrix(kind):
    rng = np.random.default_rng(3)
    a, b = rng.random((7, 12)), rng.random((7, 12))
    sigma = gallery_sigma(b)
    np.testing.assert_allclose(
        paired_dissimilarity(a, b, kind, sigma), np.diag(dissimilarity(a, b, kind, sigma))
    )


def test_the_reweighted_euclidean_is_shapednas_comparison():
    """Against lapy itself: ``reweight_ev`` of the spectra with their zero eigenvalue
    first, then ``compute_distance(..., "euc")``, pair by pair (the plain reference)."""
    rng = np.random.default_rng(5)
    spectra = np.sort(rng.uniform(0.5, 80.0, (6, 50)), axis=1)  # without the zero one
    fast = dissimilarity(spectra[:2], spectra, REWEIGHTED)
    for i in range(2):
        for j in range(6):
            a, b = (reweight_ev(np.concatenate([[0.0], spectra[k]])) for k in (i, j))
            assert fast[i, j] == pytest.approx(compute_distance(a, b, "euc"), rel=1e-12)


def test_a_modality_is_compared_by_its_own_comparison_under_a_preset():
    """``with_fusion`` gives the spectrum ShapeDNA's comparison: the spectrum's score is
    then that, the other modalities' stay the preset's, and the weights are the new ones."""
    rng = np.random.default_rng(6)
    preset = get_preset(DEFAULT_PRESET)
    vectors = _flat_vectors(rng, 8)
    learned = with_fusion(preset, {"ddt": 0.25}, {"spectrum": REWEIGHTED, "ddt": "D1"})
    assert learned.comparison("spectrum") == REWEIGHTED and learned.comparison("ddt") == "D1"
    assert learned.comparisons == {"spectrum": REWEIGHTED} and learned.weight("ddt") == 0.25
    q, g = vectors["spectrum"][:3], vectors["spectrum"]
    np.testing.assert_array_equal(
        preset_dissimilarity("spectrum", q, g, learned), reweighted_euclidean(q, g)
    )
    np.testing.assert_array_equal(
        preset_dissimilarity("ddt", vectors["ddt"][:3], vectors["ddt"], learned),
        mean_normalized_manhattan(vectors["ddt"][:3], vectors["ddt"]),
    )
    fused_ones = learned.fused_modalities
    per = {m: dissimilarity(vectors[m][:3], vectors[m], learned.comparison(m)) for m in fused_ones}
    expected = fuse(
        per,
        "product",
        {m: learned.weight(m) for m in learned.fused_modalities},
    )
    fused = fused_dissimilarity({m: v[:3] for m, v in vectors.items()}, vectors, learned)
    np.testing.assert_allclose(fused, expected, rtol=1e-12)
    assert learned.descriptor_fields() == preset.descriptor_fields()
    with pytest.raises(ValueError, match="gdm cannot be compared by 'reweighted euclidean'"):
        with_fusion(preset, {}, {"gdm": REWEIGHTED})
    with pytest.raises(ValueError, match="unknown comparison 'cosine'"):
        with_fusion(preset, {}, {"gdm": "cosine"})


# ------------------------------------------------------------------- the size, units


def _flat_vectors(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """Flat vectors of ``n`` shapes: every modality of the default's sizes, and sizes."""
    sizes = get_preset(DEFAULT_PRESET).modality_sizes()
    vectors = {m: rng.random((n, k)) + 0.01 for m, k in sizes.items()}
    vectors[SIZE] = np.sqrt(rng.uniform(100.0, 400.0, (n, 1)))
    return vectors


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_a_units_any_preset_scores_exactly_as_before_the_size(name):
    """Units "any" (every shipped preset's): the fused score is the fused modalities'
    at the preset's weights, bit for bit, whatever the sizes; the size is not weighed."""
    preset = get_preset(name)
    assert preset.units == "any" and preset.scored_modalities == preset.fused_modalities
    rng = np.random.default_rng(3)
    queries, gallery = _flat_vectors(rng, 4), _flat_vectors(rng, 7)
    before = fuse(
        {
            m: dissimilarity(queries[m], gallery[m], preset.dissimilarity)
            for m in preset.fused_modalities
        },
        preset.fusion,
        {m: preset.weight(m) for m in preset.fused_modalities},
    )
    assert np.array_equal(fused_dissimilarity(queries, gallery, preset), before)
    resized = {**queries, SIZE: 10.0 * queries[SIZE]}
    assert np.array_equal(fused_dissimilarity(resized, gallery, preset), before)
    whole = {m: preset.weight(m) for m in preset.fused_modalities if preset.weight(m) != 0.0}
    assert query_weights(preset, 0.0) == whole


def test_the_size_is_zero_for_equal_areas_symmetric_scale_sensitive_and_unit_free():
    """Eq. (8) of ``[sqrt(A)]``: two files of one size are 0 apart, a copy scaled by 2
    (four times the area) ``2 |2 - 1| / 3`` from its original, whatever the unit both
    are in."""
    sizes = np.sqrt(np.array([[150.0], [150.0], [600.0], [320.0]]))
    d = size_dissimilarity(sizes, sizes)
    assert d[0, 1] == 0.0 and np.all(np.diag(d) == 0.0)
    np.testing.assert_array_equal(d, d.T)
    assert d[0, 2] == pytest.approx(2.0 / 3.0, rel=1e-14)
    assert np.all(d[0, 2:] > 0.0)
    np.testing.assert_allclose(size_dissimilarity(1e3 * sizes, 1e3 * sizes), d, rtol=1e-12)
    np.testing.assert_allclose(paired_size_dissimilarity(sizes[:2], sizes[2:]), [d[0, 2], d[1, 3]])


def test_sizes_within_the_tolerance_are_told_apart_by_the_shape_alone():
    """The preset's comparison raises eq. (8) to its tolerance: equal and nearly equal
    sizes all score it (the shape's score decides between them), larger differences
    score eq. (8) itself."""
    preset = with_units(get_preset(DEFAULT_PRESET), "metric")
    tolerance = preset.size_tolerance
    assert 0.0 < tolerance < 0.1 and preset.comparison(SIZE) == f"D1 >= {tolerance:g}"
    sizes = np.array([[100.0], [100.0], [100.0 * (1 + tolerance / 2)], [130.0]])
    d = preset_dissimilarity(SIZE, sizes, sizes, preset)
    np.testing.assert_array_equal(d[0, :3], tolerance)
    assert d[0, 3] == pytest.approx(2 * 30 / 230, rel=1e-14)
    np.testing.assert_array_equal(d, d.T)
    paired = paired_preset_dissimilarity(SIZE, sizes[:2], sizes[2:], preset)
    np.testing.assert_array_equal(paired, [d[0, 2], d[1, 3]])
    ddt = np.random.default_rng(5).random((4, 3))
    np.testing.assert_array_equal(
        preset_dissimilarity("ddt", ddt, ddt, preset), mean_normalized_manhattan(ddt, ddt)
    )


@pytest.mark.parametrize("name", ["smeets2010-surface", "smeets2010-tosca"])
def test_a_metric_preset_fuses_the_size_at_its_weight(name):
    """The product rule multiplies the shape's score by ``D_size^w``, the sum adds
    ``w D_size``; the same descriptors, only the comparison changes."""
    any_units = get_preset(name)
    metric = with_units(any_units, "metric")
    assert metric.scored_modalities == (*any_units.fused_modalities, SIZE)
    assert metric.descriptor_fields() == any_units.descriptor_fields()
    rng = np.random.default_rng(4)
    queries, gallery = _flat_vectors(rng, 3), _flat_vectors(rng, 5)
    shape = fused_dissimilarity(queries, gallery, any_units)
    size = np.maximum(
        mean_normalized_manhattan(queries[SIZE], gallery[SIZE]), metric.size_tolerance
    )
    w = metric.weight(SIZE)
    expected = shape * size**w if metric.fusion == "product" else shape + w * size
    np.testing.assert_allclose(fused_dissimilarity(queries, gallery, metric), expected, rtol=1e-12)
    assert query_weights(metric, 0.0)[SIZE] == w


def test_the_size_fades_out_as_a_query_looks_partial():
    """A part is smaller than its whole: the size's weight goes the way of the shape's."""
    metric = with_units(get_preset(DEFAULT_PRESET), "metric")
    w = metric.weight(SIZE)
    assert query_weights(metric, 0.5)[SIZE] == pytest.approx(0.5 * w)
    assert SIZE not in query_weights(metric, 1.0)
