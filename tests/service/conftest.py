"""A real service for the tests: uvicorn and Huey consumer processes on a temporary data dir.

The database is created by ``alembic upgrade head`` (so the migrations are
tested), the API runs in its own process on a free loopback port, and the
descriptor jobs run in real ``python -m worker`` processes that tests may
kill and restart (:class:`benchmarks.common.Service`, which the benchmarks run too).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import httpx
import pytest

from app.migrations import upgrade_head
from benchmarks.common import Service


def migrated_service(tmp_path_factory, name: str, **env: str) -> Service:
    """A service (not started) on a fresh data dir whose database Alembic built."""
    data_dir = tmp_path_factory.mktemp(name)
    upgrade_head(f"sqlite:///{data_dir / 'shapes.sqlite3'}")
    svc = Service(data_dir)
    svc.env.update(env)
    return svc


@contextmanager
def running(svc: Service, workers: int = 2) -> Iterator[Service]:
    """Start ``workers`` enrollment consumers, one query consumer and the API; stop them
    all on exit."""
    try:
        for _ in range(workers):
            svc.start_worker()
        svc.start_worker("query")
        svc.start_api()
        yield svc
    finally:
        svc.close()


@pytest.fixture(scope="session")
def service(tmp_path_factory) -> Iterator[Service]:
    with running(migrated_service(tmp_path_factory, "shapes-data")) as svc:
        yield svc


GALLERY = {
    "quadruped-0": "quadruped",
    "quadruped-1": "quadruped",
    "biped-0": "biped",
    "biped-1": "biped",
    "hand-0": "hand",
    "hand-1": "hand",
}


@pytest.fixture(scope="session")
def gallery(service: Service) -> dict[str, int]:
    """A small gallery of the bundled examples, enrolled and ready: name -> mesh id."""
    ids = {}
    for name, label in GALLERY.items():
        response = service.upload(name, label, metadata='{"source": "examples"}')
        assert response.status_code in (200, 202), response.text
        ids[name] = response.json()["id"]
    for name, mesh_id in ids.items():
        body = service.wait_mesh(mesh_id)
        assert body["status"] == "ready", (name, body)
    return ids


def nul_refusals(svc: Service) -> list[httpx.Response]:
    """Every kind of text the service keeps or looks up, sent with a NUL character: a
    label, a name, a listing's label and a verification's claimed label."""
    path = svc.meshes / "hand-3.off.gz"
    named = svc.client.post(
        "/meshes", files={"file": (path.name, path.read_bytes())}, data={"name": "x\x00y"}
    )
    return [
        svc.upload("hand-3", "a\x00b"),
        named,
        svc.client.get("/meshes", params={"label": "a\x00b"}),
        svc.client.post(
            "/verify",
            files={"file": (path.name, path.read_bytes())},
            data={"claim_label": "a\x00b"},
        ),
    ]


def assert_text_refused(responses: list[httpx.Response]) -> None:
    for response in responses:
        assert response.status_code == 422, response.text
        assert response.json()["error"] == "invalid_text", response.text
        assert "NUL" in response.json()["detail"]
