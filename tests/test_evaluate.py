"""The evaluation harness: ``shapes evaluate`` end to end on a few small TOSCA meshes,
the descriptor cache, D2's sigma, fusion, and the report."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from worker import evaluate
from worker.cli import main
from worker.compare import mean_normalized_manhattan
from worker.evaluate import (
    BASELINE,
    ROWS,
    EvaluationError,
    cache_namespace,
    dissimilarity_matrices,
    modality_dissimilarity,
    read_labels,
    score_dissimilarity,
)
from worker.presets import PRESETS, Preset

TOSCA = Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets" / "tosca"
# The 8 smallest files of three classes (4.3k to 19k vertices).
SUBSET = {
    "wolf0.off.gz": "wolf",
    "wolf1.off.gz": "wolf",
    "wolf2.off.gz": "wolf",
    "centaur0.off.gz": "centaur",
    "centaur3.off.gz": "centaur",
    "centaur5.off.gz": "centaur",
    "horse0.off.gz": "horse",
    "horse6.off.gz": "horse",
}
# Test-only preset: the paper's method at 500 vertices keeps the run to seconds.
EVAL_PRESET = Preset(name="test-eval-small", version=0, n_vertices=500, n_eigenpairs=100)
# Wolves, centaurs and horses are far apart; even at 500 vertices the paper's GDM and
# the preset's fusion should find a same-class nearest neighbour for at least 7 of 8.
MIN_EASY_NN = 7 / 8
MAX_EASY_EER = 0.3


def write_labels(path: Path, rows: dict[str, str]) -> Path:
    path.write_text("file,class\n" + "".join(f"{f},{c}\n" for f, c in rows.items()))
    return path


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """``shapes evaluate`` on the TOSCA subset with 2 worker processes, cold cache."""
    if not TOSCA.is_dir():
        pytest.skip(f"TOSCA set not found at {TOSCA}")
    tmp = tmp_path_factory.mktemp("evaluate")
    labels = write_labels(tmp / "labels.csv", SUBSET)
    cache, out = tmp / "cache", tmp / "out"
    argv = ["evaluate", str(TOSCA), "--labels", str(labels), "--preset", EVAL_PRESET.name]
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
    assert report["class_sizes"] == {"centaur": 3, "horse": 2, "wolf": 3}
    gallery = [o["file"] for o in report["objects"] if o["gallery"]]
    assert gallery == ["centaur0.off.gz", "horse0.off.gz", "wolf0.off.gz"]
    assert (
        "first instance of each class in natural file-name order"
        in (report["protocol"]["identification"])
    )
    for key, row in report["rows"].items():
        for column in evaluate.COLUMNS:
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
    assert [c.strip() for c in header.strip("|").split("|")][1:] == list(evaluate.COLUMNS.values())
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

    monkeypatch.setattr(evaluate, "_describe_job", must_not_describe)
    monkeypatch.setitem(PRESETS, EVAL_PRESET.name, EVAL_PRESET)
    out = first_run["tmp"] / "rerun"
    assert main([*first_run["argv"], "--jobs", "1", "--out", str(out)]) == 0
    again, before = load_report(out), load_report(first_run["out"])
    assert again["timings"]["from_cache"] == 8 and again["timings"]["computed"] == 0
    for key, row in before["rows"].items():
        for column in evaluate.COLUMNS:
            assert again["rows"][key][column] == row[column], (key, column)
    printed = capsys.readouterr().out
    assert "ShapeDNA (lapy)" in printed and "GDM+DDT product" in printed


def test_only_missing_entries_are_computed(first_run, tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    for entry in first_run["cache"].glob("*/*.npz"):
        target = cache / entry.parent.name / entry.name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(entry.read_bytes())
    wolf1 = evaluate.file_sha256(TOSCA / "wolf1.off.gz")
    next(cache.glob(f"*/{wolf1}.descriptor.npz")).unlink()

    calls = []
    real = evaluate._describe_job

    def counting(path, preset, need_descriptor, need_baseline):
        calls.append((Path(path).name, need_descriptor, need_baseline))
        return real(path, preset, need_descriptor, need_baseline)

    monkeypatch.setattr(evaluate, "_describe_job", counting)
    meshes = read_labels(first_run["tmp"] / "labels.csv", TOSCA)
    computed = evaluate.compute_descriptors(meshes, EVAL_PRESET, cache, jobs=1, progress=False)
    assert calls == [("wolf1.off.gz", True, False)]
    assert computed.stats["from_cache"] == 7 and computed.stats["computed"] == 1


def test_cache_namespace_follows_preset_and_version():
    base = cache_namespace(EVAL_PRESET)
    assert base.startswith(f"{EVAL_PRESET.name}-v0-")
    assert cache_namespace(dataclasses.replace(EVAL_PRESET, version=1)) != base
    # an edited preset that forgot its version bump must not reuse stale entries
    assert cache_namespace(dataclasses.replace(EVAL_PRESET, n_vertices=600)) != base
    assert cache_namespace(EVAL_PRESET) == base


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
    report = evaluate.run_evaluation(
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


# --------------------------------------------------------------------------- pure parts


def test_d2_uses_the_standard_deviation_over_all_objects():
    rng = np.random.default_rng(1)
    x = rng.gamma(2.0, size=(6, 5))
    x[:, 4] = 3.0  # no spread: gallery_sigma sets sigma = 1
    d, info = modality_dissimilarity(x, "D2")
    sigma = np.where(x.std(axis=0) > 0, x.std(axis=0), 1.0)
    expected = np.sqrt((((x[:, None, :] - x[None, :, :]) / sigma) ** 2).sum(-1))
    np.testing.assert_allclose(d, expected, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(info["sigma"], sigma)
    assert np.array_equal(d, d.T) and np.all(np.diag(d) == 0)
    # sigma normalizes each element: rescaling one element changes nothing
    scaled = x * np.array([1.0, 1000.0, 1e-3, 7.0, 1.0])
    np.testing.assert_allclose(modality_dissimilarity(scaled, "D2")[0], d, rtol=1e-8)


def test_d1_is_eq_8():
    x = np.random.default_rng(2).gamma(2.0, size=(5, 4))
    d, info = modality_dissimilarity(x, "D1")
    np.testing.assert_allclose(d, mean_normalized_manhattan(x, x), atol=1e-15)
    assert info == {"dissimilarity": "D1"}
    with pytest.raises(ValueError, match="unknown dissimilarity"):
        modality_dissimilarity(x, "D3")


def test_fusion_rows_use_preset_weights():
    rng = np.random.default_rng(3)
    vectors = {m: rng.gamma(2.0, size=(5, 3)) for m in ("gdm", "ddt", "spectrum")}
    preset = dataclasses.replace(
        EVAL_PRESET, dissimilarity="D1", fusion_weights={"gdm": 2.0, "spectrum": 0.5}
    )
    matrices, info = dissimilarity_matrices(vectors, preset, baseline=None)
    gdm, ddt, spectrum = (matrices[m] for m in ("gdm", "ddt", "spectrum"))
    np.testing.assert_allclose(matrices["gdm+ddt sum"], 2 * gdm + ddt)
    np.testing.assert_allclose(matrices["gdm+ddt product"], gdm**2 * ddt)
    np.testing.assert_allclose(matrices["gdm+ddt+spectrum sum"], 2 * gdm + ddt + 0.5 * spectrum)
    np.testing.assert_allclose(
        matrices["gdm+ddt+spectrum product"], gdm**2 * ddt * np.sqrt(spectrum)
    )
    assert BASELINE not in matrices
    assert info["gdm+ddt sum"] == {"fusion": "sum", "weights": {"gdm": 2.0, "ddt": 1.0}}


def test_score_dissimilarity_names_the_confusions():
    # a0 a1 | b0 b1; a1 is closer to b0 than to a0, everything else is clean
    d = np.array(
        [
            [0.0, 0.5, 0.9, 0.9],
            [0.5, 0.0, 0.2, 0.9],
            [0.9, 0.2, 0.0, 0.1],
            [0.9, 0.9, 0.1, 0.0],
        ]
    )
    names = ["a0", "a1", "b0", "b1"]
    labels = ["a", "a", "b", "b"]
    scores = score_dissimilarity(d, labels, names, np.array([0, 2]), np.array([1, 3]))
    assert scores["nn"] == 0.75
    assert scores["nn_errors"] == [
        {"query": "a1", "class": "a", "nearest": "b0", "nearest_class": "b"}
    ]
    assert scores["r1rr"] == 0.5
    assert scores["rank1_errors"] == [
        {"probe": "a1", "class": "a", "matched": "b0", "matched_class": "b"}
    ]
    assert scores["cmc"] == [0.5, 1.0]
    # genuine 0.5, 0.1; impostors 0.9, 0.2, 0.9, 0.9: FRR = FAR = 1/4 between 0.2 and 0.5
    assert scores["eer"] == pytest.approx(0.25)


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


def test_cli_reports_bad_input_without_traceback(tmp_path, capsys):
    (tmp_path / "labels.csv").write_text("file,class\nnope.off,x\n")
    assert main(["evaluate", str(tmp_path), "--cache", str(tmp_path / "c")]) == 2
    assert "nope.off" in capsys.readouterr().err
