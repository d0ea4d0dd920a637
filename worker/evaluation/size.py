"""The size's weight in a collection of metric units: ``shapes tune --units metric``.

A metric collection scores a whole query by the preset's fused score of the shape and the
size (:attr:`~worker.engine.presets.Preset.scored_modalities`), the shape's modalities at
the weights the preset chose without the size. So the size's weight is chosen against
that score as one modality: :func:`~worker.recognition.fusion.tune_fusion` with two, the
size on :data:`SIZE_GRID` and the shape's score at 1 (its rule's weight of one: the
product ``(prod_m D_m^w_m)^1 D_size^w`` and the sum ``1 sum_m w_m D_m + w D_size`` are the
metric preset's score at size weight ``w``), by the same class-stratified folds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from worker.engine.compare import fuse
from worker.engine.presets import SIZE, Preset
from worker.recognition.fusion import FOLDS, FusionTuning, tune_fusion

from .scoring import modality_dissimilarity, preset_matrix

#: The size's weights tried against the shape's score at 1 (the product's exponent, the
#: sum's factor); beyond 1 the size outweighs the shape.
SIZE_GRID = (0.0, 0.0625, 0.125, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
#: The preset's fused score of the shape, one modality of the size's tuning.
SHAPE = "shape"


def shape_and_size(
    vectors: Mapping[str, np.ndarray], preset: Preset
) -> tuple[np.ndarray, np.ndarray]:
    """All-to-all (n, n): the preset's fused score of the shape (its fused modalities at
    its weights), and the size as the preset compares it (eq. 8 at least its tolerance)."""
    shape = fuse(
        {
            m: modality_dissimilarity(vectors[m], preset.dissimilarity)[0]
            for m in preset.fused_modalities
        },
        preset.fusion,
        {m: preset.weight(m) for m in preset.fused_modalities},
    )
    size = preset_matrix(SIZE, vectors[SIZE], preset)[0]
    return shape, size


def size_tuning(
    vectors: Mapping[str, np.ndarray],
    labels: Sequence[str] | np.ndarray,
    preset: Preset,
    *,
    folds: int = FOLDS,
    grid: tuple[float, ...] = SIZE_GRID,
    alternatives: Mapping[str, np.ndarray] | None = None,
) -> FusionTuning:
    """Choose the size's weight against the preset's score of the shape by
    class-stratified cross-validation (the module's docstring).

    Parameters
    ----------
    vectors : modality -> (n, M), the fused modalities' and ``SIZE`` -> (n, 1).
    labels : (n,) the class of each object.
    preset : the shape's score (its rule and weights) and the size's comparison; its own
        size weight (0 without one) is scored on the same folds.
    folds, grid : of :func:`~worker.recognition.fusion.tune_fusion`, ``grid`` the size's.
    alternatives : comparison name -> (n, n), other comparisons of the size to choose
        from (the folds choose each with its weight; the size's own is preferred on equal
        losses).

    Returns
    -------
    FusionTuning over the modalities ``SIZE`` and :data:`SHAPE` (weight 1).
    """
    shape, size = shape_and_size(vectors, preset)
    own = {SIZE: preset.fusion_weights.get(SIZE, 0.0), SHAPE: 1.0}
    return tune_fusion(
        {SIZE: size, SHAPE: shape},
        np.asarray(labels),
        preset.fusion,
        own,
        folds=folds,
        grid=grid,
        comparison={SIZE: preset.comparison(SIZE), SHAPE: "preset"},
        alternatives=None if alternatives is None else {SIZE: alternatives},
    )
