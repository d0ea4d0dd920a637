"""``shapes tune`` on a few small TOSCA meshes, and ``shapes evaluate --weights`` with its file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from worker.engine.presets import PRESETS, Preset
from worker.evaluation.compute import compute_descriptors, descriptor_vectors
from worker.evaluation.datasets import read_labels
from worker.evaluation.scoring import modality_dissimilarity
from worker.recognition.fusion import tune_fusion

#: Three meshes of each of three classes (the smallest files): three folds leave two of
#: every class to choose on.
SUBSET = {
    "wolf0.off.gz": "wolf",
    "wolf1.off.gz": "wolf",
    "wolf2.off.gz": "wolf",
    "centaur0.off.gz": "centaur",
    "centaur3.off.gz": "centaur",
    "centaur5.off.gz": "centaur",
    "horse0.off.gz": "horse",
    "horse5.off.gz": "horse",
    "horse6.off.gz": "horse",
}
FOLDS = 3
#: Test-only preset: the surface measure's three modalities at 500 vertices, in seconds.
TUNE_PRESET = Preset(
    name="test-tune-small",
    version=0,
    n_vertices=500,
    n_eigenpairs=100,
    measure="surface",
    dissimilarity="D1",
    fused_modalities=("gdm", "ddt", "spectrum"),
    fusion_weights={"gdm": 0.5},
)


@pytest.fixture
def tune_preset(monkeypatch: pytest.MonkeyPatch) -> Preset:
    monkeypatch.setitem(PRESETS, TUNE_PRESET.name, TUNE_PRESET)
    return TUNE_PRESET


@pytest.fixture(scope="module")
def tuned(tmp_path_factory, tosca_dir):
    """``shapes tune`` on the subset with two worker processes, cold cache."""
    tmp = tmp_path_factory.mktemp("tune")
    labels = tmp / "labels.csv"
    labels.write_text("file,class\n" + "".join(f"{f},{c}\n" for f, c in SUBSET.items()))
    argv = ["tune", str(tosca_dir), "--labels", str(labels), "--preset", TUNE_PRESET.name]
    argv += ["--jobs", "2", "--cache", str(tmp / "cache"), "--folds", str(FOLDS)]
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(PRESETS, TUNE_PRESET.name, TUNE_PRESET)
        code = main([*argv, "--out", str(tmp / "weights.json")])
    return {"code": code, "tmp": tmp, "labels": labels, "argv": argv}


@pytest.mark.slow  # describes nine TOSCA meshes
def test_tune_writes_the_weights_the_library_chooses(tuned, tosca_dir, capsys):
    assert tuned["code"] == 0
    document = json.loads((tuned["tmp"] / "weights.json").read_text())
    assert (document["preset"], document["preset_version"]) == (TUNE_PRESET.name, 0)
    assert document["fusion"] == "product" and document["meshes"] == len(SUBSET)
    # The same choice as the library's on the same descriptors (from the cache).
    computed = compute_descriptors(
        read_labels(tuned["labels"], tosca_dir), TUNE_PRESET, tuned["tmp"] / "cache"
    )
    vectors = descriptor_vectors(computed)
    expected = tune_fusion(
        {m: modality_dissimilarity(vectors[m], "D1")[0] for m in TUNE_PRESET.fused_modalities},
        np.array([m.label for m in computed.meshes]),
        "product",
        {"gdm": 0.5, "ddt": 1.0, "spectrum": 1.0},
        folds=FOLDS,
    )
    assert document["weights"] == expected.weights
    assert [f["weights"] for f in document["folds"]] == [f.weights for f in expected.folds]
    assert document["held_out"]["tuned"]["eer"] == expected.held_out.eer
    assert document["held_out"]["preset"]["weights"] == {"gdm": 0.5, "ddt": 1.0, "spectrum": 1.0}
    assert sum(f["held_out_objects"] for f in document["folds"]) == len(SUBSET)
    assert list(document["sensitivity"]) == ["gdm", "ddt"]
    # The printed table: a row per fold, and the choice on all meshes.
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(PRESETS, TUNE_PRESET.name, TUNE_PRESET)
        assert main([*tuned["argv"], "--out", str(tuned["tmp"] / "again.json")]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith(("| 0 |", "| 1 |", "| 2 |"))]
    assert len(rows) == FOLDS
    chosen = ", ".join(f"{m} {w:g}" for m, w in expected.weights.items())
    assert f"chosen on all meshes: {chosen} (loss " in out


@pytest.mark.slow  # scores nine TOSCA meshes
def test_evaluate_fuses_with_the_weights_of_the_file(tuned, tosca_dir, tune_preset):
    weights = json.loads((tuned["tmp"] / "weights.json").read_text())["weights"]
    out = tuned["tmp"] / "evaluated"
    argv = ["evaluate", str(tosca_dir), "--labels", str(tuned["labels"])]
    argv += ["--preset", tune_preset.name, "--jobs", "2", "--cache", str(tuned["tmp"] / "cache")]
    code = main([*argv, "--weights", str(tuned["tmp"] / "weights.json"), "--out", str(out)])
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert report["preset"]["fusion_weights"] == weights
    assert report["timings"]["computed"] == 0  # the weights do not change the descriptors


def write_weights(path: Path, **changes: object) -> Path:
    document = {
        "preset": TUNE_PRESET.name,
        "preset_version": TUNE_PRESET.version,
        "fusion": "product",
        "weights": {"gdm": 0.0, "ddt": 0.5, "spectrum": 1.0},
    }
    path.write_text(json.dumps({**document, **changes}))
    return path


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"preset_version": 7}, "holds weights for test-tune-small v7 (product rule), not for "),
        ({"preset": "smeets2010-shrec"}, "holds weights for smeets2010-shrec v0"),
        ({"fusion": "sum"}, "(sum rule), not for test-tune-small v0 (product rule)"),
        ({"weights": {"gdm": 0.0, "ddt": 0.5, "curvature": 1.0}}, "unknown modalities"),
        ({"weights": {"gdm": 0.0, "ddt": 0.5}}, "fuses ['ddt', 'gdm', 'spectrum']"),
        ({"weights": {"gdm": -1, "ddt": 0.5, "spectrum": 1}}, "not numbers >= 0: {'gdm': -1}"),
        ({"weights": None}, "holds no 'weights' object"),
    ],
)
def test_evaluate_refuses_weights_of_another_preset_or_modalities(
    tmp_path, capsys, tune_preset, changes, message
):
    weights = write_weights(tmp_path / "weights.json", **changes)
    argv = ["evaluate", str(tmp_path), "--preset", tune_preset.name, "--weights", str(weights)]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_tune_refuses_a_preset_with_one_modality(tmp_path, capsys):
    assert main(["tune", str(tmp_path), "--preset", "lb-spectrum"]) == 2
    assert "lb-spectrum fuses ['spectrum'] only: no weights to choose" in capsys.readouterr().err
