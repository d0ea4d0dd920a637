"""A search that waits seconds for its descriptor holds no database lock: enrollments
(and other requests that write) go on meanwhile."""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

from benchmarks.common import TIMEOUT, Service
from worker.jobs.queue import make_huey
from worker.jobs.settings import QueueSettings


def _wait_queued_query(service: Service) -> None:
    queries = make_huey(QueueSettings(data_dir=service.data_dir), "query")
    deadline = time.monotonic() + TIMEOUT
    while queries.pending_count() == 0:
        assert time.monotonic() < deadline, "the query never reached the queue\n" + service.logs()
        time.sleep(0.05)


def test_an_enrollment_is_not_held_up_by_a_query_waiting_for_its_descriptor(
    service: Service, gallery
):
    service.stop_workers("query")
    with ThreadPoolExecutor(1) as pool:
        waiting = pool.submit(service.query, "bird-0", k=1)
        _wait_queued_query(service)  # the query is inside its request, waiting for a worker
        created = service.upload("bird-1", "bird")
        assert created.status_code == 202, created.text
        assert not waiting.done()  # answered while the query still waited
        service.start_worker("query")
        answer = waiting.result(TIMEOUT)
    assert answer.status_code == 200, answer.text
    mesh_id = created.json()["id"]
    assert service.wait_mesh(mesh_id)["status"] == "ready"
    assert service.client.delete(f"/meshes/{mesh_id}").status_code == 204
