"""The gallery's fusion weights: the preset's, the operator's (pinned), or learned on the
gallery's own labelled shapes.

The paper leaves the fusion weights to future work (sec. 5); the preset's were chosen on
TOSCA. A gallery with labels can do better for its own kind of objects: each modality's
weight and comparison (D1, D2, ShapeDNA's for the spectrum) are chosen by
class-stratified cross-validation on its labelled shapes with the code ``shapes evaluate
--fusion learned`` uses (:func:`worker.recognition.fusion.learn_fusion`, the preset's
rule), and adopted only if the held-out folds favour them over the preset's beyond the
folds' noise (:meth:`~worker.recognition.fusion.FusionTuning.adoption`, a corrected
resampled t-test of the gain in loss, the mean of EER and 1 - mAP); otherwise the
preset's stay, and the answer says why.

Learning needs at least ``MIN_CLASSES`` labels with at least ``MIN_PER_CLASS`` shapes
each (a fold must leave two of every class to choose on); smaller labels take no part.
Five folds, or the most that hold a shape each, in ``REPEATS`` rounds. Its cost is bounded
like the calibration's: above ``max_shapes`` labelled shapes a seeded, class-stratified
sample is learned on, so a fit takes the same time whatever the gallery's size, and the
next waits ``IDLE_AFTER_FIT`` times as long. It runs in a thread of its own, reading the
index only to copy the sampled vectors, so no search waits for it.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np

from worker.engine.presets import MODALITIES, SIZE, Preset, with_fusion
from worker.recognition.fusion import REPEATS, Adoption, FusionTuning, learn_fusion

from .index import GalleryIndex

MIN_CLASSES = 3
MIN_PER_CLASS = 3
#: After a fit, the next one waits at least this many times its duration: learning keeps
#: at most about a fifth of a core busy, however often the gallery changes.
IDLE_AFTER_FIT = 4.0

Source = Literal["preset", "pinned", "learned"]


@dataclass(frozen=True)
class GalleryFusion:
    """The weights and comparisons a gallery fuses with, where they came from, and why.

    Attributes
    ----------
    weights : modality -> weight, in use.
    comparisons : modality -> comparison, in use (:meth:`Preset.comparison`).
    source : ``preset``, ``pinned`` (``SHAPES_FUSION_WEIGHTS`` or the collection's pin)
        or ``learned``.
    reason : a sentence for the operator.
    tuning : the cross-validation (each fold's choice, the held-out scores of the choice
        and of the preset's weights), when one ran.
    adoption : its test against the preset's weights, when one ran.
    shapes, classes : labelled shapes and labels learned on.
    sampled : a sample of the labelled shapes was learned on (above ``max_shapes``).
    version : the gallery's change counter when fitted (-1: never fitted).
    fitted_at : Unix time of the fit.
    seconds : how long the cross-validation took (0: none ran).
    """

    weights: dict[str, float]
    comparisons: dict[str, str]
    source: Source
    reason: str
    tuning: FusionTuning | None = None
    adoption: Adoption | None = None
    shapes: int = 0
    classes: int = 0
    sampled: bool = False
    version: int = -1
    fitted_at: float = 0.0
    seconds: float = 0.0

    def applied(self, preset: Preset) -> Preset:
        """``preset`` fusing with these weights and comparisons."""
        return with_fusion(preset, self.weights, self.comparisons)


def _comparisons(preset: Preset) -> dict[str, str]:
    return {m: preset.comparison(m) for m in preset.scored_modalities}


def preset_fusion(preset: Preset, reason: str, version: int = -1) -> GalleryFusion:
    return GalleryFusion(
        weights={m: preset.weight(m) for m in preset.scored_modalities},
        comparisons=_comparisons(preset),
        source="preset",
        reason=reason,
        version=version,
        fitted_at=time.time(),
    )


def pinned_fusion(
    preset: Preset, weights: Mapping[str, float], where: str = "SHAPES_FUSION_WEIGHTS"
) -> GalleryFusion:
    """The operator's weights (set by ``where``) for the preset's scored modalities; one
    left out keeps the preset's weight, and one the preset does not score is unused.

    Raises
    ------
    ValueError
        Weights of unknown modalities, or not numbers >= 0.
    """
    unknown = set(weights) - {*MODALITIES, SIZE}
    if unknown:
        raise ValueError(f"{where} weighs unknown modalities {sorted(unknown)}")
    if any(not np.isfinite(w) or w < 0 for w in weights.values()):
        raise ValueError(f"{where} must be numbers >= 0, got {dict(weights)}")
    return GalleryFusion(
        weights={m: float(weights.get(m, preset.weight(m))) for m in preset.scored_modalities},
        comparisons=_comparisons(preset),
        source="pinned",
        reason=f"pinned by the operator ({where})",
        fitted_at=time.time(),
    )


def learn_gallery_fusion(
    index: GalleryIndex,
    labels: Mapping[int, str],
    preset: Preset,
    *,
    max_shapes: int,
    version: int,
    seed: int = 0,
) -> GalleryFusion:
    """Cross-validate the fusion's weights and comparisons on the labelled shapes of
    ``index`` (eq. 9's sigma the whole gallery's) and adopt them if the held-out folds
    favour them over the preset's; ``preset`` is the service's own (its weights and
    comparisons are the ones to beat)."""
    rng = np.random.default_rng(seed)
    described: list[int] = []  # how many labelled shapes there were to choose from

    def learnable(names: np.ndarray) -> np.ndarray:
        """The labels with enough shapes, a stratified sample above ``max_shapes``."""
        counts = Counter(names.tolist())
        kept = np.isin(names, [label for label, n in counts.items() if n >= MIN_PER_CLASS])
        described.append(int(kept.sum()))
        picked: np.ndarray = np.flatnonzero(kept)[_sample(names[kept], max_shapes, rng)]
        return picked

    names, vectors, sigma = index.labelled_vectors(labels, learnable)
    classes = len(set(names.tolist()))
    if classes < MIN_CLASSES:
        return preset_fusion(
            preset,
            f"the preset's weights: learning needs at least {MIN_CLASSES} labels with at least "
            f"{MIN_PER_CLASS} described shapes each ({classes} labels have)",
            version,
        )
    started = time.perf_counter()
    tuning = learn_fusion(vectors, names, preset, sigma, seed=seed, repeats=REPEATS)
    held, base = tuning.held_out, tuning.preset_held_out
    adoption = tuning.adoption()
    measured = (
        f"held-out EER {100 * held.eer:.2f}% and mAP {100 * held.map:.2f}% against the "
        f"preset's {100 * base.eer:.2f}% and {100 * base.map:.2f}% ({len(tuning.folds)} "
        f"folds in {tuning.repeats} rounds, {len(names)} labelled shapes; gain "
        f"{100 * adoption.gain:.2f} points of loss, t {adoption.statistic:.2f} against "
        f"{adoption.critical:.2f})"
    )
    if adoption.adopted:
        weights, comparisons = dict(tuning.weights), dict(tuning.comparisons)
        reason = f"learned: {measured}"
    else:
        weights = {m: preset.weight(m) for m in preset.scored_modalities}
        comparisons = _comparisons(preset)
        reason = (
            "the preset's weights: the learned ones were not better beyond the folds' "
            f"noise; {measured}"
        )
    return GalleryFusion(
        weights=weights,
        comparisons=comparisons,
        source="learned" if adoption.adopted else "preset",
        reason=reason,
        tuning=tuning,
        adoption=adoption,
        shapes=len(names),
        classes=classes,
        sampled=len(names) < described[0],
        version=version,
        fitted_at=time.time(),
        seconds=time.perf_counter() - started,
    )


def saved_fusion(fusion: GalleryFusion) -> dict[str, Any]:
    """What a restart needs of an adopted fusion (:func:`restored_fusion`): the choice and
    why, not the cross-validation's folds."""
    return {
        "weights": fusion.weights,
        "comparisons": fusion.comparisons,
        "reason": fusion.reason,
        "adoption": None if fusion.adoption is None else asdict(fusion.adoption),
        "shapes": fusion.shapes,
        "classes": fusion.classes,
        "sampled": fusion.sampled,
        "fitted_at": fusion.fitted_at,
        "seconds": fusion.seconds,
    }


def restored_fusion(saved: Mapping[str, Any], preset: Preset) -> GalleryFusion:
    """A learned fusion saved before a restart, for ``preset``: it ranks until the next
    fit, which starts at once (it has no folds to show).

    Raises
    ------
    ValueError
        Not a saved fusion of this preset's scored modalities.
    """
    try:
        weights = {m: float(w) for m, w in saved["weights"].items()}
        comparisons = {m: str(c) for m, c in saved["comparisons"].items()}
        adoption = saved["adoption"]
        fusion = GalleryFusion(
            weights=weights,
            comparisons=comparisons,
            source="learned",
            reason=f"learned before the service restarted, refitting now: {saved['reason']}",
            adoption=None if adoption is None else Adoption(**adoption),
            shapes=int(saved["shapes"]),
            classes=int(saved["classes"]),
            sampled=bool(saved["sampled"]),
            fitted_at=float(saved["fitted_at"]),
            seconds=float(saved["seconds"]),
        )
    except (KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"not a saved fusion: {exc}") from exc
    if set(weights) != set(preset.scored_modalities):
        raise ValueError(f"a fusion of {sorted(weights)}, not of {preset.scored_modalities}")
    fusion.applied(preset)  # raises ValueError for a comparison the preset cannot take
    return fusion


def _sample(names: np.ndarray, max_shapes: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of at most about ``max_shapes`` of ``names``, each label in proportion (at
    least ``MIN_PER_CLASS`` of each); all of them when there are no more."""
    if len(names) <= max_shapes:
        return np.arange(len(names))
    chosen = []
    for label in np.unique(names):
        members = np.flatnonzero(names == label)
        share = max(MIN_PER_CLASS, round(max_shapes * len(members) / len(names)))
        chosen.append(rng.choice(members, size=min(share, len(members)), replace=False))
    return np.sort(np.concatenate(chosen))
