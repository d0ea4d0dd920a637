"""Descriptor jobs run under a time and a memory limit and fail with a sentence, not a crash."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.service.conftest import TOSCA, Service
from worker.engine.pipeline import ShapeDescriptor
from worker.jobs.limits import describe_limited

from .conftest import make_service

WOLF = TOSCA / "wolf0.off.gz"
GB = 1024**3


def test_within_the_limits_the_descriptor_comes_back():
    npz, code, _ = describe_limited(
        WOLF,
        WOLF.name,
        "smeets2010-shrec",
        max_faces=10**6,
        time_limit=120,
        memory_limit_bytes=4 * GB,
    )
    assert code is None and ShapeDescriptor.from_npz_bytes(npz).vertices > 2000


def test_over_the_time_limit_the_job_fails_with_a_sentence():
    npz, code, sentence = describe_limited(
        WOLF, WOLF.name, "smeets2010-shrec", max_faces=10**6, time_limit=0.5, memory_limit_bytes=0
    )
    assert npz is None and code == "describe_timeout"
    assert "longer than this service's limit of 0.5 seconds" in sentence


def test_over_the_memory_limit_the_job_fails_with_a_sentence():
    npz, code, sentence = describe_limited(
        WOLF, WOLF.name, "smeets2010-shrec", max_faces=10**6, time_limit=120,
        memory_limit_bytes=300 * 1024**2,
    )  # fmt: skip
    assert npz is None and code == "describe_out_of_memory", (code, sentence)
    assert "300 MB" in sentence


def test_a_mesh_error_keeps_its_code_and_a_crash_is_raised_for_a_retry():
    npz, code, sentence = describe_limited(
        WOLF, WOLF.name, "smeets2010-shrec", max_faces=10, time_limit=30, memory_limit_bytes=0
    )
    assert code == "too_many_faces" and "the limit is 10" in sentence
    with pytest.raises(RuntimeError, match="FileNotFoundError"):
        describe_limited(
            TOSCA / "missing.off.gz", "m.off.gz", "smeets2010-shrec", max_faces=10,
            time_limit=30, memory_limit_bytes=0,
        )  # fmt: skip


@pytest.fixture(scope="module")
def limited(tmp_path_factory) -> Iterator[Service]:
    svc = make_service(tmp_path_factory, "limited", SHAPES_JOB_TIME_LIMIT_SECONDS="1")
    try:
        svc.start_worker()
        svc.start_api()
        yield svc
    finally:
        svc.close()


def test_a_job_over_its_limit_fails_and_the_worker_lives_on(limited: Service):
    worker = limited.workers[0]
    created = limited.upload("wolf0", "wolf")
    mesh = limited.wait_mesh(created.json()["id"])
    assert mesh["status"] == "failed" and mesh["error"] == "describe_timeout", mesh
    assert "1 seconds" in mesh["detail"]
    job = limited.client.get(mesh["links"]["job"]).json()
    assert job["enqueues"] == 1  # not retried
    query = limited.query("wolf1")
    assert query.status_code == 422 and query.json()["error"] == "describe_timeout"
    assert worker.poll() is None  # the same worker process is still serving
