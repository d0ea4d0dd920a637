"""The describe_upload task as a worker runs it: the result's encoding and the heartbeat."""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh

from worker.engine.descriptor import ShapeDescriptor
from worker.jobs.queue import descriptor_npz, heartbeat_key, make_huey
from worker.jobs.settings import QueueSettings


@pytest.fixture
def huey(tmp_path: Path):
    settings = QueueSettings(data_dir=tmp_path, job_time_limit_seconds=120)
    huey = make_huey(settings)
    huey.immediate = True  # run tasks in this process, results in memory
    return huey


@pytest.mark.slow  # a whole descriptor at the default preset's 2,500 vertices
def test_a_described_upload_comes_back_as_the_workers_npz_bytes(huey, tmp_path):
    trimesh.creation.icosphere(subdivisions=3).export(tmp_path / "ball.off")
    task = huey.describe_upload("ball.off", "ball.off", "smeets2010-shrec", 10_000)
    result = task.get()
    assert result["ok"] is True
    descriptor = ShapeDescriptor.from_npz_bytes(descriptor_npz(result))
    assert descriptor.preset == "smeets2010-shrec" and abs(descriptor.vertices - 2500) <= 75
    assert descriptor.ddt.shape == (20, 20, 5)
    beat = huey.get(heartbeat_key(task.id), peek=True)
    assert set(beat) == {"pid", "host", "started", "beat"} and beat["beat"] >= beat["started"]


@pytest.mark.slow  # starts a fork server
def test_a_refused_upload_is_a_result_with_its_code_not_an_error(huey, tmp_path):
    (tmp_path / "notes.off").write_text("OFF\nthis is not a mesh\n")
    result = huey.describe_upload("notes.off", "notes.off", "smeets2010-shrec", 10_000).get()
    assert result["ok"] is False and result["code"] == "unreadable_mesh"
    assert result["message"].endswith(".")
