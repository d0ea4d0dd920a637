"""The gallery's yardstick of closeness against a plain count over the same pairs, and its
meaning: within a class is close, across classes is not (no server)."""

from __future__ import annotations

import numpy as np
import pytest

from app.gallery.reference import FLAT_PAIRS, fit_reference
from worker.engine.compare import dissimilarity

from .test_index import SHREC, TOSCA, _gallery, _index


@pytest.mark.parametrize("preset", [SHREC, TOSCA], ids=["D2-product", "D1-sum"])
def test_closeness_is_the_share_of_pairs_of_different_objects_farther_apart(preset):
    gallery = _gallery(64, seed=5, preset=preset)
    index = _index(preset, gallery)
    labels = {i: f"class-{i % 8}" for i in range(0, 64, 2)}  # half the shapes labelled
    reference = fit_reference(index, labels, [], version=7)
    assert reference.version == 7
    sigma = index.sigma() if preset.dissimilarity == "D2" else None
    for m in preset.modality_sizes():
        pairs = reference.scores[m]
        # Every pair drawn is of two shapes that do not share a label (most of them).
        assert 0.5 * FLAT_PAIRS < len(pairs) <= FLAT_PAIRS
        assert np.all(np.diff(pairs) >= 0)
        whole = dissimilarity(
            gallery[m], gallery[m], preset.dissimilarity, None if sigma is None else sigma[m]
        )
        for value in np.quantile(whole[np.triu_indices(64, 1)], [0.05, 0.5, 0.95]):
            expected = np.count_nonzero(pairs > value) / len(pairs)
            assert reference.closeness(m, float(value)) == pytest.approx(expected)
        assert reference.closeness(m, 0.0) == 1.0  # closer than any pair of two shapes
        assert reference.closeness(m, float(pairs[-1])) == 0.0


def test_a_nearest_neighbour_is_closer_than_most_pairs_of_different_objects():
    gallery = _gallery(96, seed=2)
    index = _index(SHREC, gallery)
    reference = fit_reference(index, {}, [], version=0)
    whole = dissimilarity(gallery["ddt"], gallery["ddt"], "D2", index.sigma()["ddt"])
    np.fill_diagonal(whole, np.inf)
    nearest = whole.min(axis=1)  # each shape's nearest neighbour: mostly its own class
    closeness = [reference.closeness("ddt", float(v)) for v in nearest]
    assert np.median(closeness) > 0.9


def test_a_gallery_of_one_shape_has_no_yardstick():
    index = _index(SHREC, {m: v[:1] for m, v in _gallery(8).items()})
    reference = fit_reference(index, {}, [], version=0)
    assert reference.closeness("ddt", 0.5) is None
