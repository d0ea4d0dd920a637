"""Calibration: ROC, thresholds at a FAR, and the isotonic confidence, on known scores."""

from __future__ import annotations

import numpy as np
import pytest

from worker.recognition import metrics
from worker.recognition.calibration import calibrate, isotonic_decreasing


def test_separated_scores_have_no_error_and_certain_confidences():
    c = calibrate(np.linspace(0.0, 1.0, 20), np.linspace(2.0, 3.0, 30))
    assert (c.genuine, c.impostor, c.eer) == (20, 30, 0.0)
    t = c.threshold_at(0.01)
    assert 1.0 <= t < 2.0 and c.rates_at(t) == (0.0, 0.0)
    np.testing.assert_allclose(c.confidence([0.0, 0.5, 2.5, 9.0]), [1.0, 1.0, 0.0, 0.0])
    assert not c.trusted


def test_threshold_at_a_far_and_the_rates_there():
    genuine = np.arange(1.0, 41.0)  # 1 .. 40
    impostor = np.arange(30.5, 130.5)  # 30.5 .. 129.5: the 10 lowest overlap the genuines
    c = calibrate(genuine, impostor)
    t = c.threshold_at(0.05)  # at most 5 of the 100 impostors accepted
    far, frr = c.rates_at(t)
    # The fifth impostor is 34.5, the sixth 35.5: every score up to 35 may be accepted.
    assert far == pytest.approx(0.05) and t == 35.0
    assert frr == pytest.approx(5 / 40)  # 36 .. 40 rejected
    assert c.rates_at(c.threshold_at(0.0))[0] == 0.0
    assert c.eer == pytest.approx(metrics.pair_equal_error_rate(genuine, impostor))


def test_eer_is_the_evaluations_on_the_same_pairs():
    rng = np.random.default_rng(0)
    d = rng.random((30, 30))
    d = d + d.T
    labels = np.repeat(np.arange(6), 5)
    i, j = np.triu_indices(30, 1)
    same = labels[i] == labels[j]
    c = calibrate(d[i, j][same], d[i, j][~same])
    assert c.eer == metrics.equal_error_rate(d, labels)
    far, frr, thresholds = metrics.roc_curve(d, labels)
    np.testing.assert_array_equal(c.far, far)
    np.testing.assert_array_equal(c.thresholds, thresholds)


def test_isotonic_fit_is_monotone_and_keeps_the_mean():
    rng = np.random.default_rng(1)
    x = rng.random(500)
    y = (rng.random(500) < 1.0 - x).astype(float)  # genuine more likely at low scores
    knots, values = isotonic_decreasing(x, y)
    assert np.all(np.diff(knots) > 0) and np.all(np.diff(values) <= 0)
    # Pooling preserves each block's sum, so the overall mean too.
    fitted = np.interp(np.sort(x), knots, values)
    assert abs(fitted.mean() - y.mean()) < 0.02
    # A hand-checkable case: the violator (0 at x=1, 1 at x=2) is pooled to 0.5.
    knots, values = isotonic_decreasing([0.0, 1.0, 2.0, 3.0], [1.0, 0.0, 1.0, 0.0])
    np.testing.assert_allclose(values, [1.0, 0.5, 0.0])
    np.testing.assert_allclose(knots, [0.0, 1.5, 3.0])


def test_too_few_pairs_to_calibrate():
    with pytest.raises(ValueError, match="at least 10 genuine"):
        calibrate(np.arange(5.0), np.arange(50.0))
