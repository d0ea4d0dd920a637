"""The labelled collections an evaluation runs on, and where the shared ones live."""

from __future__ import annotations

import csv
import os
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from worker.engine.errors import MeshError
from worker.engine.formats import mesh_format
from worker.recognition.metrics import natural_sort_key

#: Environment variable naming the directory that holds the shared data sets.
DATASETS_ENV = "SHAPES_DATASETS_DIR"
#: Where the shared data sets are when the variable is unset: beside the checkout.
DEFAULT_DATASETS_DIR = Path(__file__).resolve().parents[2].parent / "shared" / "datasets"
#: Default descriptor cache of ``shapes evaluate`` and the benchmarks, outside any checkout.
DEFAULT_CACHE = Path.home() / ".cache" / "modalshape" / "evaluate"
#: How an evaluation resamples its meshes: every one on its own (as the service does), or
#: once per figure, carried to its poses by vertex id (:mod:`.figures`).
RESAMPLINGS = ("mesh", "figure")
#: The coordinate axes a collection's files may stand on (the partiality protocol's
#: range camera orbits it).
UP_AXES = ("x", "y", "z")


def shared_dataset(name: str) -> Path:
    """Directory of the shared data set ``name`` (e.g. ``"tosca"``).

    ``$SHAPES_DATASETS_DIR/<name>`` when the variable is set, otherwise
    ``<checkout>/../shared/datasets/<name>``. The directory may not exist: callers
    check (tests skip, scripts fail with the path in the message).
    """
    root = os.environ.get(DATASETS_ENV)
    return (Path(root) if root else DEFAULT_DATASETS_DIR) / name


class EvaluationError(ValueError):
    """The evaluation cannot run on this input; the message says why."""


@dataclass(frozen=True)
class LabeledMesh:
    """One object of the evaluated set: file name (as in labels.csv), class, path."""

    name: str
    label: str
    path: Path


def read_labels(
    labels_csv: str | Path, dataset_dir: str | Path, per_class_limit: int | None = None
) -> list[LabeledMesh]:
    """Read ``labels.csv`` (columns ``file,class``; files relative to ``dataset_dir``).

    Parameters
    ----------
    labels_csv : path of the CSV file, with a header row naming ``file`` and ``class``.
    dataset_dir : directory the file names are relative to.
    per_class_limit : keep only the first ``per_class_limit`` files of each class in
        natural file-name order (at least 2, so every class keeps a genuine pair).

    Returns
    -------
    list of LabeledMesh in natural file-name order.

    Raises
    ------
    EvaluationError
        On a missing column, a missing file, a repeated file, or fewer than two classes.
    """
    dataset_dir = Path(dataset_dir)
    if per_class_limit is not None and per_class_limit < 2:
        raise EvaluationError("--limit must be at least 2 meshes per class")
    with open(labels_csv, newline="") as handle:
        reader = csv.DictReader(handle)
        fields = [f.strip().lower() for f in (reader.fieldnames or [])]
        if "file" not in fields or "class" not in fields:
            raise EvaluationError(
                f"{labels_csv} needs a header row with 'file' and 'class' columns, got {fields}"
            )
        rows = [{k.strip().lower(): (v or "").strip() for k, v in row.items()} for row in reader]
    meshes = [
        LabeledMesh(name=r["file"], label=r["class"], path=dataset_dir / r["file"])
        for r in rows
        if r["file"]
    ]
    repeated = [name for name, count in Counter(m.name for m in meshes).items() if count > 1]
    if repeated:
        raise EvaluationError(f"{labels_csv} lists files more than once: {repeated}")
    missing = [m.name for m in meshes if not m.path.is_file()]
    if missing:
        raise EvaluationError(f"files listed in {labels_csv} not found in {dataset_dir}: {missing}")
    meshes.sort(key=lambda m: natural_sort_key(m.name))
    if per_class_limit is not None:
        taken: Counter[str] = Counter()
        kept = []
        for m in meshes:
            if taken[m.label] < per_class_limit:
                taken[m.label] += 1
                kept.append(m)
        meshes = kept
    if len({m.label for m in meshes}) < 2:
        raise EvaluationError("the evaluation needs at least two classes")
    return meshes


def pose_set(directory: str | Path) -> list[LabeledMesh]:
    """Every mesh file in ``directory``, as poses of one object (labelled by the
    directory's name), in natural file-name order; e.g. SCAPE's 71 poses of one body.

    Raises
    ------
    EvaluationError
        When the directory holds fewer than two mesh files.
    """
    directory = Path(directory)
    files = (
        sorted(
            (p for p in directory.iterdir() if p.is_file() and _is_mesh_file(p.name)),
            key=lambda p: natural_sort_key(p.name),
        )
        if directory.is_dir()
        else []
    )
    if len(files) < 2:
        raise EvaluationError(f"{directory} needs at least two mesh files (poses of one object)")
    return [LabeledMesh(name=p.name, label=directory.name, path=p) for p in files]


def _is_mesh_file(name: str) -> bool:
    try:
        mesh_format(name)
    except MeshError:
        return False
    return True
