"""The service on PostgreSQL and Redis (real servers): the migrations both ways;
enrollment, search and deletion surviving a worker and the Redis server killed
with -9 mid-work; outages of the queue and the database answered as the contract
says; and a fault drill under load."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator

import httpx
import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from conftest import example
from sqlalchemy import create_engine, inspect, text

from app import models  # noqa: F401  (registers the tables on Base.metadata)
from app.db import Base
from app.migrations import alembic_config, upgrade_head
from benchmarks.common import TIMEOUT, Postgres, Redis, Service, describing_children
from tests.service.conftest import assert_text_refused, nul_refusals
from worker.jobs.queue import FILE_GONE, make_huey
from worker.jobs.settings import QueueSettings
from worker.jobs.sources import database_source

pytestmark = [pytest.mark.scaleout, pytest.mark.service, pytest.mark.slow]

TABLES = {
    "meshes",
    "descriptors",
    "jobs",
    "previews",
    "query_previews",
    "gallery_changes",
    "uploads",
}


@pytest.fixture(scope="module")
def postgres() -> Iterator[Postgres]:
    server = Postgres().start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="module")
def redis_server() -> Iterator[Redis]:
    server = Redis().start()
    try:
        yield server
    finally:
        server.stop()


def _tables(url: str) -> set[str]:
    engine = create_engine(url)
    try:
        return set(inspect(engine).get_table_names())
    finally:
        engine.dispose()


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_the_migrations_upgrade_and_downgrade(backend: str, request, tmp_path):
    if backend == "sqlite":
        url = f"sqlite:///{tmp_path / 'shapes.sqlite3'}"
    else:
        url = request.getfixturevalue("postgres").url
    upgrade_head(url)
    assert TABLES <= _tables(url)
    assert _schema_differences(url) == []  # the migrations make the models' schema
    command.downgrade(alembic_config(url), "base")
    assert not TABLES & _tables(url)
    upgrade_head(url)
    assert TABLES <= _tables(url)


def _schema_differences(url: str) -> list:
    """What the migrated database lacks or has beyond the models (Alembic's comparison)."""
    engine = create_engine(url)
    try:
        with engine.connect() as connection:
            return compare_metadata(MigrationContext.configure(connection), Base.metadata)
    finally:
        engine.dispose()


def _descriptor_rows(url: str) -> int:
    engine = create_engine(url)
    try:
        with engine.connect() as connection:
            return int(connection.execute(text("select count(*) from descriptors")).scalar_one())
    finally:
        engine.dispose()


def _wait_all(service: Service, ids: list[int]) -> dict[int, dict]:
    deadline = time.monotonic() + 3 * TIMEOUT
    done: dict[int, dict] = {}
    while len(done) < len(ids):
        assert time.monotonic() < deadline, f"still waiting for {set(ids) - set(done)}"
        for mesh_id in set(ids) - set(done):
            body = service.client.get(f"/meshes/{mesh_id}").json()
            assert "status" in body, (mesh_id, body)
            if body["status"] in ("ready", "failed"):
                done[mesh_id] = body
        time.sleep(0.2)
    return done


def test_the_service_on_postgresql_and_redis_survives_kill_9(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    upgrade_head(postgres.url)
    service = Service(tmp_path / "data")
    service.env.update(SHAPES_DATABASE_URL=postgres.url, SHAPES_REDIS_URL=redis_server.url)
    try:
        victim = service.start_worker()
        service.start_worker("query")
        service.start_api()
        names = {
            "quadruped-0": "quadruped",
            "quadruped-1": "quadruped",
            "bird-0": "bird",
            "bird-1": "bird",
            "hand-0": "hand",
        }
        created = {name: service.upload(name, label) for name, label in names.items()}
        assert all(r.status_code == 202 for r in created.values()), created
        ids = [r.json()["id"] for r in created.values()]
        again = service.upload("quadruped-0", "quadruped")  # the same bytes: the same mesh
        assert again.status_code == 200
        assert again.json()["id"] == created["quadruped-0"].json()["id"]

        # A worker dies mid-job, then the Redis server, with jobs still queued.
        deadline = time.monotonic() + TIMEOUT
        while service.client.get("/meshes", params={"status": "processing"}).json()["total"] < 1:
            assert time.monotonic() < deadline, service.logs()
            time.sleep(0.05)
        os.kill(victim.pid, signal.SIGKILL)
        victim.wait()
        redis_server.kill()
        time.sleep(1.0)
        redis_server.start()
        service.start_worker()

        done = _wait_all(service, ids)
        assert all(body["status"] == "ready" for body in done.values()), done
        ready = service.client.get("/ready").json()
        assert ready["checks"]["index"] == f"ok ({len(ids)} shapes in 1 collection)"
        assert _descriptor_rows(postgres.url) == len(ids)

        answer = service.query("quadruped-2", k=2)
        assert answer.status_code == 200, answer.text
        assert [m["label"] for m in answer.json()["matches"]] == ["quadruped", "quadruped"]
        first = created["quadruped-0"].json()["id"]
        assert service.client.delete(f"/meshes/{first}").status_code == 204
        matches = service.query("quadruped-2", k=5).json()["matches"]
        assert first not in [m["mesh_id"] for m in matches]
        assert _descriptor_rows(postgres.url) == len(ids) - 1
    finally:
        service.close()


def _wait_index_size(service: Service, size: int) -> None:
    deadline = time.monotonic() + TIMEOUT
    while service.index_size() != size:
        assert time.monotonic() < deadline, f"index stuck at {service.index_size()}, not {size}"
        time.sleep(0.1)


def test_two_api_replicas_and_two_workers_share_nothing_but_the_servers(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    """Every process has its own data directory: uploads live in the database, and a
    shape enrolled through one replica is searched, downloaded and deleted through
    the other."""
    upgrade_head(postgres.url)
    shared = {
        "SHAPES_DATABASE_URL": postgres.url,
        "SHAPES_REDIS_URL": redis_server.url,
        "SHAPES_UPLOADS": "database",
    }
    a, b = Service(tmp_path / "api-a"), Service(tmp_path / "api-b")
    enroller, searcher = Service(tmp_path / "worker-1"), Service(tmp_path / "worker-2")
    for process in (a, b, enroller, searcher):
        process.env.update(shared)
    try:
        enroller.start_worker()
        searcher.start_worker("query")
        a.start_api()
        b.start_api()
        start = _descriptor_rows(postgres.url)  # what the other tests left
        names = {"biped-0": "biped", "biped-1": "biped", "spider-1": "spider"}
        ids = [a.upload(name, label).json()["id"] for name, label in names.items()]
        assert all(body["status"] == "ready" for body in _wait_all(a, ids).values())
        _wait_index_size(b, start + 3)  # stored by A's collector, followed by B
        matches = b.query("biped-2", k=2).json()["matches"]
        assert {m["mesh_id"] for m in matches} == set(ids[:2])
        original = example("spider-1").read_bytes()
        assert b.client.get(f"/meshes/{ids[2]}/file").content == original

        assert b.client.delete(f"/meshes/{ids[0]}").status_code == 204
        _wait_index_size(a, start + 2)
        assert ids[0] not in [m["mesh_id"] for m in a.query("biped-2", k=5).json()["matches"]]
        assert a.client.get(f"/meshes/{ids[0]}/file").status_code == 404
        rows = _descriptor_rows(postgres.url)
        assert a.index_size() == b.index_size() == rows == start + 2
        assert not list((tmp_path / "api-a").glob("uploads/*/*"))  # nothing on a disk
    finally:
        for process in (b, a, enroller, searcher):
            process.close()


# ------------------------------------------------------------------ fault drills
PARTIAL = "partial/quadruped-3-top-cut"  # bytes no test enrolls: a query needs a worker


def _unavailable(response: httpx.Response, code: str) -> None:
    """A dependency's outage as the contract says: 503, JSON, the code, Retry-After."""
    assert response.status_code == 503, response.text
    assert response.headers["content-type"] == "application/json", response.text
    assert response.json()["error"] == code, response.text
    assert int(response.headers["retry-after"]) > 0


def _scaled_out(
    postgres: Postgres, redis_server: Redis, root, *replicas: str, **env: str
) -> list[Service]:
    """API replicas and one process each for the two queues' workers, all sharing
    nothing but the servers (and ``env``); the last one returned runs the workers."""
    upgrade_head(postgres.url)
    shared = env | {
        "SHAPES_DATABASE_URL": postgres.url,
        "SHAPES_REDIS_URL": redis_server.url,
        "SHAPES_UPLOADS": "database",
        "SHAPES_SWEEP_INTERVAL_SECONDS": "2",
        "SHAPES_STALLED_AFTER_SECONDS": "8",
    }
    services = [Service(root / name) for name in (*replicas, "workers")]
    for service in services:
        service.env.update(shared)
    services[-1].start_worker()
    services[-1].start_worker("query")
    for api in services[:-1]:
        api.start_api()
    return services


def test_an_upload_during_a_queue_outage_is_described_once_it_is_back_without_a_restart(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    api, workers = _scaled_out(postgres, redis_server, tmp_path, "api")
    try:
        redis_server.kill()
        accepted = api.upload("spider-3", "spider")
        assert accepted.status_code == 202, accepted.text  # stored; queued once it is back
        _unavailable(api.query(PARTIAL), "queue_unavailable")
        ready = api.client.get("/ready")
        assert ready.status_code == 503 and ready.json()["checks"]["queue"].startswith("error")
        retried = api.upload("spider-3", "spider")  # the client's retry: the same mesh
        assert retried.json()["id"] == accepted.json()["id"]

        redis_server.start()
        back = time.monotonic()
        mesh = api.wait_mesh(accepted.json()["id"])
        assert mesh["status"] == "ready", mesh
        assert time.monotonic() - back < 30
        assert api.client.get("/ready").status_code == 200
    finally:
        api.close()
        workers.close()


def test_a_database_outage_answers_json_503s_and_loses_nothing(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    api, workers = _scaled_out(postgres, redis_server, tmp_path, "api")
    try:
        before = api.upload("hand-3", "hand")
        assert api.wait_mesh(before.json()["id"])["status"] == "ready"
        postgres.kill()
        _unavailable(api.upload("bird-3", "bird"), "database_unavailable")
        _unavailable(api.query("hand-3"), "database_unavailable")
        _unavailable(api.client.get("/meshes"), "database_unavailable")
        ready = api.client.get("/ready")
        assert ready.status_code == 503 and ready.json()["checks"]["database"].startswith("error")

        postgres.start()
        api.wait_ready()
        assert api.client.get(f"/meshes/{before.json()['id']}").json()["status"] == "ready"
        after = api.upload("bird-3", "bird")
        assert after.status_code == 202, after.text
        assert api.wait_mesh(after.json()["id"])["status"] == "ready"
    finally:
        api.close()
        workers.close()


#: The fault drill's bound on any answer while PostgreSQL is frozen (SIGSTOP).
FROZEN_ANSWER_SECONDS = 6.0


def test_a_frozen_database_answers_503_within_seconds_and_loses_nothing(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    """PostgreSQL stopped with SIGSTOP for 15 s (connections open, nothing answers, as a
    hung host) during uploads, queries, listings and readiness checks: every request
    answers within 6 s, a success or 503 + Retry-After naming the database, and every
    accepted upload is described once it thaws."""
    api, workers = _scaled_out(postgres, redis_server, tmp_path, "api")
    try:
        before = api.upload("hand-3", "hand")
        assert api.wait_mesh(before.json()["id"])["status"] == "ready"
        calls = {
            "upload": lambda: api.upload("bird-3", "bird"),
            "query": lambda: api.query("hand-3", k=1),
            "list": lambda: api.client.get("/meshes"),
            "ready": lambda: api.client.get("/ready"),
        }
        answers: list[tuple[str, httpx.Response, float]] = []
        postgres.freeze()
        try:
            frozen = time.monotonic()
            while time.monotonic() - frozen < 15:
                for name, call in calls.items():
                    started = time.monotonic()
                    answers.append((name, call(), time.monotonic() - started))
        finally:
            postgres.thaw()
        slow = [(n, r.status_code, round(t, 1)) for n, r, t in answers if t > FROZEN_ANSWER_SECONDS]
        assert slow == []
        for name, response, _ in answers:
            if response.status_code in (200, 202):
                continue
            if name == "ready":
                assert response.status_code == 503, response.text
                assert response.json()["checks"]["database"].startswith("error"), response.text
            else:
                _unavailable(response, "database_unavailable")
        refused = {n for n, r, _ in answers if r.status_code == 503}
        assert refused == set(calls), answers  # the freeze was felt by every kind of call

        api.wait_ready()
        accepted = {r.json()["id"] for n, r, _ in answers if n == "upload" and r.status_code < 300}
        for mesh_id in accepted | {before.json()["id"]}:
            assert api.wait_mesh(mesh_id)["status"] == "ready"
        after = api.upload("bird-3", "bird")
        assert after.status_code in (200, 202), after.text
        assert api.wait_mesh(after.json()["id"])["status"] == "ready"
    finally:
        api.close()
        workers.close()


def test_a_nul_character_is_refused_on_postgresql_and_the_connection_stays_usable(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    """PostgreSQL cannot store NUL (SQLite can): every text field refuses it alike, 422
    with a sentence, and the client's keep-alive connection serves the next request."""
    api, workers = _scaled_out(postgres, redis_server, tmp_path, "api")
    try:
        before = api.client.get("/meshes").json()["total"]
        assert_text_refused(nul_refusals(api))
        listed = api.client.get("/meshes")  # on the same keep-alive connection
        assert listed.status_code == 200 and listed.json()["total"] == before
    finally:
        api.close()
        workers.close()


ADMIN = "admin-key-of-the-scale-out-tests"


def _keyed(api: Service, key: str) -> httpx.Client:
    return httpx.Client(base_url=api.url, timeout=TIMEOUT, headers={"X-API-Key": key})


def _post_mesh(client: httpx.Client, path: str, name: str, **data: str) -> httpx.Response:
    mesh = example(name)
    return client.post(path, files={"file": (mesh.name, mesh.read_bytes())}, data=data)


def test_a_collections_links_serve_its_own_key_and_nothing_of_it_reaches_another(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    """Every link an answer in collection c1 gives works with the c1 key that got it and
    is refused to a c2 key; through c2 nothing of c1 is readable or detectable: a c1
    preview's sha256, a c1 job's id or c1's bytes as a query answer in c2 exactly as
    bytes and ids that exist nowhere do."""
    api, workers = _scaled_out(postgres, redis_server, tmp_path, "api", SHAPES_API_KEY=ADMIN)
    admin = _keyed(api, ADMIN)
    try:
        keys = {}
        for name in ("c1", "c2"):
            assert admin.post("/collections", json={"name": name}).status_code == 201
            made = admin.post("/keys", json={"collection": name, "scope": "write"})
            keys[name] = _keyed(api, made.json()["key"])
        c1, c2 = keys["c1"], keys["c2"]

        enrolled = _post_mesh(c1, "/collections/c1/meshes", "hand-0", label="hand")
        assert enrolled.status_code == 202, enrolled.text
        mesh = enrolled.json()
        deadline = time.monotonic() + 3 * TIMEOUT
        while c1.get(mesh["links"]["self"]).json()["status"] != "ready":
            assert time.monotonic() < deadline
            time.sleep(0.2)
        links = [link for link in mesh["links"].values() if link]
        for name in ("hand-0", PARTIAL):  # enrolled bytes, and bytes a worker describes
            answer = _post_mesh(c1, "/collections/c1/query", name, k="1")
            assert answer.status_code == 200, answer.text
            links.append(answer.json()["preview"])
        similar = c1.post(f"{mesh['links']['self']}/similar", params={"k": "1"})
        links.append(similar.json()["preview"])
        job = c1.get(mesh["links"]["job"]).json()
        links += list(job["links"].values())

        for link in links:
            method = "POST" if link.endswith("/similar") else "GET"  # the one POST link
            assert c1.request(method, link).status_code == 200, link
            assert c2.request(method, link).status_code in (403, 404), link

        # Through c2: c1's previews, job and bytes answer as if they did not exist.
        nowhere = "0" * 64
        missing = c2.get(f"/collections/c2/previews/{nowhere}")
        assert missing.status_code == 404
        for link in links:
            if "/previews/" in link:
                sha = link.rsplit("/", 1)[1]
                probed = c2.get(f"/collections/c2/previews/{sha}")
                assert (probed.status_code, probed.json()) == (404, missing.json())
        job_probe, no_job = c2.get(f"/jobs/{job['id']}"), c2.get("/jobs/999999")
        assert job_probe.status_code == no_job.status_code == 404
        assert job_probe.json()["error"] == no_job.json()["error"]
        asked = _post_mesh(c2, "/collections/c2/query", "hand-0", k="1").json()
        never = _post_mesh(c2, "/collections/c2/query", "hand-1", k="1").json()
        assert asked["descriptor_source"] == never["descriptor_source"] == "computed"
    finally:
        admin.close()
        api.close()
        workers.close()


def test_a_mesh_deleted_before_a_worker_read_it_is_a_plain_outcome_in_the_log(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    """Uploads in the database, a task whose upload row is gone by the time a worker
    reads it (its mesh deleted after the worker took the task, too late to revoke it):
    the worker answers that outcome, says so in one line, no traceback."""
    api, workers = _scaled_out(postgres, redis_server, tmp_path, "api")
    try:
        settings = QueueSettings(
            data_dir=tmp_path, redis_url=redis_server.url, database_url=postgres.url
        )
        task = make_huey(settings).describe_upload(
            database_source("0" * 64), "gone.off.gz", "smeets2010-surface", 10_000
        )
        assert task.get(blocking=True, timeout=TIMEOUT)["code"] == FILE_GONE
        logs = workers.logs()
        assert "its mesh was deleted before it was described" in logs, logs
        assert "Traceback" not in logs, logs
    finally:
        api.close()
        workers.close()


def test_a_query_preview_link_works_on_every_replica(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    a, b, workers = _scaled_out(postgres, redis_server, tmp_path, "api-a", "api-b")
    try:
        answer = a.query(PARTIAL, k=1)
        assert answer.status_code == 200, answer.text
        link = answer.json()["preview"]
        for replica in (a, b):
            preview = replica.client.get(link)
            assert preview.status_code == 200, preview.text
            assert preview.content[:4] == b"glTF"
    finally:
        for process in (b, a, workers):
            process.close()


class _Load:
    """A bounded mixed load on the replicas (uploads, queries, deletes) in a thread,
    keeping every response; a connection refused (a replica being killed) is kept
    apart, as the balancer in front would send that request elsewhere."""

    def __init__(self, replicas: list[Service], names: list[str]) -> None:
        self.replicas, self.names = replicas, names
        self.responses: list[httpx.Response] = []
        self.refused = 0
        self.accepted: dict[int, str] = {}  # mesh id -> name, of every 200/202 upload
        self.deleted: set[int] = set()  # ids a delete was sent for
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> _Load:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self._thread.join(TIMEOUT)

    def _send(self, step: int, make) -> httpx.Response | None:
        replica = self.replicas[step % len(self.replicas)]
        try:
            response: httpx.Response = make(replica)
        except httpx.TransportError:
            self.refused += 1
            return None
        self.responses.append(response)
        return response

    def _run(self) -> None:
        for step in range(10_000):
            if self._stop.is_set():
                return
            name = self.names[step % len(self.names)]
            upload = self._send(step, lambda r, name=name: r.upload(name, name.split("-")[0]))
            if upload is not None and upload.status_code in (200, 202):
                self.accepted[upload.json()["id"]] = name
            query = PARTIAL if step % 2 else "biped-0"
            self._send(step + 1, lambda r, query=query: r.query(query, k=3))
            if step % 5 == 4 and self.accepted:
                victim = max(self.accepted)
                path = f"/meshes/{victim}"
                # Asked: gone once answered 204, or if the answer was lost on the way.
                self.deleted.add(victim)
                self._send(step, lambda r, path=path: r.client.delete(path))
            self._stop.wait(0.2)

    def unexplained_errors(self) -> list[str]:
        """Every 5xx that is not a JSON body with an error code."""
        return [
            f"{r.request.method} {r.request.url.path}: {r.status_code} {r.text[:200]}"
            for r in self.responses
            if r.status_code >= 500
            and not (r.headers.get("content-type") == "application/json" and "error" in r.json())
        ]


def test_fault_drill_under_load_every_upload_ends_true_and_every_error_is_json(
    postgres: Postgres, redis_server: Redis, tmp_path
):
    """Redis, PostgreSQL, a worker, a describing child and an API replica, each killed
    and brought back under a mixed load: afterwards every accepted upload is ready,
    both replicas' indexes equal the descriptor rows, and no answer was a non-JSON 5xx."""
    a, b, workers = _scaled_out(postgres, redis_server, tmp_path, "api-a", "api-b")
    names = [f"{kind}-{pose}" for pose in range(4) for kind in ("biped", "bird", "spider")]
    try:
        with _Load([a, b], names) as load:
            time.sleep(2)
            redis_server.kill()
            time.sleep(3)
            redis_server.start()
            time.sleep(2)
            postgres.kill()
            time.sleep(3)
            postgres.start()
            time.sleep(2)
            children = describing_children(workers, TIMEOUT)
            for child in children:
                os.kill(child, signal.SIGKILL)
            (consumer,) = workers.workers["enroll"]
            os.kill(consumer.pid, signal.SIGKILL)
            consumer.wait()
            workers.workers["enroll"] = []
            workers.start_worker()
            assert b.api is not None
            os.kill(b.api.pid, signal.SIGKILL)
            b.api.wait()
            b.start_api()
            time.sleep(2)
        assert children
        live = [mesh_id for mesh_id in load.accepted if mesh_id not in load.deleted]
        for mesh_id in load.deleted:  # deleted, or (the delete refused) still there
            assert a.client.get(f"/meshes/{mesh_id}").status_code in (200, 404)
        done = _wait_all(a, live)
        failed = {i: (m["error"], m["detail"]) for i, m in done.items() if m["status"] != "ready"}
        assert not failed, failed
        assert load.unexplained_errors() == []
        outages = {r.json()["error"] for r in load.responses if r.status_code == 503}
        assert "database_unavailable" in outages, outages  # the load met the outage
        assert len(load.responses) > 20 and load.refused < len(load.responses)
        rows = _descriptor_rows(postgres.url)
        _wait_index_size(a, rows)
        _wait_index_size(b, rows)
    finally:
        for process in (b, a, workers):
            process.close()
