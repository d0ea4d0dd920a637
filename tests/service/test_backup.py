"""The restore drill: ``shapes backup`` of a live gallery under load, ``shapes restore``
on an empty data directory, and a service on it with every mesh, file and answer of
the one backed up."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
import threading

import pytest

from app.backup import backup
from app.config import Settings
from app.migrations import upgrade_head
from benchmarks.common import REPO, Service

from .conftest import migrated_service, running

pytestmark = [pytest.mark.slow, pytest.mark.service]

BEFORE = {f"{kind}-{pose}": kind for kind in ("biped", "quadruped", "hand") for pose in (0, 1)}
DURING = {f"{kind}-{pose}": kind for kind in ("bird", "spider") for pose in (0, 1, 2)}


def shapes(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )


def _meshes(service: Service) -> dict[int, dict]:
    items = service.client.get("/meshes", params={"limit": 200}).json()["items"]
    keep = ("id", "sha256", "name", "label", "metadata", "status", "descriptor", "created_at")
    out = {m["id"]: {k: m[k] for k in keep} for m in items}
    for mesh in out.values():  # a mesh queued when backed up is described after the restore
        if mesh["descriptor"] is not None:
            mesh["descriptor"].pop("timings")
    return out


def _answers(service: Service, ids) -> dict[str, object]:
    out: dict[str, object] = {}
    for mesh_id in sorted(ids):
        similar = service.client.post(f"/meshes/{mesh_id}/similar", params={"k": 20}).json()
        out[f"similar {mesh_id}"] = [(m["mesh_id"], m["score"]) for m in similar["matches"]]
    query = service.query("biped-3", k=20).json()
    out["query"] = [(m["mesh_id"], m["score"], m["scores"]) for m in query["matches"]]
    return out


def test_a_backup_under_load_restores_every_mesh_and_answer(tmp_path_factory, tmp_path):
    with running(migrated_service(tmp_path_factory, "backed-up")) as live:
        first = [live.upload(name, label).json()["id"] for name, label in BEFORE.items()]
        for mesh_id in first:
            assert live.wait_mesh(mesh_id)["status"] == "ready"

        def load() -> None:  # uploads, a delete and queries while the backup runs
            for name, label in DURING.items():
                live.upload(name, label)
                live.query("quadruped-2", k=3)
            live.client.delete(f"/meshes/{first[0]}")

        loader = threading.Thread(target=load)
        loader.start()
        backed_up = shapes("backup", str(tmp_path / "backup"), "--data-dir", str(live.data_dir))
        loader.join()
        assert backed_up.returncode == 0, backed_up.stderr
        assert backed_up.stdout.startswith("Backed up ")
        manifest = json.loads((tmp_path / "backup" / "manifest.json").read_text())
        with sqlite3.connect(tmp_path / "backup" / "shapes.sqlite3") as db:
            kept = {mesh_id for (mesh_id,) in db.execute("SELECT id FROM meshes")}
        assert manifest["meshes"] == len(kept) and set(first[1:]) <= kept
        # The live gallery and the backup brought to one content: what was enrolled
        # after the copy, deleted here; what was deleted after the copy (the load's
        # delete may come before or after it), deleted from the restored copy below.
        # What was queued in the backup is described after the restore.
        for mesh_id in _meshes(live):
            if mesh_id not in kept:
                assert live.client.delete(f"/meshes/{mesh_id}").status_code == 204
        common = set(_meshes(live))
        assert common <= kept and kept - common <= {first[0]}
        for mesh_id in common:
            assert live.wait_mesh(mesh_id)["status"] == "ready"
        expected_meshes = _meshes(live)
        expected_files = {i: live.client.get(f"/meshes/{i}/file").content for i in common}
        expected_answers = _answers(live, common)

    # A damaged backup is refused before anything is copied.
    database = tmp_path / "backup" / "shapes.sqlite3"
    intact = database.read_bytes()
    database.write_bytes(intact[:-1] + bytes([intact[-1] ^ 1]))
    refused = shapes("restore", str(tmp_path / "backup"), "--data-dir", str(tmp_path / "bad"))
    assert refused.returncode == 1 and "damaged" in refused.stderr
    assert not (tmp_path / "bad" / "shapes.sqlite3").exists()
    database.write_bytes(intact)

    restored = shapes("restore", str(tmp_path / "backup"), "--data-dir", str(tmp_path / "new"))
    assert restored.returncode == 0, restored.stderr
    again = shapes("restore", str(tmp_path / "backup"), "--data-dir", str(tmp_path / "new"))
    assert again.returncode == 1 and "empty data directory" in again.stderr
    with running(Service(tmp_path / "new")) as copy:
        for mesh_id in kept:
            assert copy.wait_mesh(mesh_id)["status"] == "ready"
        for mesh_id in kept - common:
            assert copy.client.delete(f"/meshes/{mesh_id}").status_code == 204
        assert _meshes(copy) == expected_meshes
        files = {i: copy.client.get(f"/meshes/{i}/file").content for i in common}
        assert files == expected_files
        assert _answers(copy, common) == expected_answers
    # The backed-up index (with the rows of its parts file) was loaded, not rebuilt.
    assert "index.parts" in manifest["files"]
    logs = "".join(path.read_text() for path in (tmp_path / "new" / "logs").glob("api-*.log"))
    assert "Application startup complete" in logs and "unusable" not in logs


def test_a_mesh_deleted_while_backing_up_is_left_out_whole(tmp_path):
    """Its file was gone when the copy reached it: the backup leaves out its rows too,
    as if it had been deleted just before."""
    settings = Settings(data_dir=tmp_path / "data")
    settings.data_dir.mkdir()
    upgrade_head(settings.sqlalchemy_url)
    with sqlite3.connect(settings.data_dir / "shapes.sqlite3") as db:
        for mesh_id, sha in ((1, "a" * 64), (2, "b" * 64)):
            db.execute(
                "INSERT INTO meshes (id, sha256, name, metadata, filename, size_bytes, "
                "storage_path, status, created_at, updated_at) VALUES "
                "(?, ?, 'm', '{}', 'm.off', 3, ?, 'queued', '2026-01-01', '2026-01-01')",
                (mesh_id, sha, f"{sha[:2]}/{sha}"),
            )
            db.execute(
                "INSERT INTO jobs (mesh_id, preset, preset_version, task_id, status, enqueues, "
                "created_at, updated_at) VALUES (?, 'p', 1, ?, 'queued', 1, '2026-01-01', "
                "'2026-01-01')",
                (mesh_id, sha),
            )
    kept = settings.uploads_dir / "aa" / ("a" * 64)
    kept.parent.mkdir(parents=True)
    kept.write_bytes(b"OFF")
    manifest = backup(settings, tmp_path / "backup")
    assert manifest["left_out"] == [2] and manifest["meshes"] == 1
    with sqlite3.connect(tmp_path / "backup" / "shapes.sqlite3") as db:
        assert db.execute("SELECT mesh_id FROM jobs").fetchall() == [(1,)]
    assert set(manifest["files"]) == {"shapes.sqlite3", f"uploads/aa/{'a' * 64}"}
