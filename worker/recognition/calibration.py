"""Verification calibration: from genuine and impostor scores to decisions and confidences.

Pure numpy. The service calibrates its gallery with it (``GET /calibration``,
``POST /verify``, every match's ``confidence``), and ``shapes evaluate`` computes
its ROC and EER with it, so the offline report and the live endpoint agree on the
same data.

A score is a dissimilarity (smaller is more alike). A pair is *genuine* when both
shapes carry the same label, an *impostor* pair otherwise; at threshold ``t`` a
pair is accepted when its score is ``<= t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .metrics import pair_equal_error_rate, pair_roc

#: Fewer genuine or impostor pairs than this and there is nothing to calibrate.
MIN_PAIRS = 10
#: The rule for "enough to trust": at least this many genuine pairs ...
TRUSTED_GENUINE = 100
#: ... and enough impostor pairs that FAR 0.1% is at least one accepted impostor.
TRUSTED_IMPOSTOR = 1000
#: FAR operating points the calibration states thresholds for.
OPERATING_FARS = (0.001, 0.01, 0.05)


@dataclass(frozen=True)
class Calibration:
    """What the genuine and impostor scores of one kind of score say.

    Attributes
    ----------
    genuine, impostor : number of pairs of each kind.
    far, frr, thresholds : the ROC (:func:`worker.recognition.metrics.pair_roc`).
    eer : equal error rate.
    knots, probabilities : the isotonic map from score to the probability that the
        pair is genuine (non-increasing; linear in between, constant outside).
    """

    genuine: int
    impostor: int
    far: NDArray[np.float64]
    frr: NDArray[np.float64]
    thresholds: NDArray[np.float64]
    eer: float
    knots: NDArray[np.float64]
    probabilities: NDArray[np.float64]

    @property
    def trusted(self) -> bool:
        """At least ``TRUSTED_GENUINE`` genuine and ``TRUSTED_IMPOSTOR`` impostor pairs."""
        return self.genuine >= TRUSTED_GENUINE and self.impostor >= TRUSTED_IMPOSTOR

    def threshold_at(self, far: float) -> float:
        """The largest threshold whose false acceptance rate is at most ``far``
        (``-inf`` accepts nothing when even the best impostor is too close)."""
        allowed = np.flatnonzero(self.far <= far)
        return float(self.thresholds[allowed[-1]])

    def rates_at(self, threshold: float) -> tuple[float, float]:
        """``(FAR, FRR)`` at ``threshold``, as estimated from the pairs."""
        i = int(np.searchsorted(self.thresholds, threshold, side="right")) - 1
        return float(self.far[i]), float(self.frr[i])

    def confidence(self, scores: ArrayLike) -> NDArray[np.float64]:
        """The probability that a pair with these scores is genuine."""
        return np.interp(np.asarray(scores, dtype=np.float64), self.knots, self.probabilities)


def calibrate(genuine: ArrayLike, impostor: ArrayLike, min_pairs: int = MIN_PAIRS) -> Calibration:
    """The calibration of a score from its genuine and impostor pairs.

    ``min_pairs`` is the fewest pairs of each kind accepted: the service refuses to
    calibrate on fewer than ``MIN_PAIRS``; an evaluation reports the ROC of any set.

    Raises
    ------
    ValueError
        With fewer than ``min_pairs`` pairs of either kind.
    """
    g = np.asarray(genuine, dtype=np.float64).ravel()
    i = np.asarray(impostor, dtype=np.float64).ravel()
    if g.size < max(min_pairs, 1) or i.size < max(min_pairs, 1):
        raise ValueError(
            f"calibration needs at least {min_pairs} genuine and {min_pairs} impostor pairs, "
            f"got {g.size} and {i.size}"
        )
    far, frr, thresholds = pair_roc(g, i)
    scores = np.concatenate([g, i])
    same = np.concatenate([np.ones(g.size), np.zeros(i.size)])
    knots, probabilities = isotonic_decreasing(scores, same)
    return Calibration(
        genuine=int(g.size),
        impostor=int(i.size),
        far=far,
        frr=frr,
        thresholds=thresholds,
        eer=pair_equal_error_rate(g, i),
        knots=knots,
        probabilities=probabilities,
    )


def isotonic_decreasing(
    x: ArrayLike, y: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Least-squares non-increasing fit of ``y`` on ``x`` (pool adjacent violators).

    Parameters
    ----------
    x : (n,) float, the scores.
    y : (n,) float, the outcomes (1 genuine, 0 impostor).

    Returns
    -------
    knots : (b,) float, increasing: the mean score of each pooled block.
    values : (b,) float, non-increasing: each block's mean outcome.
    """
    order = np.argsort(np.asarray(x, dtype=np.float64), kind="stable")
    xs = np.asarray(x, dtype=np.float64)[order]
    ys = np.asarray(y, dtype=np.float64)[order]
    # Equal scores are one observation of their mean outcome.
    unique, start = np.unique(xs, return_index=True)
    counts = np.diff(np.append(start, xs.size)).astype(np.float64)
    sums = np.add.reduceat(ys, start)
    # Blocks as a stack: merge while the newest block's mean exceeds the previous one's.
    block_sum: list[float] = []
    block_count: list[float] = []
    block_x: list[float] = []
    for value, s, c in zip(unique, sums, counts, strict=True):
        block_sum.append(float(s))
        block_count.append(float(c))
        block_x.append(float(value) * float(c))
        while len(block_sum) > 1 and (
            block_sum[-1] / block_count[-1] > block_sum[-2] / block_count[-2]
        ):
            s2, c2, x2 = block_sum.pop(), block_count.pop(), block_x.pop()
            block_sum[-1] += s2
            block_count[-1] += c2
            block_x[-1] += x2
    count = np.asarray(block_count)
    return np.asarray(block_x) / count, np.asarray(block_sum) / count
