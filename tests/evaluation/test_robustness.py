"""The robustness protocol: its numbers on hand-made descriptors, and one real run."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest
from conftest import EXAMPLES, example

from worker.engine.presets import PARTS, Preset
from worker.evaluation.datasets import pose_set
from worker.evaluation.robustness import (
    PRESET_ROW,
    cross_resolution,
    pose_invariance,
    tessellation_scores,
)
from worker.evaluation.run import run_robustness
from worker.evaluation.shapedna import BASELINE

PRESET = Preset(
    name="test-robust", version=0, dissimilarity="D1", fusion="product", fused_modalities=("gdm",)
)


def _descriptors(points: np.ndarray) -> dict[str, np.ndarray]:
    """Every modality (and the baseline) the same positive 2-D points."""
    vectors = {m: points.copy() for m in ("gdm", "ddt", "spectrum")}
    vectors[BASELINE] = points.copy()
    return vectors


@pytest.fixture
def collection():
    # Three classes of two objects, far apart; within a class 0.1 apart.
    centres = np.array([[1.0, 1.0], [1.0, 4.0], [4.0, 1.0]])
    points = np.repeat(centres, 2, axis=0) + np.tile([[0.0, 0.0], [0.1, 0.0]], (3, 1))
    return _descriptors(points), ["a", "a", "b", "b", "c", "c"]


def test_variants_equal_to_their_sources_pass_with_no_gap(collection):
    originals, labels = collection
    sources = np.arange(6)
    scores = tessellation_scores(originals, labels, {"same": (sources, originals)}, PRESET)
    for row in ("gdm", "ddt", "spectrum", PRESET_ROW, BASELINE):
        assert scores[row]["class_retrieval"] == 1.0 and scores[row]["self_retrieval"] == 1.0
        assert scores[row]["gap"] == 0.0 and scores[row]["passes"]


def test_a_variant_that_drifts_towards_another_class_fails(collection):
    originals, labels = collection
    drifted = _descriptors(originals["gdm"][[0]] + [[0.0, 2.4]])  # object 0 moved near b
    scores = tessellation_scores(originals, labels, {"drift": (np.array([0]), drifted)}, PRESET)
    row = scores["gdm"]
    assert row["class_retrieval"] == 0.0 and row["self_retrieval"] == 0.0 and not row["passes"]
    d1_to_source = np.mean(2 * np.abs([0.0, 2.4]) / (originals["gdm"][0] * 2 + [0.0, 2.4]))
    assert row["gap"] == pytest.approx(d1_to_source / row["nearest_other_class_median"])
    assert row["variants"]["drift"]["count"] == 1


def test_a_product_is_measured_on_the_scale_of_one_distance(collection):
    # Two modalities moved alike, fused by a product with weights 1 and 3: the product
    # of the distances would put the gap at its fourth power; its weighted geometric
    # mean, the protocol's scale, at the modalities' own.
    originals, labels = collection
    drifted = _descriptors(originals["gdm"] + [[0.0, 0.03]])
    preset = dataclasses.replace(
        PRESET, fused_modalities=("gdm", "ddt"), fusion_weights={"gdm": 1.0, "ddt": 3.0}
    )
    variants = {"drift": (np.arange(6), drifted)}
    scores = tessellation_scores(originals, labels, variants, preset)
    assert scores[PRESET_ROW]["gap"] == pytest.approx(scores["gdm"]["gap"], rel=1e-9)
    assert scores["gdm"]["gap"] > 0.01
    summed = tessellation_scores(
        originals, labels, variants, dataclasses.replace(preset, fusion="sum")
    )
    assert summed[PRESET_ROW]["gap"] == pytest.approx(scores["gdm"]["gap"], rel=1e-9)


def test_pose_invariance_counts_poses_closer_to_the_collection(collection):
    originals, labels = collection
    poses = _descriptors(np.array([[8.0, 8.0], [8.0, 8.2], [1.02, 1.0]]))  # one near class a
    names = [f"m{i}" for i in range(len(labels))]
    scores = pose_invariance(poses, originals, labels, PRESET, ["p0", "p1", "p2"], names)
    assert scores["gdm"]["foreign_nearest"] == 1 and scores["gdm"]["poses"] == 3
    nearest_a = names[int(np.argmin(np.abs(originals["gdm"] - [1.02, 1.0]).sum(axis=1)))]
    assert scores["gdm"]["foreign"] == [["p2", nearest_a]]
    assert 0 < scores[PRESET_ROW]["ratio"] < 10


def test_cross_resolution_finds_a_pose_unless_the_resolution_moves_it_past_another():
    poses = np.array([[1.0, 1.0], [1.0, 1.3], [1.0, 2.0]])
    # Pose 0 at the other resolution moved towards pose 1, past the half-way point.
    other = poses + [[0.0, 0.2], [0.0, 0.01], [0.0, 0.01]]
    scores = cross_resolution(_descriptors(poses), _descriptors(other), PRESET)
    row = scores["gdm"]
    assert row["poses"] == 3
    # Wrong: only pose 0 at the second resolution, 0.1 from pose 1 and 0.2 from its
    # own pose at the first. (Pose 0 at the first is still nearer its own, 0.2 away,
    # than pose 1 at the second, 0.31 away.)
    assert row["rank1"] == pytest.approx(5 / 6)
    assert row["ratio"] < 1  # most poses moved less than the next pose is away
    same = cross_resolution(_descriptors(poses), _descriptors(poses), PRESET)
    for key in ("gdm", "ddt", "spectrum", PRESET_ROW, BASELINE):
        assert same[key]["rank1"] == 1.0 and same[key]["ratio"] == 0.0


@pytest.mark.slow  # describes 4 meshes, 2 variants each, and 2 poses
def test_run_writes_the_report_and_rotation_costs_nothing(tmp_path, surface_preset):
    labels = tmp_path / "labels.csv"
    labels.write_text(
        "file,class\nquadruped-0.off.gz,quadruped\nquadruped-1.off.gz,quadruped\n"
        "biped-0.off.gz,biped\nbiped-1.off.gz,biped\n"
    )
    poses = tmp_path / "quadrupeds"
    poses.mkdir()
    for name in ("quadruped-2", "quadruped-0"):
        shutil.copy(example(name), poses)
    preset = dataclasses.replace(
        surface_preset,
        name="test-robust-run",
        n_vertices=500,
        fused_modalities=("gdm", "ddt", "spectrum"),
        gdm_samples=100,
        parts_first_radius=0.07,
    )
    report = run_robustness(
        EXAMPLES,
        labels,
        preset,
        out_dir=tmp_path / "out",
        cache_root=tmp_path / "cache",
        variants=("rotated-scaled", "decimated-50"),
        poses_dir=poses,
        progress=False,
    )
    saved = json.loads((tmp_path / "out" / "robustness.json").read_text())
    assert saved["tessellation"] == report["tessellation"]
    assert "| GDM+DDT+Spectrum product" in (tmp_path / "out" / "robustness.md").read_text()
    for row in ("gdm", "ddt", "spectrum", PARTS, PRESET_ROW, BASELINE):
        rotated = report["tessellation"][row]["variants"]["rotated-scaled"]
        assert rotated["gap"] < 1e-4 and rotated["self_retrieval"] == 1.0
        assert report["tessellation"][row]["variants"]["decimated-50"]["count"] == 4
    assert "| Parts |" in (tmp_path / "out" / "robustness.md").read_text()
    assert PARTS not in report["poses"]["scores"]  # the parts never rank a whole query
    assert report["poses"]["scores"][PRESET_ROW]["poses"] == 2
    # Both poses remeshed at two resolutions; quadruped-0 and -2 differ by more than that.
    across = report["poses"]["cross_resolution"]
    assert across[PRESET_ROW]["poses"] == 2 and across[PRESET_ROW]["rank1"] == 1.0
    markdown = (tmp_path / "out" / "robustness.md").read_text()
    assert "Cross-resolution pose retrieval (2 poses" in markdown
    assert [m.name for m in pose_set(poses)] == ["quadruped-0.off.gz", "quadruped-2.off.gz"]
    assert report["failures"] == {}
    # The same meshes rotated; decimated to half the faces, about half the vertices.
    vertices = report["input_vertices"]
    assert vertices["rotated-scaled"] == vertices["original"]
    assert 0.4 < vertices["decimated-50"] / vertices["original"] < 0.6
    assert f"{vertices['decimated-50']:,}" in (tmp_path / "out" / "robustness.md").read_text()
