"""``shapes evaluate`` end to end on a few of the bundled examples: the report, its
files, the descriptor cache in use, meshes left out."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from conftest import EXAMPLES, example

from app.cli import main
from worker.engine.mesh_io import face_areas, load_mesh
from worker.engine.presets import PRESETS, SIZE, Preset
from worker.evaluation import compute
from worker.evaluation.cache import file_sha256
from worker.evaluation.datasets import LabeledMesh, read_labels
from worker.evaluation.run import run_evaluation
from worker.evaluation.scoring import BASELINE, COLUMNS, ROWS, score_dissimilarity
from worker.evaluation.size import SIZE_GRID
from worker.recognition.fusion import all_to_all, feasible_folds
from worker.recognition.metrics import first_instance_split

pytestmark = pytest.mark.slow  # shapes evaluate end to end

# 8 examples of three classes.
SUBSET = {
    "quadruped-0.off.gz": "quadruped",
    "quadruped-1.off.gz": "quadruped",
    "quadruped-2.off.gz": "quadruped",
    "biped-0.off.gz": "biped",
    "biped-2.off.gz": "biped",
    "biped-3.off.gz": "biped",
    "hand-0.off.gz": "hand",
    "hand-2.off.gz": "hand",
}
# Test-only preset: the paper's method at 500 vertices keeps the run to seconds.
EVAL_PRESET = Preset(name="test-eval-small", version=0, n_vertices=500, n_eigenpairs=100)
# The three figures are far apart: even at 500 vertices the paper's GDM and the preset's
# fusion find a same-class nearest neighbour for all 8 and put every pair of one figure
# nearer than any pair of two (measured: NN 100%, EER 0).
MIN_EASY_NN = 1.0
MAX_EASY_EER = 0.0


def describe_area(path: Path) -> float:
    """The area of a file's cleaned surface: what its descriptor records."""
    mesh = load_mesh(path)
    return float(face_areas(mesh.vertices, mesh.faces).sum())


def write_labels(path: Path, rows: dict[str, str]) -> Path:
    path.write_text("file,class\n" + "".join(f"{f},{c}\n" for f, c in rows.items()))
    return path


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """``shapes evaluate`` on the examples' subset with 2 worker processes, cold cache."""
    tmp = tmp_path_factory.mktemp("evaluate")
    labels = write_labels(tmp / "labels.csv", SUBSET)
    cache, out = tmp / "cache", tmp / "out"
    argv = ["evaluate", str(EXAMPLES), "--labels", str(labels), "--preset", EVAL_PRESET.name]
    argv += ["--jobs", "2", "--cache", str(cache)]
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(PRESETS, EVAL_PRESET.name, EVAL_PRESET)
        code = main([*argv, "--out", str(out)])
    return {"code": code, "argv": argv, "cache": cache, "out": out, "tmp": tmp}


def load_report(out: Path) -> dict:
    return json.loads((out / "report.json").read_text())


# --------------------------------------------------------------------------- end to end


def test_cli_writes_report_files(first_run):
    out = first_run["out"]
    assert first_run["code"] == 0
    for name in ("report.json", "report.md", "cmc.png", "roc.png"):
        assert (out / name).stat().st_size > 1000, name
    for name in ("cmc.png", "roc.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    report = load_report(out)
    assert list(report["rows"]) == list(ROWS)
    assert report["command"].startswith("shapes evaluate ")
    assert report["preset"]["name"] == EVAL_PRESET.name
    assert report["failures"] == {}
    assert report["class_sizes"] == {"biped": 3, "hand": 2, "quadruped": 3}
    gallery = [o["file"] for o in report["objects"] if o["gallery"]]
    assert gallery == ["biped-0.off.gz", "hand-0.off.gz", "quadruped-0.off.gz"]
    assert (
        "first instance of each class in natural file-name order"
        in (report["protocol"]["identification"])
    )
    for key, row in report["rows"].items():
        for column in COLUMNS:
            assert 0.0 <= row[column] <= 1.0, (key, column)
        assert len(row["cmc"]) == 3 and row["cmc"][-1] == 1.0
        assert row["cmc"][0] == row["r1rr"]
        assert np.all(np.diff(row["cmc"]) >= 0)
        far, frr = np.array(row["roc"]["far"]), np.array(row["roc"]["frr"])
        assert far[0] == 0.0 and frr[0] == 1.0 and far[-1] == 1.0 and frr[-1] == 0.0
        # every NN error is a query whose nearest object has another class
        assert len(row["nn_errors"]) == round((1 - row["nn"]) * 8)
    for key in ("gdm", "gdm+ddt product"):
        assert report["rows"][key]["nn"] >= MIN_EASY_NN
        assert report["rows"][key]["eer"] <= MAX_EASY_EER
    assert report["timings"]["computed"] == 8 and report["timings"]["from_cache"] == 0


def test_markdown_table_has_every_row_and_column(first_run):
    markdown = (first_run["out"] / "report.md").read_text()
    header = next(line for line in markdown.splitlines() if line.startswith("| |"))
    assert [c.strip() for c in header.strip("|").split("|")][1:] == list(COLUMNS.values())
    report = load_report(first_run["out"])
    for row in report["rows"].values():
        line = next(x for x in markdown.splitlines() if x.startswith(f"| {row['title']} |"))
        cells = [c.strip() for c in line.strip("|").split("|")][1:]
        assert float(cells[0]) == pytest.approx(100 * row["nn"], abs=0.05)
        assert float(cells[2]) == pytest.approx(100 * row["eer"], abs=0.005)


def test_baseline_column_is_lapy_shapedna(first_run):
    report = load_report(first_run["out"])
    row = report["rows"][BASELINE]
    assert row["title"] == "ShapeDNA (lapy)"
    assert "compute_distance" in row["dissimilarity"]
    assert "normalize_ev" in report["protocol"]["baseline"]
    assert row["nn"] >= 0.5  # a working baseline, not noise
    assert "| ShapeDNA (lapy) |" in (first_run["out"] / "report.md").read_text()
    assert len(list(first_run["cache"].glob("*/*.shapedna-k50.npz"))) == 8


def test_d2_sigma_recorded_over_all_objects(first_run):
    report = load_report(first_run["out"])
    assert EVAL_PRESET.dissimilarity == "D2"
    assert "over all 8 evaluated objects" in report["protocol"]["dissimilarity"]
    sizes = {m: len(s) for m, s in report["d2_sigma"].items()}
    assert sizes == {"gdm": 19, "ddt": 20 * 20 * 5, "spectrum": 50}
    assert all(min(s) > 0 for s in report["d2_sigma"].values())


def test_rerun_reads_the_cache_only(first_run, monkeypatch, capsys):
    def must_not_describe(*args, **kwargs):
        raise AssertionError("a cached mesh was described again")

    monkeypatch.setattr(compute, "_describe_job", must_not_describe)
    monkeypatch.setitem(PRESETS, EVAL_PRESET.name, EVAL_PRESET)
    out = first_run["tmp"] / "rerun"
    assert main([*first_run["argv"], "--jobs", "1", "--out", str(out)]) == 0
    again, before = load_report(out), load_report(first_run["out"])
    assert again["timings"]["from_cache"] == 8 and again["timings"]["computed"] == 0
    for key, row in before["rows"].items():
        for column in COLUMNS:
            assert again["rows"][key][column] == row[column], (key, column)
    printed = capsys.readouterr().out
    assert "ShapeDNA (lapy)" in printed and "GDM+DDT product" in printed


def test_only_missing_entries_are_computed(first_run, tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    for entry in first_run["cache"].glob("*/*.npz"):
        target = cache / entry.parent.name / entry.name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(entry.read_bytes())
    second = file_sha256(example("quadruped-1"))
    next(cache.glob(f"*/{second}.descriptor.npz")).unlink()

    calls = []
    real = compute._describe_job

    def counting(path, sha256, preset, variant, need_descriptor, need_baseline, stored, carried):
        calls.append((Path(path).name, variant, need_descriptor, need_baseline))
        return real(path, sha256, preset, variant, need_descriptor, need_baseline, stored, carried)

    monkeypatch.setattr(compute, "_describe_job", counting)
    meshes = read_labels(first_run["tmp"] / "labels.csv", EXAMPLES)
    computed = compute.compute_descriptors(meshes, EVAL_PRESET, cache, jobs=1, progress=False)
    assert calls == [("quadruped-1.off.gz", None, True, False)]
    assert computed.stats["from_cache"] == 7 and computed.stats["computed"] == 1


def test_a_remeshed_variant_is_made_once_and_described_again_from_its_stored_mesh(
    tmp_path, monkeypatch
):
    """MeshLab's remeshing is most of the robustness protocol's time: its meshes are
    stored, so a changed pipeline describes the same variant meshes without remaking
    them, and gets the very descriptors it would from a freshly made one."""
    path = example("quadruped-0")
    meshes = [LabeledMesh(name=path.name, label="quadruped", path=path)]
    cache = tmp_path / "cache"
    made = compute.compute_descriptors(
        meshes, EVAL_PRESET, cache, jobs=1, progress=False, variant="remeshed-8k"
    )
    stored = list(cache.glob("variants-*/*.remeshed-8k.npz"))
    assert [p.name for p in stored] == [f"{file_sha256(path)}.remeshed-8k.npz"]

    def must_not_remesh(*args, **kwargs):
        raise AssertionError("a stored variant mesh was made again")

    monkeypatch.setattr(compute, "make_variant", must_not_remesh)
    for entry in cache.glob(f"{EVAL_PRESET.name}-*/*.npz"):
        entry.unlink()  # as if the pipeline had changed: descriptors gone, meshes kept
    again = compute.compute_descriptors(
        meshes, EVAL_PRESET, cache, jobs=1, progress=False, variant="remeshed-8k"
    )
    assert again.stats["computed"] == 1 and not again.failures
    for modality in ("gdm", "ddt", "spectrum"):
        assert np.array_equal(
            again.descriptors[0].vector(modality), made.descriptors[0].vector(modality)
        )
    # lapy's eigensolver varies at rounding level between two runs on one mesh
    np.testing.assert_allclose(
        again.baselines[0].descriptor, made.baselines[0].descriptor, atol=1e-9
    )


def test_failed_mesh_is_left_out_and_reported(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=3)
    box = trimesh.creation.box(extents=(1.0, 1.5, 3.0)).subdivide().subdivide().subdivide()
    rows = {}
    for i, (label, mesh) in enumerate(
        [("round", sphere), ("round", sphere), ("boxy", box), ("boxy", box)]
    ):
        name = f"{label}{i}.off"
        mesh.apply_scale(1.0 + 0.1 * i).export(tmp_path / name)
        rows[name] = label
    (tmp_path / "broken.off").write_text("OFF\nthis is not a mesh\n")
    rows["broken.off"] = "boxy"
    labels = write_labels(tmp_path / "labels.csv", rows)
    report = run_evaluation(
        tmp_path,
        labels,
        EVAL_PRESET,
        out_dir=tmp_path / "out",
        cache_root=tmp_path / "cache",
        jobs=1,
        progress=False,
        plot=lambda report, out: None,
    )
    assert list(report["failures"]) == ["broken.off"]
    assert [o["file"] for o in report["objects"]] == [
        "boxy2.off",
        "boxy3.off",
        "round0.off",
        "round1.off",
    ]
    # same shapes at other scales: every scale-normalized representation matches them
    assert report["rows"]["gdm"]["nn"] == 1.0
    assert "broken.off" in (tmp_path / "out" / "report.md").read_text()


def test_cli_reports_bad_input_without_traceback(tmp_path, capsys):
    (tmp_path / "labels.csv").write_text("file,class\nnope.off,x\n")
    assert main(["evaluate", str(tmp_path), "--cache", str(tmp_path / "c")]) == 2
    assert "nope.off" in capsys.readouterr().err


def test_the_learned_fusion_row_holds_held_out_figures_only(first_run):
    """``--fusion learned`` (three of each class: as many folds as hold one each), from
    the cache but for the one mesh added."""
    labels = write_labels(first_run["tmp"] / "nine.csv", {**SUBSET, "hand-3.off.gz": "hand"})
    out = first_run["tmp"] / "learned"
    argv = ["evaluate", str(EXAMPLES), "--labels", str(labels), "--preset", EVAL_PRESET.name]
    argv += ["--jobs", "2", "--cache", str(first_run["cache"]), "--fusion", "learned"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(PRESETS, EVAL_PRESET.name, EVAL_PRESET)
        assert main([*argv, "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert list(report["rows"])[-2:] == ["learned", BASELINE]
    row, learned = report["rows"]["learned"], report["learned_fusion"]
    classes = [o["class"] for o in report["objects"]]
    assert len(learned["folds"]) == feasible_folds(classes)
    assert sum(f["held_out_objects"] for f in learned["folds"]) == len(SUBSET) + 1
    # The EER is the folds' mean of their held-out EERs, never one over pooled scales.
    folds_eer = np.mean([f["held_out"]["learned"]["eer"] for f in learned["folds"]])
    assert row["eer"] == pytest.approx(folds_eer) == learned["held_out"]["learned"]["eer"]
    assert set(row["comparisons"].values()) <= {"D1", "D2", "reweighted euclidean"}
    assert set(row["weights"]) == set(EVAL_PRESET.fused_modalities)
    frr = np.asarray(row["roc"]["frr"])
    assert np.all(np.diff(frr) <= 1e-12) and 0.0 <= frr.min() <= frr.max() <= 1.0
    assert "Learned fusion (held-out folds)" in (out / "report.md").read_text()


# --------------------------------------------------------------------------- units


#: The evaluation preset with a size weight (only how it compares: the same descriptors,
#: the same cache entries).
SIZED_PRESET = replace(EVAL_PRESET, fusion_weights={SIZE: 0.5})
NINE = {**SUBSET, "hand-3.off.gz": "hand"}  # three of each class: three folds


def _evaluate(first_run, labels: Path, out: Path, *extra: str) -> dict:
    argv = ["evaluate", str(EXAMPLES), "--labels", str(labels), "--preset", SIZED_PRESET.name]
    argv += ["--jobs", "2", "--cache", str(first_run["cache"]), *extra, "--out", str(out)]
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(PRESETS, SIZED_PRESET.name, SIZED_PRESET)
        assert main(argv) == 0
    return load_report(out)


def test_units_metric_adds_the_size_and_leaves_every_other_row_as_it_was(first_run):
    """``--units metric``: the size alone and the preset's score with it, from the same
    descriptors (all from the cache); every row of the scale-free report unchanged, byte
    for byte."""
    plain = load_report(first_run["out"])
    metric = _evaluate(
        first_run, first_run["tmp"] / "labels.csv", first_run["tmp"] / "metric", "--units", "metric"
    )
    key = "gdm+ddt+size product"
    assert list(metric["rows"]) == [*list(ROWS)[:-1], SIZE, key, BASELINE]
    for row in ROWS:
        assert json.dumps(metric["rows"][row]) == json.dumps(plain["rows"][row]), row
    assert metric["timings"]["computed"] == 0
    assert metric["rows"][SIZE]["dissimilarity"] == f"D1 >= {SIZED_PRESET.size_tolerance:g}"
    assert metric["rows"][key]["members"] == ["gdm", "ddt", SIZE]
    assert metric["rows"][key]["weights"] == {"gdm": 1.0, "ddt": 1.0, SIZE: 0.5}
    assert metric["protocol"]["preset_score"] == key and "units" not in plain["protocol"]
    assert (metric["preset"]["units"], plain["preset"]["units"]) == ("metric", "any")
    # The size row is eq. (8) of every file's sqrt(area) (of its cleaned surface), at
    # least the tolerance.
    meshes = read_labels(first_run["tmp"] / "labels.csv", EXAMPLES)
    sizes = np.sqrt([[describe_area(m.path)] for m in meshes])
    names, labels = [m.name for m in meshes], [m.label for m in meshes]
    matrix = np.maximum(all_to_all(sizes, "D1"), SIZED_PRESET.size_tolerance)
    np.fill_diagonal(matrix, 0.0)
    expected = score_dissimilarity(matrix, labels, names, *first_instance_split(names, labels))
    for column in COLUMNS:
        assert metric["rows"][SIZE][column] == pytest.approx(expected[column], abs=1e-12)


def test_units_metric_learns_the_size_with_the_shape(first_run):
    labels = write_labels(first_run["tmp"] / "nine-metric.csv", NINE)
    report = _evaluate(
        first_run,
        labels,
        first_run["tmp"] / "learned-metric",
        "--units",
        "metric",
        "--fusion",
        "learned",
    )
    row = report["rows"]["learned"]
    assert row["members"] == ["gdm", "ddt", SIZE]
    assert list(row["weights"]) == [SIZE, "gdm", "ddt"] and row["weights"]["ddt"] == 1.0
    assert row["comparisons"][SIZE] == SIZED_PRESET.comparison(SIZE)


def test_tune_chooses_the_size_weight_that_evaluate_takes(first_run, capsys):
    """``shapes tune --units metric`` chooses only the size's weight (the shape's are the
    preset's) and ``shapes evaluate --units metric --weights`` fuses with it."""
    labels = write_labels(first_run["tmp"] / "nine-tune.csv", NINE)
    weights = first_run["tmp"] / "size-weights.json"
    argv = ["tune", str(EXAMPLES), "--labels", str(labels), "--preset", SIZED_PRESET.name]
    argv += ["--jobs", "2", "--cache", str(first_run["cache"]), "--folds", "3", "--units", "metric"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(PRESETS, SIZED_PRESET.name, SIZED_PRESET)
        assert main([*argv, "--out", str(weights)]) == 0
    document = json.loads(weights.read_text())
    assert (document["units"], document["chosen"]) == ("metric", [SIZE])
    assert document["weights"]["gdm"] == document["weights"]["ddt"] == 1.0
    assert document["weights"][SIZE] in SIZE_GRID and list(document["sensitivity"]) == [SIZE]
    assert document["held_out"]["preset"]["weights"] == {"gdm": 1.0, "ddt": 1.0, SIZE: 0.5}
    assert "weights of size from (0, 0.0625" in capsys.readouterr().out
    report = _evaluate(
        first_run,
        labels,
        first_run["tmp"] / "tuned-metric",
        "--units",
        "metric",
        "--weights",
        str(weights),
    )
    assert report["preset"]["fusion_weights"] == document["weights"]
    assert report["rows"]["gdm+ddt+size product"]["weights"][SIZE] == document["weights"][SIZE]


def test_unknown_units_are_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", str(EXAMPLES), "--units", "imperial"])
    assert "invalid choice: 'imperial'" in capsys.readouterr().err
