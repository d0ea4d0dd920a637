"""Durable jobs: a worker killed mid-job, and a restart with work still queued."""

from __future__ import annotations

import os
import signal
import time

from .conftest import TIMEOUT, Service


def _wait_processing(service: Service, job_id: int) -> dict:
    deadline = time.monotonic() + TIMEOUT
    while time.monotonic() < deadline:
        job = service.client.get(f"/jobs/{job_id}").json()
        if job["status"] != "queued":
            return job
        time.sleep(0.05)
    raise AssertionError("the job never started\n" + service.logs())


def test_worker_killed_mid_job_is_retried_after_a_new_worker_starts(service: Service, gallery):
    service.stop_workers("enroll")
    victim = service.start_worker()
    created = service.upload("centaur3", "centaur")
    assert created.status_code == 202
    body = created.json()

    job = _wait_processing(service, body["job_id"])
    assert job["status"] == "processing", job
    assert job["worker"].split("@")[0] == str(victim.pid)
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
    created = service.upload("wolf2", "wolf")  # queued; no worker is running
    assert created.status_code == 202
    mesh_id = created.json()["id"]
    service.stop_api()

    service.start_api()  # loads the saved index, re-checks unfinished jobs
    assert service.client.get(f"/meshes/{mesh_id}").json()["status"] == "queued"
    assert service.client.get("/ready").json()["checks"]["index"] == size_before
    service.start_worker()
    assert service.wait_mesh(mesh_id)["status"] == "ready"
    matches = service.client.post(f"/meshes/{mesh_id}/similar", params={"k": 2}).json()
    assert matches["matches"][0]["label"] == "wolf"
