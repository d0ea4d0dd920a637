"""Fusion weights by cross-validation, on small dissimilarities whose right weights are known."""

from __future__ import annotations

import numpy as np
import pytest

from worker.engine.compare import fuse
from worker.engine.presets import DEFAULT_PRESET, REWEIGHTED, get_preset
from worker.recognition.fusion import (
    FOLDS,
    GRID,
    PRESET_COMPARISON,
    FoldResult,
    FusionScores,
    FusionTuning,
    choose_weights,
    feasible_folds,
    fusion_scores,
    learn_fusion,
    stratified_folds,
    tune_fusion,
)
from worker.recognition.metrics import pair_equal_error_rate

#: Four classes of six objects: five folds leave at least four of each to choose on.
LABELS = np.repeat(np.arange(4), 6)
PERFECT = FusionScores(eer=0.0, nn=1.0, map=1.0)


def distances(points: np.ndarray) -> np.ndarray:
    """(n, n) Euclidean distances of (n, d) points."""
    return np.linalg.norm(points[:, None] - points[None], axis=-1)


def clustered(labels: np.ndarray, spread: float, rng: np.random.Generator) -> np.ndarray:
    """Distances of points scattered by ``spread`` around their class's centre (the
    centres 10 apart): at 0.1 every object's own class is nearer than any other, at 5
    the classes overlap."""
    centres = 10.0 * np.eye(labels.max() + 1)
    return distances(centres[labels] + spread * rng.standard_normal((len(labels), len(centres))))


def noise(n: int, rule: str, rng: np.random.Generator) -> np.ndarray:
    """Symmetric positive dissimilarities that know nothing of the classes, spread wide
    enough on the rule's scale (a factor of e^+-6 for the product, 0 to 100 for the sum)
    to bury the separated classes at weight 1."""
    x = np.exp(rng.normal(0.0, 3.0, (n, n))) if rule == "product" else rng.uniform(0, 100, (n, n))
    return np.triu(x, 1) + np.triu(x, 1).T


def test_stratified_folds_spread_every_class_evenly():
    labels = np.repeat(np.arange(4), [13, 7, 5, 3])
    fold = stratified_folds(labels, 5)
    for c in range(4):
        counts = np.bincount(fold[labels == c], minlength=5)
        assert counts.max() - counts.min() <= 1
    np.testing.assert_array_equal(fold, stratified_folds(labels, 5))  # seeded


@pytest.mark.parametrize("rule", ["product", "sum"])
def test_a_modality_of_pure_noise_gets_weight_zero(rule):
    rng = np.random.default_rng(0)
    mats = {"noise": noise(len(LABELS), rule, rng), "signal": clustered(LABELS, 0.1, rng)}
    tuning = tune_fusion(mats, LABELS, rule, {"noise": 1.0, "signal": 1.0})
    assert tuning.weights == {"noise": 0.0, "signal": 1.0}
    assert [f.weights for f in tuning.folds] == [tuning.weights] * 5
    assert tuning.loss == 0.0 and tuning.held_out == PERFECT
    # The noise's equal weight (the preset's here) costs on the held-out objects ...
    assert tuning.preset_held_out.loss > 0.1
    # ... and on every object the loss only grows with the noise's weight.
    assert tuning.sensitivity["noise"][0] == 0.0
    assert np.all(np.diff(tuning.sensitivity["noise"]) >= 0.0)
    assert tuning.sensitivity["noise"][-1] > 0.1
    assert sum(f.held_out_objects for f in tuning.folds) == len(LABELS)


def test_held_out_figures_read_only_the_pairs_and_queries_of_held_out_objects():
    labels = np.repeat(np.arange(3), 4)
    held = np.array([0, 5, 10])
    # Every pair among the other objects is wrong: impostors at 0.1, genuine pairs at 9.
    same = labels[:, None] == labels[None]
    d = np.where(same, 9.0, 0.1)
    # Every pair involving a held-out object is right: genuine 1, impostor 5.
    touching = np.isin(np.arange(12), held)
    touching = touching[:, None] | touching[None]
    d[touching] = np.where(same, 1.0, 5.0)[touching]
    np.fill_diagonal(d, 0.0)
    # Perfect although every pair among the others is wrong: none of them was read.
    assert fusion_scores(d, labels, held) == PERFECT
    everyone = fusion_scores(d, labels)
    assert everyone.eer > 0.5 and everyone.nn < 0.5


def test_each_folds_weights_are_chosen_without_its_objects():
    rng = np.random.default_rng(0)
    # Two modalities of overlapping classes: the folds choose different weights.
    mats = {"a": clustered(LABELS, 5.0, rng), "b": clustered(LABELS, 5.0, rng)}
    preset = {"a": 1.0, "b": 1.0}
    tuning = tune_fusion(mats, LABELS, "product", preset)
    assert len({f.weights["a"] for f in tuning.folds}) > 1
    fold = stratified_folds(LABELS, 5)
    for f, result in enumerate(tuning.folds):
        train, held = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        sub = {m: d[np.ix_(train, train)] for m, d in mats.items()}
        assert result.weights == choose_weights(sub, LABELS[train], "product")[0]
        fused = fuse(mats, "product", result.weights)
        assert result.held_out == fusion_scores(fused, LABELS, held)
        assert result.preset == fusion_scores(fuse(mats, "product", preset), LABELS, held)
    assert tuning.held_out.eer == pytest.approx(np.mean([r.held_out.eer for r in tuning.folds]))
    # Whatever fold 0's objects look like, fold 0's weights stay the same.
    scrambled = {m: d.copy() for m, d in mats.items()}
    zero = fold == 0
    touching = zero[:, None] | zero[None]
    scrambled["a"][touching] = noise(len(LABELS), "sum", rng)[touching]
    again = tune_fusion(scrambled, LABELS, "product", preset)
    assert again.folds[0].weights == tuning.folds[0].weights
    # ... while the same pairs do make its held-out figures.
    assert again.folds[0].held_out != tuning.folds[0].held_out


def test_the_grid_is_searched_for_every_modality_but_the_last():
    rng = np.random.default_rng(1)
    mats = {m: clustered(LABELS, 0.1, rng) for m in ("gdm", "ddt", "spectrum")}
    weights, loss = choose_weights(mats, LABELS, "product")
    assert weights["spectrum"] == 1.0 and {weights["gdm"], weights["ddt"]} <= set(GRID)
    assert loss == fusion_scores(fuse(mats, "product", weights), LABELS).loss


def test_too_small_a_class_or_a_single_modality_is_refused():
    rng = np.random.default_rng(2)
    labels = np.repeat(np.arange(3), [6, 6, 2])
    mats = {"a": clustered(labels, 0.1, rng), "b": clustered(labels, 0.1, rng)}
    with pytest.raises(ValueError, match=r"classes \['2'\] keep fewer than two"):
        tune_fusion(mats, labels, "product", {})
    with pytest.raises(ValueError, match="at least two modalities"):
        tune_fusion({"a": mats["a"]}, labels, "product", {})
    larger = np.repeat(np.arange(3), [6, 6, 3])
    with pytest.raises(ValueError, match=r"15 labels need \(15, 15\) dissimilarities"):
        tune_fusion(mats, larger, "product", {})
    mats = {"a": clustered(larger, 0.1, rng), "b": clustered(larger, 0.1, rng)}
    with pytest.raises(ValueError, match="15 objects cannot fill 20 folds"):
        tune_fusion(mats, larger, "product", {}, folds=20)


def test_a_better_comparison_of_a_modality_is_chosen_with_its_weight():
    rng = np.random.default_rng(3)
    mats = {"a": noise(len(LABELS), "product", rng), "b": clustered(LABELS, 5.0, rng)}
    # Modality a compared otherwise separates the classes: that comparison is chosen.
    alternatives = {"a": {"other": clustered(LABELS, 0.1, rng)}}
    tuning = tune_fusion(mats, LABELS, "product", {"a": 1.0, "b": 1.0}, alternatives=alternatives)
    assert tuning.comparisons == {"a": "other", "b": PRESET_COMPARISON}
    assert all(f.comparisons["a"] == "other" for f in tuning.folds)
    assert tuning.held_out.loss < tuning.preset_held_out.loss
    assert tuning.adoption().adopted


def test_the_preset_is_kept_when_the_learned_choice_gains_nothing_beyond_noise():
    """Two modalities that carry the same signal: whatever the folds choose scores
    about as the preset's weights, and the test keeps the preset's."""
    rng = np.random.default_rng(7)
    mats = {"a": clustered(LABELS, 4.0, rng), "b": clustered(LABELS, 4.0, rng)}
    adoption = tune_fusion(mats, LABELS, "product", {"a": 1.0, "b": 1.0}).adoption()
    assert not adoption.adopted and adoption.statistic <= adoption.critical


def _folds(gains: list[float], held_out: int = 17, n: int = 85) -> FusionTuning:
    """A tuning whose folds gain ``gains`` of loss over the preset (EER only)."""
    base = FusionScores(eer=0.1, nn=1.0, map=1.0)
    folds = tuple(
        FoldResult(held_out, {}, {}, FusionScores(0.1 - 2 * g, 1.0, 1.0), base) for g in gains
    )
    empty = np.zeros((n, n))
    return FusionTuning(
        "product", GRID, {}, {}, 0.0, folds, base, base, {}, empty, np.zeros(n, np.int64)
    )


def test_the_adoption_test_is_the_corrected_resampled_t_test():
    """Nadeau and Bengio's statistic by hand: mean gain over ``s sqrt(1/k + n2/n1)``,
    against Student's one-sided 95% quantile with k - 1 degrees of freedom (2.132 at 5)."""
    gains = [0.0051, 0.0018, 0.0034, 0.0039, 0.0020]
    adoption = _folds(gains).adoption()
    s = np.std(gains, ddof=1)
    expected = np.mean(gains) / (s * np.sqrt(1 / 5 + 17 / 68))
    assert adoption.gain == pytest.approx(np.mean(gains))
    assert adoption.statistic == pytest.approx(expected)
    assert adoption.critical == pytest.approx(2.131847, abs=1e-6)
    assert adoption.adopted is True  # consistent gains: t = 5.3 (a bool, as JSON needs)
    noisy = _folds([0.02, -0.015, 0.01, -0.01, 0.004]).adoption()  # mean > 0, noise
    assert noisy.gain > 0 and not noisy.adopted
    assert _folds([0.003] * 5).adoption().adopted  # the same gain on every fold
    assert not _folds([0.0] * 5).adoption().adopted
    assert not _folds([-0.01] * 5).adoption().adopted


def test_each_modality_names_the_comparison_it_was_made_with():
    """A size compared by D1 beside a shape compared by D2: each keeps its own name,
    and an alternative of one is chosen under its own."""
    rng = np.random.default_rng(4)
    mats = {"size": noise(len(LABELS), "product", rng), "shape": clustered(LABELS, 5.0, rng)}
    named = {"size": "D1", "shape": "D2"}
    alternatives = {"size": {"log-ratio": clustered(LABELS, 0.1, rng)}}
    tuning = tune_fusion(
        mats,
        LABELS,
        "product",
        {"size": 1.0, "shape": 1.0},
        comparison=named,
        alternatives=alternatives,
    )
    assert tuning.comparisons == {"size": "log-ratio", "shape": "D2"}
    plain = tune_fusion(mats, LABELS, "product", {"size": 1.0, "shape": 1.0}, comparison=named)
    assert plain.comparisons == named


def test_the_held_out_matrix_is_each_object_under_its_folds_choice():
    rng = np.random.default_rng(0)
    mats = {"a": clustered(LABELS, 5.0, rng), "b": clustered(LABELS, 5.0, rng)}
    tuning = tune_fusion(mats, LABELS, "product", {"a": 1.0, "b": 1.0})
    fold = stratified_folds(LABELS, 5)
    for f, result in enumerate(tuning.folds):
        rows = np.flatnonzero(fold == f)
        expected = fuse(mats, "product", result.weights)[rows]
        np.testing.assert_array_equal(tuning.held_out_matrix[rows], expected)
    # Its figures per query are the folds' held-out ones.
    queries = [fusion_scores(tuning.held_out_matrix, LABELS, np.flatnonzero(fold == f)).nn
               for f in range(5)]  # fmt: skip
    assert queries == [r.held_out.nn for r in tuning.folds]


def test_each_folds_pairs_are_scored_under_its_own_choice():
    rng = np.random.default_rng(0)
    mats = {"a": clustered(LABELS, 5.0, rng), "b": clustered(LABELS, 5.0, rng)}
    tuning = tune_fusion(mats, LABELS, "product", {"a": 1.0, "b": 1.0})
    for f, result in enumerate(tuning.folds):
        genuine, impostor = tuning.fold_pairs(f, LABELS)
        assert pair_equal_error_rate(genuine, impostor) == result.held_out.eer


def test_the_most_folds_that_cross_validate_are_used():
    assert feasible_folds(np.repeat(np.arange(4), [13, 7, 5, 3])) == 5  # a class of 3 too
    six = np.repeat(np.arange(2), 3)  # dealt into five folds, they leave one empty
    mats = {"a": distances(np.eye(6)), "b": distances(np.eye(6))}
    with pytest.raises(ValueError, match="cannot fill 5 folds"):
        tune_fusion(mats, six, "sum", {})
    assert feasible_folds(six) == 4
    assert len(tune_fusion(mats, six, "sum", {}, folds=4).folds) == 4
    with pytest.raises(ValueError, match="keep fewer than two"):
        feasible_folds(np.repeat(np.arange(3), [3, 3, 2]))


def test_learn_fusion_offers_every_comparison_a_modality_may_take():
    """The spectrum with D1, D2 and ShapeDNA's comparison, the GDM and DDT with D1 and D2,
    the preset's first; a spectrum whose reweighted distance alone knows the classes is
    given it."""
    rng = np.random.default_rng(8)
    preset = get_preset(DEFAULT_PRESET)
    sizes = preset.modality_sizes()
    labels = np.repeat(np.arange(4), 6)
    vectors = {m: np.exp(rng.normal(0.0, 1.0, (24, d))) for m, d in sizes.items()}
    # The first eigenvalue tells the classes apart; ShapeDNA's weights (1/2 there) keep it
    # dominant while eq. (8) averages it with 49 elements of noise.
    spectrum = np.exp(rng.normal(0.0, 0.05, (24, sizes["spectrum"])))
    spectrum[:, 0] = 50.0 * (1 + labels) + rng.normal(0.0, 1.0, 24)
    vectors["spectrum"] = spectrum
    tuning = learn_fusion(vectors, labels, preset)
    assert tuning.comparisons["spectrum"] == REWEIGHTED
    assert set(tuning.comparisons) == set(preset.fused_modalities)
    assert {tuning.comparisons[m] for m in ("gdm", "ddt")} <= {"D1", "D2"}
    assert tuning.held_out.loss < tuning.preset_held_out.loss


def test_rounds_of_folds_are_dealt_from_their_own_seeds_and_all_tested():
    """Three rounds: 3 k folds, each round's objects held out once; the held-out matrix
    and the fold of each object are the first round's (the single round's own)."""
    rng = np.random.default_rng(9)
    mats = {"a": clustered(LABELS, 4.0, rng), "b": clustered(LABELS, 4.0, rng)}
    one = tune_fusion(mats, LABELS, "product", {"a": 1.0, "b": 1.0})
    three = tune_fusion(mats, LABELS, "product", {"a": 1.0, "b": 1.0}, repeats=3)
    assert three.repeats == 3 and len(three.folds) == 3 * FOLDS
    assert sum(f.held_out_objects for f in three.folds) == 3 * len(LABELS)
    assert three.folds[:FOLDS] == one.folds
    np.testing.assert_array_equal(three.held_out_matrix, one.held_out_matrix)
    np.testing.assert_array_equal(three.fold_of, one.fold_of)
    second = tune_fusion(mats, LABELS, "product", {"a": 1.0, "b": 1.0}, seed=1)
    assert three.folds[FOLDS : 2 * FOLDS] == second.folds  # round 1 is seed 1's split
    assert three.adoption().critical == pytest.approx(1.761310, abs=1e-6)  # 14 d.o.f.
