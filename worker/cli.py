"""The engine's verbs of the ``shapes`` command: ``describe``, ``evaluate``,
``robustness``, ``partiality``, ``tune`` and ``samples`` (the engine and its evaluation
harness). :mod:`app.cli` adds the service's verbs and runs the command.

Each verb loads the engine or the harness when it runs, so that the command's help and
the service's verbs start at once."""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .engine.presets import DEFAULT_PRESET, PRESETS, UNITS, Preset, get_preset, with_units
from .evaluation.datasets import DEFAULT_CACHE, RESAMPLINGS, UP_AXES
from .recognition.fusion import FOLDS


def _describe(args: argparse.Namespace) -> int:
    from .engine.errors import MeshError
    from .engine.pipeline import describe_file

    preset = get_preset(args.preset)
    failures = 0
    for path in args.meshes:
        try:
            descriptor = describe_file(path, preset)
        except (MeshError, OSError) as exc:
            failures += 1
            print(f"{path}: {getattr(exc, 'message', exc)}", file=sys.stderr)
            continue
        if args.out:
            out_dir = Path(args.out)
            out_dir.mkdir(parents=True, exist_ok=True)
            stem = Path(path).name.split(".")[0]
            if args.format == "npz":
                (out_dir / f"{stem}.npz").write_bytes(descriptor.to_npz_bytes())
            else:
                (out_dir / f"{stem}.json").write_text(json.dumps(descriptor.to_json()))
        timings = " ".join(f"{k}={v:.3f}s" for k, v in descriptor.timings.items())
        summary = {"file": str(path), "vertices": descriptor.vertices, "timings": timings}
        if not args.out:
            summary["descriptor"] = descriptor.to_json()
        print(json.dumps(summary))
    return 1 if failures else 0


def _git_revision() -> str:
    """``git describe`` of the checkout this code runs from, for the report; '' if none."""
    try:
        result = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--abbrev=12"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        )
    except (OSError, subprocess.SubprocessError):
        return ""
    return result.stdout.strip()


def _evaluate(args: argparse.Namespace) -> int:
    # The harness (lapy, matplotlib, tqdm) is loaded only by the command that needs it.
    from .evaluation.datasets import EvaluationError
    from .evaluation.run import run_evaluation, weighted_preset
    from .evaluation.scoring import COLUMNS

    preset = get_preset(args.preset)
    dataset = Path(args.dataset_dir)
    labels = Path(args.labels) if args.labels else dataset / "labels.csv"
    out = Path(args.out) if args.out else Path("evaluation-out") / preset.name
    try:
        preset = with_units(preset, args.units)
        if args.weights:
            preset = weighted_preset(preset, args.weights)
        report = run_evaluation(
            dataset,
            labels,
            preset,
            out_dir=out,
            cache_root=Path(args.cache),
            jobs=args.jobs,
            per_class_limit=args.limit,
            command=shlex.join(["shapes", *args.argv]),
            environment={"git": _git_revision()},
            fusion=args.fusion,
            resampling=args.resampling,
        )
    except (EvaluationError, OSError, ValueError) as exc:
        print(f"shapes evaluate: {exc}", file=sys.stderr)
        return 2
    width = max(len(row["title"]) for row in report["rows"].values())
    print(f"{'':{width}}  " + " ".join(f"{h:>6}" for h in COLUMNS.values()))
    for row in report["rows"].values():
        cells = " ".join(f"{100 * row[k]:6.2f}" for k in COLUMNS)
        print(f"{row['title']:{width}}  {cells}")
    for name, why in report["failures"].items():
        print(f"left out {name}: {why}", file=sys.stderr)
    print(f"report written to {out}/report.md", file=sys.stderr)
    return 1 if report["failures"] else 0


def _run_protocol(
    args: argparse.Namespace,
    run: Callable[..., dict[str, Any]],
    name: str,
    units: str = "any",
    **options: Any,
) -> tuple[dict[str, Any] | None, Path]:
    """Run a variant protocol (``robustness``, ``partiality``) with the command's
    arguments and the protocol's own ``options``; the report (None after an error,
    printed) and its directory."""
    from .evaluation.datasets import EvaluationError

    preset = with_units(get_preset(args.preset), units)
    dataset = Path(args.dataset_dir)
    labels = Path(args.labels) if args.labels else dataset / "labels.csv"
    out = Path(args.out) if args.out else Path("evaluation-out") / name / preset.name
    variants = args.variants.split(",") if args.variants else None
    try:
        report = run(
            dataset,
            labels,
            preset,
            out_dir=out,
            cache_root=Path(args.cache),
            jobs=args.jobs,
            per_class_limit=args.limit,
            poses_dir=args.poses,
            command=shlex.join(["shapes", *args.argv]),
            environment={"git": _git_revision()},
            **({"variants": variants} if variants else {}),
            **options,
        )
    except (EvaluationError, OSError, RuntimeError) as exc:
        print(f"shapes {name}: {exc}", file=sys.stderr)
        return None, out
    return report, out


def _robustness(args: argparse.Namespace) -> int:
    from .evaluation.run import run_robustness

    report, out = _run_protocol(args, run_robustness, "robustness")
    if report is None:
        return 2
    titles = report["rows"]
    width = max(len(t) for t in titles.values())
    print(f"{'':{width}}   class    self    gap")
    for key, title in titles.items():
        row = report["tessellation"][key]
        print(
            f"{title:{width}}  {100 * row['class_retrieval']:5.1f}%  "
            f"{100 * row['self_retrieval']:5.1f}%  {row['gap']:.3f}"
        )
    if "poses" in report:
        print(f"\nposes of {report['poses']['dataset']}: ratio, foreign nearest neighbours")
        for key, title in titles.items():
            if key not in report["poses"]["scores"]:  # the parts: whole queries only
                continue
            row = report["poses"]["scores"][key]
            print(f"{title:{width}}  {row['ratio']:.3f}  {row['foreign_nearest']}/{row['poses']}")
        first, second = report["poses"]["resolutions"]
        print(f"\nposes at {first} against {second} and back: rank 1, ratio")
        for key, title in titles.items():
            if key not in report["poses"]["cross_resolution"]:
                continue
            row = report["poses"]["cross_resolution"][key]
            print(f"{title:{width}}  {100 * row['rank1']:5.1f}%  {row['ratio']:.3f}")
    for name, why in report["failures"].items():
        print(f"could not describe {name}: {why}", file=sys.stderr)
    print(f"report written to {out}/robustness.md", file=sys.stderr)
    return 1 if report["failures"] else 0


def _partiality(args: argparse.Namespace) -> int:
    from .evaluation.run import run_partiality

    report, out = _run_protocol(
        args,
        run_partiality,
        "partiality",
        args.units,
        copies=args.copies,
        up=args.up,
        poses_up=args.poses_up,
    )
    if report is None:
        return 2
    titles = report["rows"]
    names = list(report["variants"])
    width = max(len(t) for t in titles.values())
    print(f"{'':{width}}  " + "  ".join(f"{n:>17}" for n in names))
    print(f"{'':{width}}  " + "  ".join(f"{'class/source/mAP':>17}" for _ in names))
    for key, title in titles.items():
        cells = (report["scores"][key][n] for n in names)
        print(
            f"{title:{width}}  "
            + "  ".join(
                f"{100 * c['own_class']:5.1f}/{100 * c['own_source']:5.1f}/{100 * c['map']:5.1f}"
                for c in cells
            )
        )
    for name, why in report["failures"].items():
        print(f"could not describe {name}: {why}", file=sys.stderr)
    print(f"report written to {out}/partiality.md", file=sys.stderr)
    return 1 if report["failures"] else 0


def _tune(args: argparse.Namespace) -> int:
    from .evaluation.datasets import EvaluationError
    from .evaluation.run import run_tuning

    preset = get_preset(args.preset)
    dataset = Path(args.dataset_dir)
    labels = Path(args.labels) if args.labels else dataset / "labels.csv"
    out = Path(args.out) if args.out else Path("evaluation-out") / preset.name / "weights.json"
    try:
        preset = with_units(preset, args.units)
        tuned = run_tuning(
            dataset,
            labels,
            preset,
            out_path=out,
            cache_root=Path(args.cache),
            folds=args.folds,
            jobs=args.jobs,
            per_class_limit=args.limit,
        )
    except (EvaluationError, OSError, ValueError) as exc:
        print(f"shapes tune: {exc}", file=sys.stderr)
        return 2
    _print_tuning(tuned, preset, args.folds)
    for name, why in tuned["failures"].items():
        print(f"left out {name}: {why}", file=sys.stderr)
    print(f"weights written to {out}", file=sys.stderr)
    return 1 if tuned["failures"] else 0


def _print_tuning(tuned: dict[str, Any], preset: Preset, folds: int) -> None:
    """The folds of ``shapes tune`` as a table, the weights chosen on all meshes, and
    the loss with each weight moved over the grid (how sharply the collection decides)."""
    names = list(tuned["weights"])
    grid = tuned["grid"]

    def figures(scores: dict[str, float]) -> str:
        return f"{scores['eer']:.2%} | {scores['nn']:.1%} | {scores['map']:.1%}"

    fixed = [m for m in names if m not in tuned["chosen"]]
    others = ", ".join(f"{m} {tuned['weights'][m]:g}" for m in fixed)
    kept = f"the others the preset's ({others})" if preset.units == "metric" else f"{names[-1]} 1"
    print(
        f"preset {preset.name} v{preset.version}, {preset.fusion} rule, units "
        f"{preset.units}, {tuned['meshes']} meshes, {folds} class-stratified folds; weights "
        f"of {', '.join(tuned['chosen'])} from ({', '.join(f'{w:g}' for w in grid)}), {kept}\n"
    )
    print(f"| fold | held-out meshes | weights ({', '.join(names)}) | EER | NN | mAP |")
    print("|---|---:|---|---:|---:|---:|")
    for f, fold in enumerate(tuned["folds"]):
        shown = ", ".join(f"{fold['weights'][m]:g}" for m in names)
        scores = figures(fold["held_out"]["tuned"])
        print(f"| {f} | {fold['held_out_objects']} | {shown} | {scores} |")
    held_out = tuned["held_out"]
    own = ", ".join(f"{held_out['preset']['weights'][m]:g}" for m in names)
    print(f"| mean over the folds | | each fold's | {figures(held_out['tuned'])} |")
    print(f"| mean over the folds, the preset's | | {own} | {figures(held_out['preset'])} |")
    chosen = ", ".join(f"{m} {w:g}" for m, w in tuned["weights"].items())
    print(f"\nchosen on all meshes: {chosen} (loss {tuned['loss']:.5f})\n")
    points = " | ".join(f"{w:g}" for w in grid)
    print(f"| loss on all meshes, the others as chosen | {points} |")
    print("|---|" + "---:|" * len(grid))
    for m, losses in tuned["sensitivity"].items():
        print(f"| {m} weight | " + " | ".join(f"{x:.5f}" for x in losses) + " |")


def _samples(args: argparse.Namespace) -> int:
    from .evaluation.samples import write_samples

    try:
        written = write_samples(args.out_dir)
    except (OSError, RuntimeError) as exc:
        print(f"shapes samples: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(written) - 1} meshes and {written[-1]}")
    return 0


def _add_collection_arguments(parser: argparse.ArgumentParser) -> None:
    """What ``evaluate``, ``robustness`` and ``tune`` take: a labelled collection, the preset,
    the worker processes, the descriptor cache and a per-class limit."""
    parser.add_argument("dataset_dir", help="directory holding the mesh files")
    parser.add_argument(
        "--labels", help="CSV with columns file,class (default: DATASET_DIR/labels.csv)"
    )
    parser.add_argument("--preset", default=DEFAULT_PRESET, choices=sorted(PRESETS))
    parser.add_argument(
        "--jobs",
        type=int,
        default=os.cpu_count() or 1,
        help="worker processes, one BLAS thread each (default: CPUs)",
    )
    parser.add_argument(
        "--cache",
        default=str(DEFAULT_CACHE),
        help=f"descriptor and variant mesh cache (default: {DEFAULT_CACHE})",
    )
    parser.add_argument(
        "--limit",
        type=int,
        help="use only the first N meshes (natural file-name order) of each class, N >= 2",
    )


def _add_units_argument(parser: argparse.ArgumentParser) -> None:
    """What ``evaluate``, ``tune`` and ``partiality`` take: the collection's units (with
    ``--poses``, the poses' files in the collection's unit)."""
    parser.add_argument(
        "--units",
        choices=UNITS,
        default="any",
        help="the files' units: any (arbitrary; every score scale-free, the default) or "
        "metric (calibrated: the size of each surface is compared and fused too, at the "
        "preset's size weight, and a part compared with each whole at the scale their "
        "sizes imply)",
    )


def add_subcommands(sub: Any) -> None:
    """Register the engine's verbs on the ``shapes`` parser's subparsers."""
    describe = sub.add_parser("describe", help="compute GDM/DDT modal descriptors of meshes")
    describe.add_argument(
        "meshes", nargs="+", help="mesh files (.obj .ply .off .stl .glb .gltf, optionally .gz)"
    )
    describe.add_argument("--preset", default=DEFAULT_PRESET, choices=sorted(PRESETS))
    describe.add_argument("--out", help="directory to save descriptors in (default: print JSON)")
    describe.add_argument("--format", choices=("json", "npz"), default="json")
    describe.set_defaults(run=_describe)

    evaluate = sub.add_parser(
        "evaluate",
        help="score the descriptors on a labelled collection (the paper's sec. 4 protocol)",
        description="Describe every mesh of labels.csv, compare all to all per modality and "
        "fused, next to lapy's ShapeDNA, and write report.json, report.md, cmc.png, roc.png.",
    )
    _add_collection_arguments(evaluate)
    evaluate.add_argument("--out", help="report directory (default: evaluation-out/PRESET)")
    evaluate.add_argument(
        "--weights", help="fuse with the weights of this file of shapes tune (for the same preset)"
    )
    evaluate.add_argument(
        "--fusion",
        choices=("preset", "learned"),
        default="preset",
        help="learned: add a row with the fusion (weights and comparisons) learned on this "
        "collection by 5-fold class-stratified cross-validation, every figure held out",
    )
    _add_units_argument(evaluate)
    evaluate.add_argument(
        "--resampling",
        choices=RESAMPLINGS,
        default="mesh",
        help="mesh: every file resampled on its own (the default, as the service does); "
        "figure: each class's first file resampled once and that resampling carried to the "
        "class's other files through their shared vertex ids (poses of one figure numbered "
        "alike, as TOSCA's; a file with another vertex count is resampled on its own)",
    )
    evaluate.set_defaults(run=_evaluate)

    robustness = sub.add_parser(
        "robustness",
        help="how much the descriptors move with a file's tessellation (and with pose)",
        description="Describe every mesh of labels.csv and variants of it that keep the "
        "shape but change the triangles (decimated, remeshed, subdivided, rotated and "
        "rescaled, noisy); report per modality, for the preset's score and for ShapeDNA "
        "the class and self retrieval of the variants and the tessellation gap, and with "
        "--poses the pose invariance of a set of poses of one object. Writes "
        "robustness.json and robustness.md.",
    )
    _add_collection_arguments(robustness)
    robustness.add_argument(
        "--poses", help="directory of poses of one object (e.g. SCAPE) to measure pose invariance"
    )
    robustness.add_argument(
        "--variants", help="comma-separated subset of the variants (default: all seven)"
    )
    robustness.add_argument(
        "--out", help="report directory (default: evaluation-out/robustness/PRESET)"
    )
    robustness.set_defaults(run=_robustness)

    partial = sub.add_parser(
        "partiality",
        help="whether partial and scanned copies of the meshes find their whole",
        description="Describe every mesh of labels.csv and partial copies of it (a planar cut "
        "of 5, 15 and 30% of the vertices, geodesic holes of 10 and 25% of the area, a "
        "single-view scan, SHREC'17's range scans (also read as a depth camera's organized "
        "cloud) and holes, Gaussian noise of 0.25, 0.5 "
        "and 1% of the diagonal, the single-view scan with depth noise of 0.25 and 0.5%), "
        "and query the whole meshes with each copy; report per "
        "modality, for the parts modality, the preset's score and ShapeDNA the own class and "
        "own source at rank 1 and the mAP, and all to all among each variant's copies the "
        "NN, tiers, DCG and mAP. With --poses the poses join the gallery as one more class. "
        "Writes partiality.json and partiality.md.",
    )
    _add_collection_arguments(partial)
    partial.add_argument(
        "--poses", help="directory of poses of one object (e.g. SCAPE) to add as one more class"
    )
    partial.add_argument(
        "--variants",
        help="comma-separated subset of the partial copies: cut-5, cut-15, cut-30, holes-10, "
        "holes-25, view, range, range-cloud, view-points, view-voxels, range-floor, floor-voxels, "
        "points, shrec-holes, "
        "noise-0.25, noise-0.5, noise-1, view-noise-0.25, view-noise-0.5, points-noise-0.25, "
        "points-noise-0.5 (default: all)",
    )
    partial.add_argument(
        "--copies",
        type=int,
        default=1,
        help="copies of each variant drawn from every mesh, each with a seed of its own "
        "(SHREC'17 shot every model 20 times; default: 1)",
    )
    partial.add_argument(
        "--up",
        choices=UP_AXES,
        default="z",
        help="the axis the collection's files stand on: the range scans' camera orbits it "
        "within 25 degrees of the horizon, as SHREC'17's did (default: z, TOSCA's)",
    )
    partial.add_argument(
        "--poses-up",
        choices=UP_AXES,
        help="the axis the poses stand on (default: --up; SCAPE's stand on x)",
    )
    partial.add_argument(
        "--out", help="report directory (default: evaluation-out/partiality/PRESET)"
    )
    _add_units_argument(partial)
    partial.set_defaults(run=_partiality)

    tune = sub.add_parser(
        "tune",
        help="choose the preset's fusion weights on a labelled collection",
        description="Describe every mesh of labels.csv and choose one fusion weight per "
        "fused modality under the preset's rule (the last keeps 1) by class-stratified "
        "cross-validation: on the meshes of the other folds, the weights of a grid with "
        "the lowest mean of EER and 1 - mAP; measured on the held-out fold's pairs (EER) "
        "and with its meshes as queries (NN, mAP), beside the preset's own weights. Prints "
        "the folds and the weights chosen on all meshes, and writes them as JSON that "
        "shapes evaluate --weights takes.",
    )
    _add_collection_arguments(tune)
    tune.add_argument(
        "--folds", type=int, default=FOLDS, help=f"cross-validation folds (default: {FOLDS})"
    )
    tune.add_argument(
        "--out", help="weights file to write (default: evaluation-out/PRESET/weights.json)"
    )
    _add_units_argument(tune)
    tune.set_defaults(run=_tune)

    samples = sub.add_parser(
        "samples",
        help="write the project's sample meshes (the examples/ folder) into a directory",
        description="Generate the sample collection: five articulated figures (biped, "
        "quadruped, spider, bird, hand) in four poses each, as <class>-<pose>.off.gz, and "
        "labels.csv. Deterministic: it rewrites the repository's examples/ folder. Needs "
        "the eval extra (MeshLab's decimation).",
    )
    samples.add_argument("out_dir", help="directory to write the meshes and labels.csv in")
    samples.set_defaults(run=_samples)
