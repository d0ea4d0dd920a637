"""``shapes evaluate``: describe, compare and score a labelled collection, write the report."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from pathlib import Path

from worker.engine.presets import Preset

from .compute import compute_descriptors
from .datasets import EvaluationError, read_labels
from .report import build_report, environment_info, render_markdown


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
    plot: Callable[[Mapping, Path], None] | None = None,
) -> dict:
    """Describe, compare and score a labelled collection; write the report to ``out_dir``.

    Writes ``report.json``, ``report.md``, ``cmc.png`` and ``roc.png``.

    Returns
    -------
    The report dict (as in report.json).
    """
    meshes = read_labels(labels_csv, dataset_dir, per_class_limit)
    computed = compute_descriptors(meshes, preset, cache_root, jobs=jobs, progress=progress)
    if len({m.label for m in computed.meshes}) < 2:
        raise EvaluationError(
            f"fewer than two classes left after {len(computed.failures)} meshes failed"
        )
    env = {**environment_info(), **(environment or {})}
    report, _ = build_report(
        computed, preset, command=command, environment=env, dataset=str(dataset_dir)
    )
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
