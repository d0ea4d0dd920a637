"""A job over its limit fails with a sentence and the worker lives on (the limits themselves:
tests/jobs/test_limits.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from benchmarks.common import Service

from .conftest import make_service


@pytest.fixture(scope="module")
def limited(tmp_path_factory) -> Iterator[Service]:
    svc = make_service(tmp_path_factory, "limited", SHAPES_JOB_TIME_LIMIT_SECONDS="0.1")
    try:
        svc.start_worker()
        svc.start_worker("query")
        svc.start_api()
        yield svc
    finally:
        svc.close()


def test_a_job_over_its_limit_fails_and_the_worker_lives_on(limited: Service):
    worker = limited.workers["enroll"][0]
    created = limited.upload("quadruped-0", "quadruped")
    mesh = limited.wait_mesh(created.json()["id"])
    assert mesh["status"] == "failed" and mesh["error"] == "describe_timeout", mesh
    assert "limit of 0.1 seconds" in mesh["detail"]
    job = limited.client.get(mesh["links"]["job"]).json()
    assert job["enqueues"] == 1  # not retried
    query = limited.query("quadruped-1")
    assert query.status_code == 422 and query.json()["error"] == "describe_timeout"
    assert worker.poll() is None  # the same worker process is still serving
