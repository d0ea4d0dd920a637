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
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from conftest import example
from sqlalchemy import create_engine, inspect, text

from app import models  # noqa: F401  (registers the tables on Base.metadata)
from app.db import Base
from app.migrations import alembic_config, upgrade_head
from benchmarks.common import TIMEOUT, Postgres, Redis, Service

pytestmark = [pytest.mark.scaleout, pytest.mark.service, pytest.mark.slow]

TABLES = {"meshes", "descriptors", "jobs", "previews", "gallery_changes", "uploads"}


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
        assert ready["checks"]["index"] == f"ok ({len(ids)} shapes)"
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
