"""The describe_upload task as a worker runs it: the result's encoding, the heartbeat, an
unreachable source, the copies killed workers leave."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
import trimesh

from benchmarks.common import free_port
from worker.engine.descriptor import ShapeDescriptor
from worker.jobs.queue import (
    FILE_GONE,
    FILE_GONE_MESSAGE,
    descriptor_npz,
    heartbeat_key,
    make_huey,
)
from worker.jobs.settings import QueueSettings
from worker.jobs.sources import remove_stale_copies


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


def test_a_file_in_an_unreachable_database_waits_scheduled_without_a_heartbeat(tmp_path):
    """Not a crash and not a dead worker: the task is tried again later, and leaves no
    heartbeat that would go stale and be taken for a dead worker."""
    closed = f"postgresql+psycopg://shapes@127.0.0.1:{free_port()}/shapes"
    settings = QueueSettings(data_dir=tmp_path, database_url=closed)
    huey = make_huey(settings)
    huey.immediate = True
    task = huey.describe_upload("db:" + "0" * 64, "wolf.off", "smeets2010-shrec", 10_000)
    assert [t.id for t in huey.scheduled()] == [task.id]
    assert huey.get(heartbeat_key(task.id), peek=True) is None
    assert huey.get(task.id, peek=True) is None  # no result, no error: not done


def test_a_file_deleted_before_it_was_described_is_an_outcome_not_a_crash(huey, caplog):
    with caplog.at_level("INFO"):
        result = huey.describe_upload("gone.off", "gone.off", "smeets2010-shrec", 10_000).get()
    assert result == {"ok": False, "code": FILE_GONE, "message": FILE_GONE_MESSAGE}
    assert [r.exc_info for r in caplog.records] == [None] * len(caplog.records)
    assert any("deleted before it was described" in r.getMessage() for r in caplog.records)


def test_copies_left_by_killed_workers_are_removed_and_running_ones_kept(tmp_path):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    old, running, upload = scratch / "task-old", scratch / "task-now", scratch / "upload-x"
    for path in (old, running, upload):
        path.write_bytes(b"OFF")
    an_hour_ago = time.time() - 3600
    os.utime(old, (an_hour_ago, an_hour_ago))
    os.utime(upload, (an_hour_ago, an_hour_ago))
    assert remove_stale_copies(tmp_path, older_than_seconds=660) == 1
    assert sorted(p.name for p in scratch.iterdir()) == ["task-now", "upload-x"]
