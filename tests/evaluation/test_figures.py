"""``shapes evaluate --resampling figure``: one resampling per class, carried to its poses
by vertex id; a pose of another vertex count resampled on its own."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from conftest import bent_cylinder

from app.cli import main
from worker.engine.mesh_io import read_numbered_mesh
from worker.engine.presets import PRESETS, get_preset
from worker.engine.resample import carry_resampling, shared_resampling
from worker.evaluation.compute import compute_descriptors
from worker.evaluation.datasets import read_labels
from worker.evaluation.figures import compute_by_figure, figures_of

pytestmark = pytest.mark.slow  # describes seven generated meshes

#: Sec. 4.1's preset at 500 vertices (and 100 eigenpairs), so the run takes seconds.
FIGURE_PRESET = replace(
    get_preset("smeets2010-tosca"), name="test-figure", n_vertices=500, n_eigenpairs=100
)


def _off(mesh: trimesh.Trimesh) -> bytes:
    """OFF text in the mesh's own vertex order (trimesh's export keeps it)."""
    return mesh.export(file_type="off").encode()


@pytest.fixture(scope="module")
def collection(tmp_path_factory) -> Path:
    """Two figures: a tube in three bends and a thinner one in three, each numbered
    alike within the figure, and a fourth pose of the tube tessellated otherwise."""
    root = tmp_path_factory.mktemp("figures")
    rows = []
    for bend in (0.0, 0.8, 1.6):
        tube = bent_cylinder(bend)
        thin = trimesh.Trimesh(tube.vertices * [0.6, 0.6, 1.0], tube.faces, process=False)
        for name, mesh in ((f"tube-{bend}", tube), (f"thin-{bend}", thin)):
            (root / f"{name}.off").write_bytes(_off(mesh))
            rows.append(f"{name}.off,{name.split('-')[0]}")
    # Another tessellation of the tube: fewer sides, so other vertex ids.
    (root / "tube-coarser.off").write_bytes(_off(bent_cylinder(2.0, count=20)))
    rows.append("tube-coarser.off,tube")
    (root / "labels.csv").write_text("file,class\n" + "\n".join(rows) + "\n")
    return root


def test_each_class_shares_its_first_meshs_resampling(collection):
    meshes = read_labels(collection / "labels.csv", collection)
    figures, own = figures_of(meshes, FIGURE_PRESET.n_vertices)
    assert [f.reference.name for f in figures] == ["thin-0.0.off", "tube-0.0.off"]
    assert [[p.name for p in f.poses] for f in figures] == [
        ["thin-0.0.off", "thin-0.8.off", "thin-1.6.off"],
        ["tube-0.0.off", "tube-0.8.off", "tube-1.6.off"],
    ]
    assert [m.name for m in own] == ["tube-coarser.off"]
    reference = read_numbered_mesh(collection / "tube-0.0.off")
    expected = shared_resampling(reference, FIGURE_PRESET.n_vertices)
    tube = figures[1].resampling
    np.testing.assert_array_equal(tube.corners, expected.corners)
    np.testing.assert_array_equal(tube.faces, expected.faces)
    assert figures[0].key != figures[1].key


def test_the_evaluation_describes_every_pose_with_its_figures_resampling(collection, tmp_path):
    cache, out = tmp_path / "cache", tmp_path / "out"
    argv = ["evaluate", str(collection), "--preset", FIGURE_PRESET.name, "--jobs", "2"]
    argv += ["--cache", str(cache), "--resampling", "figure", "--out", str(out)]
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(PRESETS, FIGURE_PRESET.name, FIGURE_PRESET)
        assert main(argv) == 0
    report = json.loads((out / "report.json").read_text())
    resampling = report["resampling"]
    assert resampling["per"] == "figure"
    markdown = (out / "report.md").read_text()
    assert "## Resampling: one per figure" in markdown
    assert "| tube | `tube-0.0.off` |" in markdown and "`tube-coarser.off`." in markdown
    assert resampling["resampled_on_their_own"] == ["tube-coarser.off"]
    assert {c: f["made_on"] for c, f in resampling["figures"].items()} == {
        "thin": "thin-0.0.off",
        "tube": "tube-0.0.off",
    }
    meshes = read_labels(collection / "labels.csv", collection)
    computed, _ = compute_by_figure(meshes, FIGURE_PRESET, cache, progress=False)
    assert computed.stats["from_cache"] == len(meshes)  # the run stored every one
    assert [m.name for m in computed.meshes] == [m.name for m in meshes]
    assert [o["file"] for o in report["objects"]] == [m.name for m in meshes]
    by_name = {m.name: d for m, d in zip(computed.meshes, computed.descriptors, strict=True)}
    tube = resampling["figures"]["tube"]["vertices"]
    for bend in ("0.0", "0.8", "1.6"):
        described = by_name[f"tube-{bend}.off"]
        assert described.vertices == tube
        # Its figure's resampling, carried: the area of that mesh, not of the file.
        pose = read_numbered_mesh(collection / f"tube-{bend}.off")
        figure = shared_resampling(read_numbered_mesh(collection / "tube-0.0.off"), 500)
        carried = carry_resampling(pose, figure)
        assert described.area == pytest.approx(
            float(trimesh.Trimesh(carried.vertices, carried.faces, process=False).area), rel=1e-9
        )
    # The pose that cannot share it is described as without the option.
    alone = compute_descriptors(
        [m for m in meshes if m.name == "tube-coarser.off"], FIGURE_PRESET, cache, progress=False
    )
    np.testing.assert_array_equal(alone.descriptors[0].gdm, by_name["tube-coarser.off"].gdm)
