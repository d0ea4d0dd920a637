"""labels.csv and the shared data set directory."""

from __future__ import annotations

from pathlib import Path

import pytest

from worker.evaluation.datasets import (
    DATASETS_ENV,
    DEFAULT_DATASETS_DIR,
    EvaluationError,
    read_labels,
    shared_dataset,
)


def write_labels(path: Path, rows: dict[str, str]) -> Path:
    path.write_text("file,class\n" + "".join(f"{f},{c}\n" for f, c in rows.items()))
    return path


def test_read_labels_orders_limits_and_validates(tmp_path):
    for name in ("cat10.off", "cat2.off", "cat1.off", "dog1.off", "dog0.off", "dog3.off"):
        (tmp_path / name).write_text("")
    rows = {n: n[:3] for n in ("cat10.off", "cat2.off", "cat1.off", "dog1.off", "dog0.off")}
    labels = write_labels(tmp_path / "labels.csv", rows)
    meshes = read_labels(labels, tmp_path)
    assert [m.name for m in meshes] == ["cat1.off", "cat2.off", "cat10.off", "dog0.off", "dog1.off"]
    limited = read_labels(labels, tmp_path, per_class_limit=2)
    assert [m.name for m in limited] == ["cat1.off", "cat2.off", "dog0.off", "dog1.off"]
    with pytest.raises(EvaluationError, match="at least 2"):
        read_labels(labels, tmp_path, per_class_limit=1)
    missing = write_labels(tmp_path / "missing.csv", {**rows, "cow.off": "cow"})
    with pytest.raises(EvaluationError, match="cow.off"):
        read_labels(missing, tmp_path)
    one_class = write_labels(tmp_path / "one.csv", {"cat1.off": "cat", "cat2.off": "cat"})
    with pytest.raises(EvaluationError, match="two classes"):
        read_labels(one_class, tmp_path)
    (tmp_path / "bad.csv").write_text("name,label\ncat1.off,cat\n")
    with pytest.raises(EvaluationError, match="'file' and 'class'"):
        read_labels(tmp_path / "bad.csv", tmp_path)


def test_shared_dataset_follows_the_environment_variable(tmp_path, monkeypatch):
    monkeypatch.delenv(DATASETS_ENV, raising=False)
    assert shared_dataset("tosca") == DEFAULT_DATASETS_DIR / "tosca"
    # beside the checkout: <repo>/../shared/datasets
    assert DEFAULT_DATASETS_DIR == Path(__file__).resolve().parents[2].parent / "shared/datasets"
    monkeypatch.setenv(DATASETS_ENV, str(tmp_path))
    assert shared_dataset("tosca") == tmp_path / "tosca"
