"""``shapes evaluate``, ``shapes robustness``, ``shapes partiality`` and ``shapes tune``:
describe, compare and score a labelled collection (and variants of its meshes), write the
reports, choose the fusion weights."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from worker.engine.presets import MODALITIES, SIZE, Preset
from worker.recognition import metrics
from worker.recognition.fusion import FOLDS, REPEATS, learn_fusion, tune_fusion

from .compute import ComputedSet, compute_descriptors, descriptor_vectors
from .datasets import RESAMPLINGS, UP_AXES, EvaluationError, LabeledMesh, pose_set, read_labels
from .figures import compute_by_figure
from .learned import LEARNED, learned_row
from .partial import PARTIAL_VARIANTS
from .partiality import partial_row_titles, partiality_scores, parts_matrix
from .report import (
    build_report,
    environment_info,
    render_markdown,
    render_partiality_markdown,
    render_robustness_markdown,
)
from .robustness import (
    GAP_BAR,
    POSE_RESOLUTIONS,
    cross_resolution,
    pose_invariance,
    row_titles,
    tessellation_scores,
)
from .scoring import modality_dissimilarity
from .shapedna import BASELINE
from .size import size_tuning
from .variants import VARIANTS, copy_name, standing_name


def run_evaluation(
    dataset_dir: str | Path,
    labels_csv: str | Path,
    preset: Preset,
    *,
    out_dir: str | Path,
    cache_root: str | Path,
    jobs: int = 1,
    per_class_limit: int | None = None,
    command: str = "",
    environment: Mapping[str, str] | None = None,
    progress: bool = True,
    plot: Callable[[Mapping[str, Any], Path], None] | None = None,
    fusion: str = "preset",
    resampling: str = "mesh",
) -> dict[str, Any]:
    """Describe, compare and score a labelled collection; write the report to ``out_dir``.

    Writes ``report.json``, ``report.md``, ``cmc.png`` and ``roc.png``. With ``fusion``
    ``"learned"`` the report also has the fusion learned on the collection, from
    held-out folds (:mod:`.learned`): a ``learned`` row before ShapeDNA's and a
    ``learned_fusion`` section. With the preset's units "metric" the size is compared
    and fused too (:func:`.scoring.report_rows`). With ``resampling`` "figure" every
    class is resampled once and its poses share that resampling by vertex id
    (:mod:`.figures`; the report's ``resampling`` section says how).

    Returns
    -------
    The report dict (as in report.json).
    """
    if resampling not in RESAMPLINGS:
        raise EvaluationError(f"unknown resampling {resampling!r}; use {', '.join(RESAMPLINGS)}")
    meshes = read_labels(labels_csv, dataset_dir, per_class_limit)
    about_resampling = None
    if resampling == "figure":
        computed, about_resampling = compute_by_figure(
            meshes, preset, cache_root, jobs=jobs, progress=progress
        )
    else:
        computed = compute_descriptors(meshes, preset, cache_root, jobs=jobs, progress=progress)
    if len({m.label for m in computed.meshes}) < 2:
        raise EvaluationError(
            f"fewer than two classes left after {len(computed.failures)} meshes failed"
        )
    env = {**environment_info(), **(environment or {})}
    report, _ = build_report(
        computed, preset, command=command, environment=env, dataset=str(dataset_dir), jobs=jobs
    )
    if about_resampling is not None:
        report["resampling"] = {"per": "figure", **about_resampling}
    if fusion == LEARNED:
        _add_learned(report, computed, preset)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if plot is None:
        from .plots import plot_report  # matplotlib, only when plots are made

        plot = plot_report
    start = time.perf_counter()
    plot(report, out)
    report["timings"]["plot_seconds"] = time.perf_counter() - start
    (out / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "report.md").write_text(render_markdown(report))
    return report


def _add_learned(report: dict[str, Any], computed: ComputedSet, preset: Preset) -> None:
    names = [m.name for m in computed.meshes]
    labels = [m.label for m in computed.meshes]
    vectors = descriptor_vectors(computed, size=preset.units == "metric")
    try:
        tuning = learn_fusion(vectors, np.asarray(labels), preset)
        # A gallery decides on REPEATS rounds of the folds (the row: the first round's).
        decision = learn_fusion(vectors, np.asarray(labels), preset, repeats=REPEATS).adoption()
    except ValueError as exc:
        raise EvaluationError(f"cannot learn the fusion on this collection: {exc}") from exc
    gallery_idx, probe_idx = metrics.first_instance_split(names, labels)
    row, section = learned_row(tuning, decision, preset, labels, names, gallery_idx, probe_idx)
    rows = report["rows"]
    baseline = rows.pop(BASELINE)
    rows[LEARNED] = row
    rows[BASELINE] = baseline
    report["learned_fusion"] = section


def run_tuning(
    dataset_dir: str | Path,
    labels_csv: str | Path,
    preset: Preset,
    *,
    out_path: str | Path,
    cache_root: str | Path,
    folds: int = FOLDS,
    jobs: int = 1,
    per_class_limit: int | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Choose the preset's fusion weights on a labelled collection; write them as JSON.

    The collection is described through the cache, each fused modality compared all to
    all with the preset's dissimilarity, and the weights chosen by class-stratified
    cross-validation under the preset's rule (:func:`worker.recognition.fusion.tune_fusion`;
    the preset's own weights are scored on the same folds). With the preset's units
    "metric" only the size's weight is chosen, against the preset's score of the shape at
    its own weights (:func:`.size.size_tuning`); the document has every weight.

    Returns
    -------
    The document written to ``out_path``, which ``shapes evaluate --weights`` takes
    (:func:`weighted_preset`): ``preset``, ``preset_version``, ``fusion`` (the rule),
    ``weights`` (modality -> weight, chosen on every mesh), ``grid``, ``loss`` (of the
    weights on every mesh), ``sensitivity`` (modality -> the loss on every mesh at each
    grid point), ``folds`` (each fold's held-out meshes, choice and held-out scores),
    ``held_out`` (the mean over the folds: ``tuned`` and ``preset``, each ``eer``,
    ``nn``, ``map``), ``dataset``, ``meshes`` and ``failures`` (meshes left out, and
    why); ``units``, and ``chosen``, the modalities whose weights were chosen (the others
    are the preset's).

    Raises
    ------
    EvaluationError
        When the preset fuses a single modality, or the collection cannot fill the
        folds (:func:`~worker.recognition.fusion.tune_fusion`'s conditions).
    """
    metric = preset.units == "metric"
    if len(preset.fused_modalities) < 2 and not metric:
        raise EvaluationError(
            f"{preset.name} fuses {list(preset.fused_modalities)} only: no weights to choose"
        )
    meshes = read_labels(labels_csv, dataset_dir, per_class_limit)
    computed = compute_descriptors(meshes, preset, cache_root, jobs=jobs, progress=progress)
    vectors = descriptor_vectors(computed, size=metric)
    labels = np.array([m.label for m in computed.meshes])
    shape_weights = {m: preset.weight(m) for m in preset.fused_modalities}
    try:
        if metric:
            tuning = size_tuning(vectors, labels, preset, folds=folds)
        else:
            dissimilarities = {
                m: modality_dissimilarity(vectors[m], preset.dissimilarity)[0]
                for m in preset.fused_modalities
            }
            tuning = tune_fusion(dissimilarities, labels, preset.fusion, shape_weights, folds=folds)
    except ValueError as exc:
        raise EvaluationError(str(exc)) from exc

    def every(weights: Mapping[str, float]) -> dict[str, float]:
        """All the preset's weights: the shape's as the preset has them with the size's."""
        return {**shape_weights, SIZE: weights[SIZE]} if metric else dict(weights)

    chosen = [SIZE] if metric else list(preset.fused_modalities[:-1])
    own = every({SIZE: preset.fusion_weights.get(SIZE, 0.0)}) if metric else shape_weights
    document = {
        "preset": preset.name,
        "preset_version": preset.version,
        "fusion": preset.fusion,
        "units": preset.units,
        "chosen": chosen,
        "weights": every(tuning.weights),
        "grid": list(tuning.grid),
        "loss": tuning.loss,
        "sensitivity": {m: list(losses) for m, losses in tuning.sensitivity.items()},
        "folds": [
            {
                "held_out_objects": fold.held_out_objects,
                "weights": every(fold.weights),
                "held_out": {"tuned": asdict(fold.held_out), "preset": asdict(fold.preset)},
            }
            for fold in tuning.folds
        ],
        "held_out": {
            "tuned": asdict(tuning.held_out),
            "preset": {"weights": own, **asdict(tuning.preset_held_out)},
        },
        "dataset": str(dataset_dir),
        "meshes": len(computed.meshes),
        "failures": computed.failures,
    }
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(document, indent=1) + "\n")
    return document


def weighted_preset(preset: Preset, weights_json: str | Path) -> Preset:
    """``preset`` fusing with the weights of a ``shapes tune`` file (:func:`run_tuning`):
    the fused modalities' weights, and the size's if the file has one (a metric tuning);
    otherwise the preset's size weight stays.

    Raises
    ------
    EvaluationError
        When the file cannot be read or holds no weights, was tuned for another preset,
        preset version or fusion rule, or weighs other modalities than the preset fuses
        (and the size), or a weight is not a finite number >= 0.
    """
    path = Path(weights_json)
    try:
        document = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise EvaluationError(f"cannot read fusion weights from {path}: {exc}") from exc
    if not isinstance(document, dict) or not isinstance(document.get("weights"), dict):
        raise EvaluationError(f"{path} holds no 'weights' object (as shapes tune writes)")
    tuned_for = (document.get("preset"), document.get("preset_version"), document.get("fusion"))
    if tuned_for != (preset.name, preset.version, preset.fusion):
        raise EvaluationError(
            f"{path} holds weights for {tuned_for[0]} v{tuned_for[1]} ({tuned_for[2]} rule), "
            f"not for {preset.name} v{preset.version} ({preset.fusion} rule)"
        )
    weights: dict[str, Any] = document["weights"]
    unknown = sorted(set(weights) - {*MODALITIES, SIZE})
    if unknown:
        raise EvaluationError(
            f"{path} weighs unknown modalities {unknown}; known: {', '.join(MODALITIES)}, {SIZE}"
        )
    if set(weights) - {SIZE} != set(preset.fused_modalities):
        raise EvaluationError(
            f"{path} weighs {sorted(weights)}; {preset.name} fuses "
            f"{sorted(preset.fused_modalities)}"
        )
    bad = {
        m: w
        for m, w in weights.items()
        if isinstance(w, bool) or not isinstance(w, int | float) or not math.isfinite(w) or w < 0
    }
    if bad:
        raise EvaluationError(f"{path} has weights that are not numbers >= 0: {bad}")
    kept = {SIZE: preset.fusion_weights[SIZE]} if SIZE in preset.fusion_weights else {}
    return replace(preset, fusion_weights={**kept, **{m: float(w) for m, w in weights.items()}})


def run_robustness(
    dataset_dir: str | Path,
    labels_csv: str | Path,
    preset: Preset,
    *,
    out_dir: str | Path,
    cache_root: str | Path,
    variants: Sequence[str] = tuple(VARIANTS),
    poses_dir: str | Path | None = None,
    jobs: int = 1,
    per_class_limit: int | None = None,
    command: str = "",
    environment: Mapping[str, str] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """The tessellation-robustness protocol (:mod:`.robustness`); writes
    ``robustness.json`` and ``robustness.md`` to ``out_dir``.

    Every mesh of the collection and each of its ``variants`` is described (through
    the cache); with ``poses_dir`` (a directory of poses of one object, e.g. SCAPE)
    the pose invariance is measured against the collection too.

    Returns
    -------
    The report dict (as in robustness.json).
    """
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        raise EvaluationError(f"unknown variants {unknown}; known: {', '.join(VARIANTS)}")
    meshes = read_labels(labels_csv, dataset_dir, per_class_limit)
    start = time.perf_counter()
    computed = compute_descriptors(meshes, preset, cache_root, jobs=jobs, progress=progress)
    originals = descriptor_vectors(computed)
    failures = {name: {"original": why} for name, why in computed.failures.items()}
    described: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
    parts: dict[str, np.ndarray] = {}  # the parts modality's, per variant
    # Vertices of the meshes as described, summed: two runs whose sums agree described
    # the same variant meshes (MeshLab's remesher once gave others under load).
    vertices = {"original": sum(d.input_vertices for d in computed.descriptors)}
    for variant, sources, done in _variants_of(
        computed, variants, preset, cache_root, jobs, progress, failures
    ):
        vertices[variant] = sum(d.input_vertices for d in done.descriptors)
        described[variant] = (sources, descriptor_vectors(done))
        if preset.has_parts:
            parts[variant] = parts_matrix(done.descriptors, computed.descriptors, preset, jobs)
    labels = [m.label for m in computed.meshes]
    among = None
    if preset.has_parts:
        among = parts_matrix(
            computed.descriptors, computed.descriptors, preset, jobs, themselves=True
        )
    report: dict[str, Any] = {
        "dataset": str(dataset_dir),
        "command": command,
        "preset": preset.to_dict(),
        "rows": row_titles(preset),
        "gap_bar": GAP_BAR,
        "variants": list(variants),
        "tessellation": tessellation_scores(
            originals, labels, described, preset, None if among is None else (among, parts)
        ),
        "input_vertices": vertices,
        "failures": failures,
        "environment": {**environment_info(), **(environment or {})},
    }
    if poses_dir is not None:
        poses = pose_set(poses_dir)
        posed = compute_descriptors(poses, preset, cache_root, jobs=jobs, progress=progress)
        for name, why in posed.failures.items():
            failures[name] = {"original": why}
        report["poses"] = {
            "dataset": str(poses_dir),
            "scores": pose_invariance(
                descriptor_vectors(posed),
                originals,
                labels,
                preset,
                [m.name for m in posed.meshes],
                [m.name for m in computed.meshes],
            ),
            "resolutions": list(POSE_RESOLUTIONS),
            "cross_resolution": cross_resolution(
                *_both_resolutions(posed.meshes, preset, cache_root, jobs, progress, failures),
                preset,
            ),
        }
    report["seconds"] = time.perf_counter() - start
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "robustness.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "robustness.md").write_text(render_robustness_markdown(report))
    return report


def run_partiality(
    dataset_dir: str | Path,
    labels_csv: str | Path,
    preset: Preset,
    *,
    out_dir: str | Path,
    cache_root: str | Path,
    variants: Sequence[str] = tuple(PARTIAL_VARIANTS),
    poses_dir: str | Path | None = None,
    jobs: int = 1,
    per_class_limit: int | None = None,
    copies: int = 1,
    up: str = "z",
    poses_up: str | None = None,
    command: str = "",
    environment: Mapping[str, str] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """The partiality protocol (:mod:`.partiality`); writes ``partiality.json`` and
    ``partiality.md`` to ``out_dir``.

    Every mesh of the collection and its partial copies (:mod:`.partial`) are described
    (through the cache); the copies query the whole meshes. With ``poses_dir`` (poses
    of one object, e.g. SCAPE) the poses join the gallery as one more class, and their
    copies are queries too. ``copies``: each variant drawn that many times from every
    mesh (:func:`.variants.copy_name`; SHREC'17 shot every model 20 times), all of them
    queries, all to all among them. ``up``: the coordinate axis the collection's files
    stand on, which the range camera orbits (:data:`.partial.ORBITING`); ``poses_up``
    the poses' (default ``up``).

    Returns
    -------
    The report dict (as in partiality.json).
    """
    if not preset.has_parts:
        raise EvaluationError(f"preset {preset.name} has no parts modality")
    unknown = sorted(set(variants) - set(PARTIAL_VARIANTS))
    if unknown:
        raise EvaluationError(
            f"unknown partial variants {unknown}; known: {', '.join(PARTIAL_VARIANTS)}"
        )
    if copies < 1:
        raise EvaluationError(f"copies must be at least 1, not {copies}")
    poses_up = up if poses_up is None else poses_up
    for axis in (up, poses_up):
        if axis not in UP_AXES:
            raise EvaluationError(f"an up axis is one of {', '.join(UP_AXES)}, not {axis!r}")
    meshes = read_labels(labels_csv, dataset_dir, per_class_limit)
    standing = {m.name: up for m in meshes}
    if poses_dir is not None:
        poses = pose_set(poses_dir)
        standing |= {m.name: poses_up for m in poses}
        meshes = [*meshes, *poses]
    start = time.perf_counter()
    computed = compute_descriptors(meshes, preset, cache_root, jobs=jobs, progress=progress)
    failures = {name: {"original": why} for name, why in computed.failures.items()}
    described = {}
    shapedna = {}
    for variant, sources, done in _variants_of(
        computed, variants, preset, cache_root, jobs, progress, failures, copies, standing
    ):
        described[variant] = (sources, done.descriptors)
        shapedna[variant] = np.stack([b.descriptor for b in done.baselines])
    wholes = np.stack([b.descriptor for b in computed.baselines])
    scores = partiality_scores(
        computed.descriptors,
        [m.label for m in computed.meshes],
        described,
        preset,
        baselines=(wholes, shapedna),
        jobs=jobs,
    )
    report: dict[str, Any] = {
        "dataset": str(dataset_dir),
        "poses": None if poses_dir is None else str(poses_dir),
        "command": command,
        "preset": preset.to_dict(),
        "rows": partial_row_titles(preset),
        "wholes": len(computed.meshes),
        "copies": copies,
        "up": {"dataset": up, "poses": None if poses_dir is None else poses_up},
        **scores,
        "failures": failures,
        "environment": {**environment_info(), **(environment or {})},
        "seconds": time.perf_counter() - start,
    }
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "partiality.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "partiality.md").write_text(render_partiality_markdown(report))
    return report


def described_copies(
    meshes: Sequence[LabeledMesh],
    variant: str,
    preset: Preset,
    cache_root: str | Path,
    jobs: int = 1,
    progress: bool = False,
    standing: Mapping[str, str] | None = None,
) -> ComputedSet:
    """``variant``'s copies of ``meshes`` through the cache, each mesh's drawn around the
    axis it stands on (``standing``: mesh name -> axis, z for a mesh not in it;
    :func:`.variants.standing_name`), grouped by that axis; the copies that could not be
    described in its ``failures`` by their mesh's name."""
    axes = {m.name: (standing or {}).get(m.name, "z") for m in meshes}
    drawn = [
        compute_descriptors(
            [m for m in meshes if axes[m.name] == up],
            preset,
            cache_root,
            jobs=jobs,
            progress=progress,
            variant=standing_name(variant, up),
        )
        for up in sorted(set(axes.values()))
    ]
    return ComputedSet(
        meshes=[m for done in drawn for m in done.meshes],
        descriptors=[d for done in drawn for d in done.descriptors],
        baselines=[b for done in drawn for b in done.baselines],
        failures={m: why for done in drawn for m, why in done.failures.items()},
    )


def _variants_of(
    computed: ComputedSet,
    variants: Sequence[str],
    preset: Preset,
    cache_root: str | Path,
    jobs: int,
    progress: bool,
    failures: dict[str, dict[str, str]],
    copies: int = 1,
    standing: Mapping[str, str] | None = None,
) -> Iterator[tuple[str, np.ndarray, ComputedSet]]:
    """Each variant of the described meshes, through the cache: its name, the index of
    each copy's source in ``computed.meshes``, and the copies, ``copies`` of every mesh
    (:func:`.variants.copy_name`; the ones that could not be described recorded in
    ``failures`` under their copy's name), each drawn around the axis its mesh stands on
    (:func:`described_copies`)."""
    index = {m.name: i for i, m in enumerate(computed.meshes)}
    for variant in variants:
        drawn = []
        for copy in range(copies):
            name = copy_name(variant, copy)
            done = described_copies(
                computed.meshes, name, preset, cache_root, jobs, progress, standing
            )
            for mesh, why in done.failures.items():
                up = (standing or {}).get(mesh, "z")
                failures.setdefault(mesh, {})[standing_name(name, up)] = why
            drawn.append(done)
        all_of = ComputedSet(
            meshes=[m for done in drawn for m in done.meshes],
            descriptors=[d for done in drawn for d in done.descriptors],
            baselines=[b for done in drawn for b in done.baselines],
        )
        yield variant, np.array([index[m.name] for m in all_of.meshes], dtype=np.int64), all_of


def _both_resolutions(
    poses: Sequence[LabeledMesh],
    preset: Preset,
    cache_root: str | Path,
    jobs: int,
    progress: bool,
    failures: dict[str, dict[str, str]],
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The poses' descriptor vectors at the two ``POSE_RESOLUTIONS``, row ``i`` of
    both the same pose (poses that failed at either are left out of both, and
    recorded in ``failures``)."""
    done = []
    for variant in POSE_RESOLUTIONS:
        computed = compute_descriptors(
            poses, preset, cache_root, jobs=jobs, progress=progress, variant=variant
        )
        for name, why in computed.failures.items():
            failures.setdefault(name, {})[variant] = why
        done.append(computed)
    common = set.intersection(*({m.name for m in c.meshes} for c in done))
    vectors = []
    for computed in done:
        rows = [i for i, m in enumerate(computed.meshes) if m.name in common]
        vectors.append({k: v[rows] for k, v in descriptor_vectors(computed).items()})
    return vectors[0], vectors[1]
