"""Durable jobs: a worker killed mid-job, a restart with work still queued, and a
restart on a database described by the previous version of the preset."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import time

from benchmarks.common import TIMEOUT, Service
from worker.engine.presets import DEFAULT_PRESET, get_preset

from .conftest import migrated_service, running


def _frozen_mid_job(service: Service, worker: subprocess.Popen[bytes], name: str) -> dict:
    """Enroll ``name`` and freeze ``worker`` (SIGSTOP) while it describes the mesh: the
    upload's body, with the job seen ``processing`` after the freeze.

    A mesh is described in about a second, so a loaded machine may finish the job
    between two looks; then the mesh is deleted and sent again (at most 3 times)."""
    for _ in range(3):
        created = service.upload(name, "biped")
        assert created.status_code == 202, created.text
        body = created.json()
        deadline = time.monotonic() + TIMEOUT
        status = "queued"
        while status == "queued" and time.monotonic() < deadline:
            status = service.client.get(f"/jobs/{body['job_id']}").json()["status"]
        if status == "processing":
            os.kill(worker.pid, signal.SIGSTOP)
            job = service.client.get(f"/jobs/{body['job_id']}").json()
            if job["status"] == "processing":
                return body | {"job": job}
            os.kill(worker.pid, signal.SIGCONT)
        assert status != "queued", "the job never started\n" + service.logs()
        service.wait_mesh(body["id"])
        assert service.client.delete(f"/meshes/{body['id']}").status_code == 204
    raise AssertionError(f"{name} was described three times before it was seen processing")


def test_worker_killed_mid_job_is_retried_after_a_new_worker_starts(service: Service, gallery):
    service.stop_workers("enroll")
    victim = service.start_worker()
    body = _frozen_mid_job(service, victim, "biped-3")

    assert body["job"]["worker"].split("@")[0] == str(victim.pid)
    assert service.client.get(f"/meshes/{body['id']}").json()["status"] == "processing"
    os.kill(victim.pid, signal.SIGKILL)
    victim.wait()

    service.start_worker()
    done = service.wait_mesh(body["id"])
    assert done["status"] == "ready", done
    job = service.client.get(f"/jobs/{body['job_id']}").json()
    assert job["status"] == "succeeded"
    assert job["enqueues"] == 2  # re-enqueued once its heartbeat went stale
    assert job["worker"].split("@")[0] != str(victim.pid)


def test_restart_loses_nothing_queued_and_reloads_the_index(service: Service, gallery):
    size_before = service.client.get("/ready").json()["checks"]["index"]
    service.stop_workers("enroll")
    created = service.upload("quadruped-2", "quadruped")  # queued; no worker is running
    assert created.status_code == 202
    mesh_id = created.json()["id"]
    service.stop_api()

    service.start_api()  # loads the saved index, re-checks unfinished jobs
    assert service.client.get(f"/meshes/{mesh_id}").json()["status"] == "queued"
    assert service.client.get("/ready").json()["checks"]["index"] == size_before
    service.start_worker()
    assert service.wait_mesh(mesh_id)["status"] == "ready"
    matches = service.client.post(f"/meshes/{mesh_id}/similar", params={"k": 2}).json()
    assert matches["matches"][0]["label"] == "quadruped"


def test_a_new_preset_version_describes_every_stored_mesh_again(tmp_path_factory):
    """Deploying a new version of the default preset (as v3 -> v4) over the data of
    the previous one: the service queues every mesh without a descriptor of the
    current version, rebuilds the index from the new descriptors and answers as before."""
    version = get_preset(DEFAULT_PRESET).version
    with running(migrated_service(tmp_path_factory, "older-version"), workers=1) as svc:
        ids = {}
        for name, label in (("quadruped-0", "quadruped"), ("biped-0", "biped")):
            ids[name] = svc.upload(name, label).json()["id"]
            assert svc.wait_mesh(ids[name])["status"] == "ready"
        svc.stop_api()
        # What the previous version left: its descriptors, its jobs and its index.
        with sqlite3.connect(svc.data_dir / "shapes.sqlite3") as db:
            db.execute("UPDATE descriptors SET preset_version = preset_version - 1")
            db.execute("UPDATE jobs SET preset_version = preset_version - 1")
        index = svc.data_dir / "index"
        current = index / f"{DEFAULT_PRESET}-v{version}"
        current.rename(index / f"{DEFAULT_PRESET}-v{version - 1}")

        svc.start_api()
        # /ready says how far the describing has come (the worker may be done already).
        progress = svc.client.get("/ready").json()["descriptors"]
        assert progress["preset"] == f"{DEFAULT_PRESET} v{version}"
        assert progress["enrolled"] == 2 and 0 <= progress["described"] <= 2
        deadline = time.monotonic() + TIMEOUT
        for mesh_id in ids.values():
            while True:
                body = svc.client.get(f"/meshes/{mesh_id}").json()
                described = (body.get("descriptor") or {}).get("preset_version")
                if body["status"] == "ready" and described == version:
                    break
                assert body["status"] != "failed" and time.monotonic() < deadline, body
                time.sleep(0.2)
        ready = svc.client.get("/ready").json()
        assert ready["checks"]["index"] == "ok (2 shapes in 1 collection)"
        assert ready["descriptors"]["described"] == ready["descriptors"]["enrolled"] == 2
        matches = svc.query("quadruped-1", k=2).json()["matches"]
        assert [m["label"] for m in matches] == ["quadruped", "biped"]


def _fail_as(service: Service, mesh_id: int, code: str) -> None:
    """Mark the mesh and its job failed with ``code``, as the collector would."""
    with sqlite3.connect(service.data_dir / "shapes.sqlite3") as db:
        for table, key in (("meshes", "id"), ("jobs", "mesh_id")):
            db.execute(
                f"UPDATE {table} SET status = 'failed', error_code = ?, error_detail = ? "
                f"WHERE {key} = ?",
                (code, "as the drill left it.", mesh_id),
            )


def test_the_same_bytes_again_describe_a_mesh_that_failed_for_a_transient_reason(
    service: Service, gallery
):
    first = service.upload("spider-2", "spider").json()
    assert service.wait_mesh(first["id"])["status"] == "ready"
    _fail_as(service, first["id"], "describe_crashed")  # says nothing about the file
    again = service.upload("spider-2", "spider")
    assert again.status_code == 202, again.text
    assert again.json()["id"] == first["id"] and again.json()["job_id"] != first["job_id"]
    assert service.wait_mesh(first["id"])["status"] == "ready"

    _fail_as(service, first["id"], "unreadable_mesh")  # the file's own fault: the same again
    refused = service.upload("spider-2", "spider")
    assert refused.status_code == 200 and refused.json()["status"] == "failed"
    assert refused.json()["job_id"] == again.json()["job_id"]
