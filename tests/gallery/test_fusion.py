"""A gallery learning its fusion weights from its labelled shapes (no server)."""

from __future__ import annotations

import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from app.gallery.index import GalleryIndex
from app.gallery.service import Gallery
from app.gallery.weights import MIN_CLASSES, learn_gallery_fusion, pinned_fusion
from app.metrics import Metrics
from worker.engine.compare import reweighted_euclidean
from worker.engine.presets import DEFAULT_PRESET, MODALITIES, REWEIGHTED, get_preset

#: The default preset with every weight 1: a modality of noise costs it.
EQUAL = replace(get_preset(DEFAULT_PRESET), fusion_weights={})


def _noisy_gdm(n: int, seed: int = 0) -> tuple[dict[str, np.ndarray], dict[int, str]]:
    """Shapes of 12 overlapping classes, whose GDM is noise (the other modalities know the
    class, loosely: at weight 1 the noise costs the preset's fusion half its mAP)."""
    rng = np.random.default_rng(seed)
    classes = rng.integers(0, 12, size=n)
    gallery = {}
    for m, d in EQUAL.modality_sizes().items():
        centres = rng.normal(size=(12, d))
        gallery[m] = np.exp(centres[classes] + 1.5 * rng.normal(size=(n, d)))
    gallery["gdm"] = np.exp(rng.normal(0.0, 1.0, gallery["gdm"].shape))
    return gallery, {i: f"class-{c}" for i, c in enumerate(classes)}


def _loaded(preset, gallery, directory: Path = Path("not-saved")) -> Gallery:
    """A gallery whose index holds ``gallery`` (as loading would; nothing saved)."""
    g = Gallery(
        (1, "default"),
        preset,
        directory,
        refit_fraction=0.05,
        metrics=Metrics(),
        lock=threading.RLock(),
    )
    index = GalleryIndex(g.preset, preset.modality_sizes())
    index.add_many((i, {m: gallery[m][i] for m in MODALITIES}) for i in range(len(gallery["gdm"])))
    g._index = index
    return g


def test_a_modality_of_noise_is_weighed_out_and_the_choice_adopted():
    gallery, labels = _noisy_gdm(96)
    g = _loaded(EQUAL, gallery)
    fit = learn_gallery_fusion(g._index, labels, EQUAL, max_shapes=300, version=3)
    assert fit.source == "learned" and fit.weights["gdm"] == 0.0
    assert fit.tuning is not None and fit.tuning.held_out.loss < fit.tuning.preset_held_out.loss
    assert fit.shapes == 96 and not fit.sampled and fit.version == 3
    assert "held-out EER" in fit.reason
    # Adopted: the index ranks and the calibration fits with the learned weights.
    g.adopt_fusion(fit)
    assert g.fusion is fit and g.preset.weight("gdm") == 0.0 and g._index.preset is g.preset
    assert g.base_preset is EQUAL


def test_above_the_budget_a_stratified_sample_is_learned_on():
    gallery, labels = _noisy_gdm(160, seed=1)
    g = _loaded(EQUAL, gallery)
    fit = learn_gallery_fusion(g._index, labels, EQUAL, max_shapes=60, version=0)
    assert fit.sampled and 60 <= fit.shapes < 90 and fit.classes == len(set(labels.values()))


def test_too_few_labels_keep_the_preset_and_say_why():
    gallery, _ = _noisy_gdm(40)
    g = _loaded(EQUAL, gallery)
    two = {i: "a" if i % 2 else "b" for i in range(40)}
    fit = learn_gallery_fusion(g._index, two, EQUAL, max_shapes=300, version=0)
    assert fit.source == "preset" and fit.tuning is None
    assert f"at least {MIN_CLASSES} labels" in fit.reason


def test_weights_that_do_not_beat_the_preset_are_not_adopted():
    gallery, labels = _noisy_gdm(96)
    preset = replace(EQUAL, fusion_weights={"gdm": 0.0})  # already weighs the noise out
    g = _loaded(preset, gallery)
    fit = learn_gallery_fusion(g._index, labels, preset, max_shapes=300, version=0)
    assert fit.source == "preset" and fit.weights == {"gdm": 0.0, "ddt": 1.0, "spectrum": 1.0}
    assert "not better" in fit.reason and fit.tuning is not None


def test_pinned_weights_weigh_known_modalities_and_keep_the_presets_for_the_rest():
    pinned = pinned_fusion(EQUAL, {"gdm": 0.25, "ddt": 0.5, "spectrum": 1.0})
    assert pinned.source == "pinned" and pinned.weights["gdm"] == 0.25
    some = pinned_fusion(EQUAL, {"gdm": 0.25, "size": 3.0})  # the size: unused, any units
    assert some.weights == {m: 0.25 if m == "gdm" else EQUAL.weight(m) for m in MODALITIES}
    for bad in ({"colour": 1.0}, {"gdm": -1.0, "ddt": 1.0, "spectrum": 1.0}):
        try:
            pinned_fusion(EQUAL, bad)
        except ValueError:
            continue
        raise AssertionError(f"{bad} accepted")


def test_a_learned_comparison_is_adopted_and_the_index_ranks_with_it():
    """A spectrum that only ShapeDNA's comparison reads well (its first eigenvalue knows
    the class; eq. 8 averages it with 49 elements of noise): the gallery learns that
    comparison, and after adopting it the index and its scores use it."""
    rng = np.random.default_rng(5)
    n = 60
    classes = np.repeat(np.arange(6), 10)
    gallery = {m: np.exp(rng.normal(0.0, 1.0, (n, d))) for m, d in EQUAL.modality_sizes().items()}
    spectrum = np.exp(rng.normal(0.0, 0.05, (n, gallery["spectrum"].shape[1])))
    spectrum[:, 0] = 50.0 * (1 + classes) + rng.normal(0.0, 1.0, n)
    gallery["spectrum"] = spectrum
    labels = {i: f"class-{c}" for i, c in enumerate(classes)}
    g = _loaded(EQUAL, gallery)
    fit = learn_gallery_fusion(g._index, labels, EQUAL, max_shapes=300, version=1)
    assert fit.source == "learned" and fit.comparisons["spectrum"] == REWEIGHTED
    assert fit.adoption is not None and fit.adoption.adopted
    assert all(fold.comparisons["spectrum"] == REWEIGHTED for fold in fit.tuning.folds)
    g.adopt_fusion(fit)
    assert g.preset.comparison("spectrum") == REWEIGHTED and g._index.preset is g.preset
    assert g._index.fits["spectrum"].comparison == REWEIGHTED
    query = {m: gallery[m][0] for m in MODALITIES}
    best = g._index.search(query, 2, exclude=[0])[0]
    assert best.scores["spectrum"] == pytest.approx(
        float(reweighted_euclidean(spectrum[:1], spectrum[best.id : best.id + 1])[0, 0])
    )
    assert labels[best.id] == labels[0]


def test_a_learned_fusion_ranks_again_after_a_restart_until_the_first_fit(tmp_path):
    """The adopted fusion is kept beside the saved index; a new process's gallery ranks
    with it (and says so) until it has learned again. A file that is not a saved fusion of
    the preset is ignored, and a fit that keeps the preset's forgets the saved one."""
    gallery, labels = _noisy_gdm(96)
    g = _loaded(EQUAL, gallery, directory=tmp_path / "idx")
    g.learn_fusion = True
    g._refit_fusion(g._index, labels, version=0)
    assert g.fusion.source == "learned" and g.fusion_file.is_file()

    again = _loaded(EQUAL, gallery, directory=tmp_path / "idx")
    again.learn_fusion = True
    again._restore_fusion()
    restored = again.fusion
    assert restored.source == "learned" and restored.tuning is None
    assert (restored.weights, restored.comparisons) == (g.fusion.weights, g.fusion.comparisons)
    assert restored.reason.startswith("learned before the service restarted")
    assert again.preset == g.preset and again.fusion.version != again._version  # refits

    again.fusion_file.write_text('{"weights": {"colour": 1}}')
    third = _loaded(EQUAL, gallery, directory=tmp_path / "idx")
    third.learn_fusion = True
    third._restore_fusion()
    assert third.fusion.source == "preset"

    same = replace(EQUAL, fusion_weights={"gdm": 0.0})  # nothing left to learn
    kept = _loaded(same, gallery, directory=tmp_path / "idx")
    kept.learn_fusion = True
    kept._refit_fusion(kept._index, labels, version=0)
    assert kept.fusion.source == "preset" and not kept.fusion_file.exists()
