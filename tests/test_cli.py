"""The ``shapes describe`` command."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from app.cli import main
from worker.engine import presets
from worker.engine.descriptor import ShapeDescriptor


@pytest.mark.slow  # describes a mesh
def test_describe_saves_npz_and_json(tmp_path, capsys, monkeypatch, small_preset):
    monkeypatch.setitem(presets.PRESETS, small_preset.name, small_preset)
    mesh_path = tmp_path / "blob.ply"
    mesh_path.write_bytes(trimesh.creation.icosphere(subdivisions=4).export(file_type="ply"))
    for fmt in ("npz", "json"):
        code = main(
            [
                "describe",
                str(mesh_path),
                "--preset",
                small_preset.name,
                "--out",
                str(tmp_path / fmt),
                "--format",
                fmt,
            ]
        )
        assert code == 0
    line = json.loads(capsys.readouterr().out.splitlines()[0])
    assert line["vertices"] == 800 or abs(line["vertices"] - 800) < 30
    assert "gdm=" in line["timings"]
    from_npz = ShapeDescriptor.from_npz_bytes((tmp_path / "npz" / "blob.npz").read_bytes())
    from_json = ShapeDescriptor.from_json(json.loads((tmp_path / "json" / "blob.json").read_text()))
    np.testing.assert_array_equal(from_npz.ddt, from_json.ddt)


def test_describe_reports_bad_files_and_fails(tmp_path, capsys):
    bad = tmp_path / "broken.obj"
    bad.write_bytes(b"")
    assert main(["describe", str(bad)]) == 1
    assert "The file is empty." in capsys.readouterr().err
