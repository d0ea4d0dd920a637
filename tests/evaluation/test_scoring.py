"""The pure half of the evaluation: dissimilarity matrices, D2's sigma, fusion, scores."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from worker.engine.compare import mean_normalized_manhattan
from worker.engine.presets import Preset
from worker.evaluation.scoring import (
    BASELINE,
    dissimilarity_matrices,
    modality_dissimilarity,
    score_dissimilarity,
)

PRESET = Preset(name="test-scoring", version=0, n_vertices=500, n_eigenpairs=100)


def test_d2_uses_the_standard_deviation_over_all_objects():
    rng = np.random.default_rng(1)
    x = rng.gamma(2.0, size=(6, 5))
    x[:, 4] = 3.0  # no spread: gallery_sigma sets sigma = 1
    d, info = modality_dissimilarity(x, "D2")
    sigma = np.where(x.std(axis=0) > 0, x.std(axis=0), 1.0)
    expected = np.sqrt((((x[:, None, :] - x[None, :, :]) / sigma) ** 2).sum(-1))
    np.testing.assert_allclose(d, expected, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(info["sigma"], sigma)
    assert np.array_equal(d, d.T) and np.all(np.diag(d) == 0)
    # sigma normalizes each element: rescaling one element changes nothing
    scaled = x * np.array([1.0, 1000.0, 1e-3, 7.0, 1.0])
    np.testing.assert_allclose(modality_dissimilarity(scaled, "D2")[0], d, rtol=1e-8)


def test_d1_is_eq_8():
    x = np.random.default_rng(2).gamma(2.0, size=(5, 4))
    d, info = modality_dissimilarity(x, "D1")
    np.testing.assert_allclose(d, mean_normalized_manhattan(x, x), atol=1e-15)
    assert info == {"dissimilarity": "D1"}
    with pytest.raises(ValueError, match="unknown dissimilarity"):
        modality_dissimilarity(x, "D3")


def test_fusion_rows_use_preset_weights():
    rng = np.random.default_rng(3)
    vectors = {m: rng.gamma(2.0, size=(5, 3)) for m in ("gdm", "ddt", "spectrum")}
    preset = dataclasses.replace(
        PRESET, dissimilarity="D1", fusion_weights={"gdm": 2.0, "spectrum": 0.5}
    )
    matrices, info = dissimilarity_matrices(vectors, preset, baseline=None)
    gdm, ddt, spectrum = (matrices[m] for m in ("gdm", "ddt", "spectrum"))
    np.testing.assert_allclose(matrices["gdm+ddt sum"], 2 * gdm + ddt)
    np.testing.assert_allclose(matrices["gdm+ddt product"], gdm**2 * ddt)
    np.testing.assert_allclose(matrices["gdm+ddt+spectrum sum"], 2 * gdm + ddt + 0.5 * spectrum)
    np.testing.assert_allclose(
        matrices["gdm+ddt+spectrum product"], gdm**2 * ddt * np.sqrt(spectrum)
    )
    assert BASELINE not in matrices
    assert info["gdm+ddt sum"] == {"fusion": "sum", "weights": {"gdm": 2.0, "ddt": 1.0}}


def test_score_dissimilarity_names_the_confusions():
    # a0 a1 | b0 b1; a1 is closer to b0 than to a0, everything else is clean
    d = np.array(
        [
            [0.0, 0.5, 0.9, 0.9],
            [0.5, 0.0, 0.2, 0.9],
            [0.9, 0.2, 0.0, 0.1],
            [0.9, 0.9, 0.1, 0.0],
        ]
    )
    names = ["a0", "a1", "b0", "b1"]
    labels = ["a", "a", "b", "b"]
    scores = score_dissimilarity(d, labels, names, np.array([0, 2]), np.array([1, 3]))
    assert scores["nn"] == 0.75
    assert scores["nn_errors"] == [
        {"query": "a1", "class": "a", "nearest": "b0", "nearest_class": "b"}
    ]
    assert scores["r1rr"] == 0.5
    assert scores["rank1_errors"] == [
        {"probe": "a1", "class": "a", "matched": "b0", "matched_class": "b"}
    ]
    assert scores["cmc"] == [0.5, 1.0]
    # genuine 0.5, 0.1; impostors 0.9, 0.2, 0.9, 0.9: FRR = FAR = 1/4 between 0.2 and 0.5
    assert scores["eer"] == pytest.approx(0.25)
