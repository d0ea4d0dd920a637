"""The gallery's calibration of any fusion a search asks for, against a plain fit of the
same pairs scored exhaustively (no server)."""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest

from app.gallery.pairs import FUSED, fit_calibration
from worker.engine.compare import dissimilarity, fuse
from worker.recognition.calibration import calibrate

from .test_index import SHREC, TOSCA, _gallery, _index


@pytest.mark.parametrize("preset", [SHREC, TOSCA], ids=["D2-product", "D1-sum"])
def test_every_fusion_is_calibrated_from_the_pairs_it_would_rank_by(preset):
    gallery = _gallery(48, seed=3, preset=preset)
    index = _index(preset, gallery)
    labels = {i: f"class-{i % 6}" for i in range(48)}
    fit = fit_calibration(index, labels, preset, max_pairs=10_000, version=0)
    first, second = np.array(list(combinations(range(48), 2))).T
    genuine = np.array(
        [labels[int(a)] == labels[int(b)] for a, b in zip(first, second, strict=True)]
    )
    sigma = index.sigma() if preset.dissimilarity == "D2" else None

    def pair_scores(m: str) -> np.ndarray:
        whole = dissimilarity(
            gallery[m], gallery[m], preset.dissimilarity, None if sigma is None else sigma[m]
        )
        return whole[first, second]

    for modalities, rule in [(("gdm", "ddt"), "sum"), (("gdm", "ddt", "spectrum"), "product")]:
        weights = {m: preset.weight(m) for m in modalities}
        scores = fuse({m: pair_scores(m) for m in modalities}, rule, weights)
        expected = calibrate(scores[genuine], scores[~genuine])
        found = fit.for_fusion(modalities, rule)
        assert found.eer == pytest.approx(expected.eer)
        assert found.threshold_at(0.05) == pytest.approx(expected.threshold_at(0.05))
        assert fit.for_fusion(modalities, rule) is found  # fitted once, then kept
    own = tuple(preset.fused_modalities)
    assert fit.for_fusion(own, preset.fusion) is fit.rows[FUSED]
    assert fit.for_fusion(("ddt",), "sum") is fit.rows["ddt"]
