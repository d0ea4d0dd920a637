"""The service on PostgreSQL and Redis (real servers): the migrations both ways, and
enrollment, search and deletion surviving a worker and the Redis server killed
with -9 mid-work."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator

import pytest
from alembic import command
from sqlalchemy import create_engine, inspect, text

from app.migrations import alembic_config, upgrade_head

from .conftest import TIMEOUT, Service
from .servers import Postgres, Redis

pytestmark = [pytest.mark.scaleout, pytest.mark.service, pytest.mark.slow]

TABLES = {"meshes", "descriptors", "jobs", "previews"}


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


def test_the_migrations_upgrade_and_downgrade_on_postgresql(postgres: Postgres):
    upgrade_head(postgres.url)
    assert TABLES <= _tables(postgres.url)
    command.downgrade(alembic_config(postgres.url), "base")
    assert not TABLES & _tables(postgres.url)
    upgrade_head(postgres.url)
    assert TABLES <= _tables(postgres.url)


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
        names = {"wolf0": "wolf", "wolf1": "wolf", "cat0": "cat", "cat1": "cat", "horse0": "horse"}
        created = {name: service.upload(name, label) for name, label in names.items()}
        assert all(r.status_code == 202 for r in created.values()), created
        ids = [r.json()["id"] for r in created.values()]
        again = service.upload("wolf0", "wolf")  # the same bytes: the same mesh
        assert again.status_code == 200 and again.json()["id"] == created["wolf0"].json()["id"]

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
        assert ready["checks"]["index"] == f"ok ({len(ids)} shapes)"
        assert _descriptor_rows(postgres.url) == len(ids)

        answer = service.query("wolf2", k=2)
        assert answer.status_code == 200, answer.text
        assert [m["label"] for m in answer.json()["matches"]] == ["wolf", "wolf"]
        wolf0 = created["wolf0"].json()["id"]
        assert service.client.delete(f"/meshes/{wolf0}").status_code == 204
        matches = service.query("wolf2", k=5).json()["matches"]
        assert wolf0 not in [m["mesh_id"] for m in matches]
        assert _descriptor_rows(postgres.url) == len(ids) - 1
    finally:
        service.close()
