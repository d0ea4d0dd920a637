"""The API process killed -9 mid-upload, a corrupted or deleted index: nothing half-written,
nothing lost, the index agrees with the database, SQLite's integrity check passes.

(A worker killed mid-job and a restart with queued work: tests/service/test_service_faults.py.)
"""

from __future__ import annotations

import os
import signal
import sqlite3
import threading
import time
from collections.abc import Iterator

import httpx
import pytest

from benchmarks.common import Service

from .conftest import integrity_check, make_service


@pytest.fixture(scope="module")
def crashy(tmp_path_factory) -> Iterator[Service]:
    svc = make_service(tmp_path_factory, "crashy")
    try:
        svc.start_worker()
        svc.start_api()
        for name in ("quadruped-0", "quadruped-1"):
            created = svc.upload(name, "quadruped")
            assert svc.wait_mesh(created.json()["id"])["status"] == "ready"
        yield svc
    finally:
        svc.close()


def _db(service: Service, sql: str) -> list[tuple]:
    with sqlite3.connect(f"file:{service.data_dir / 'shapes.sqlite3'}?mode=ro", uri=True) as db:
        return db.execute(sql).fetchall()


def _kill_api(service: Service) -> None:
    assert service.api is not None
    os.kill(service.api.pid, signal.SIGKILL)
    service.api.wait()
    service.api = None


def _index_agrees_with_the_database(service: Service) -> None:
    ready = _db(service, "SELECT count(*) FROM descriptors")[0][0]
    assert (
        service.client.get("/ready").json()["checks"]["index"]
        == f"ok ({ready} shapes in 1 collection)"
    )
    statuses = {s for (s,) in _db(service, "SELECT status FROM meshes")}
    assert statuses <= {"queued", "processing", "ready", "failed"}
    assert integrity_check(service) == "ok"


def test_api_killed_mid_upload_leaves_nothing_half_written(crashy: Service):
    before = _db(crashy, "SELECT id, sha256, status FROM meshes ORDER BY id")
    started = threading.Event()

    def slow_body():
        yield b'--b\r\nContent-Disposition: form-data; name="file"; filename="slow.off"\r\n\r\n'
        yield b"OFF\n"
        started.set()
        for _ in range(200):
            time.sleep(0.05)
            yield b"0 0 0\n" * 100

    def upload() -> None:
        try:
            httpx.post(
                f"{crashy.url}/meshes",
                content=slow_body(),
                headers={"content-type": "multipart/form-data; boundary=b"},
                timeout=30,
            )
        except httpx.HTTPError:
            pass  # the server died under it: expected

    sender = threading.Thread(target=upload)
    sender.start()
    assert started.wait(10)
    time.sleep(0.5)
    assert list((crashy.data_dir / "tmp").glob("upload-*"))  # the upload was streaming
    _kill_api(crashy)
    sender.join(30)

    crashy.start_api()
    assert _db(crashy, "SELECT id, sha256, status FROM meshes ORDER BY id") == before
    assert not list((crashy.data_dir / "tmp").glob("upload-*"))  # leftover removed at start
    _index_agrees_with_the_database(crashy)


def test_api_killed_right_after_accepting_loses_no_upload(crashy: Service):
    created = crashy.upload("quadruped-2", "quadruped")
    assert created.status_code == 202
    _kill_api(crashy)
    crashy.start_api()
    mesh = crashy.wait_mesh(created.json()["id"])
    assert mesh["status"] == "ready", mesh
    _index_agrees_with_the_database(crashy)


@pytest.mark.parametrize("damage", ["corrupt", "delete"])
def test_a_damaged_index_is_rebuilt_from_the_database_at_start(crashy: Service, damage):
    crashy.stop_api()  # saves the index
    files = [p for p in (crashy.data_dir / "index").rglob("*") if p.is_file()]
    assert files
    for path in files:
        if damage == "corrupt":
            path.write_bytes(b"\x00garbage" * 64)
        else:
            path.unlink()
    crashy.start_api()
    _index_agrees_with_the_database(crashy)
    first = _db(crashy, "SELECT id FROM meshes WHERE name = 'quadruped-0'")[0][0]
    similar = crashy.client.post(f"/meshes/{first}/similar", params={"k": 1}).json()
    assert similar["matches"][0]["label"] == "quadruped"
