"""A real service for the tests: uvicorn and Huey consumer processes on a temporary data dir.

The database is created by ``alembic upgrade head`` (so the migrations are
tested), the API runs in its own process on a free loopback port, and the
descriptor jobs run in real ``python -m worker`` processes that tests may
kill and restart.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest
from conftest import example

from app.migrations import upgrade_head

REPO = Path(__file__).resolve().parents[2]
TIMEOUT = 120.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Service:
    """The API process, its worker processes and an HTTP client."""

    def __init__(self, data_dir: Path) -> None:
        self.data_dir = data_dir
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.env = dict(
            os.environ,
            SHAPES_DATA_DIR=str(data_dir),
            SHAPES_HEARTBEAT_SECONDS="1",
            # Long enough that a slow job on a loaded CI machine never looks dead.
            SHAPES_STALLED_AFTER_SECONDS="15",
            SHAPES_COLLECTOR_INTERVAL_SECONDS="0.2",
            SHAPES_MAX_UPLOAD_BYTES=str(1_000_000),
            SHAPES_QUERY_TIMEOUT_SECONDS="90",
            OMP_NUM_THREADS="1",
            OPENBLAS_NUM_THREADS="1",
        )
        self.api: subprocess.Popen | None = None
        self.workers: dict[str, list[subprocess.Popen]] = {"enroll": [], "query": []}
        self.client = httpx.Client(base_url=self.url, timeout=TIMEOUT)
        self._logs = data_dir / "logs"
        self._logs.mkdir(parents=True, exist_ok=True)

    def _spawn(self, args: list[str], name: str) -> subprocess.Popen:
        log = open(self._logs / f"{name}-{time.monotonic_ns()}.log", "wb")  # noqa: SIM115
        return subprocess.Popen(
            [sys.executable, *args], cwd=REPO, env=self.env, stdout=log, stderr=subprocess.STDOUT
        )

    def start_api(self) -> None:
        self.api = self._spawn(
            ["-m", "uvicorn", "app.main:app", "--host", "127.0.0.1", "--port", str(self.port)],
            "api",
        )
        self.wait_ready()

    def wait_ready(self) -> None:
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            assert self.api is not None and self.api.poll() is None, self.logs()
            try:
                if self.client.get("/ready").status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.2)
        raise AssertionError("the API did not become ready\n" + self.logs())

    def stop_api(self) -> None:
        if self.api is not None and self.api.poll() is None:
            self.api.send_signal(signal.SIGTERM)
            self.api.wait(60)
        self.api = None

    def start_worker(self, queue: str = "enroll") -> subprocess.Popen:
        """A ``python -m worker`` consumer of the enrollment or the query queue."""
        worker = self._spawn(["-m", "worker", "--queue", queue], f"worker-{queue}")
        self.workers[queue].append(worker)
        return worker

    def stop_workers(self, queue: str | None = None) -> None:
        """Stop the consumers of ``queue`` (default: all), gracefully (SIGINT)."""
        stopping = [w for q, ws in self.workers.items() if queue in (None, q) for w in ws]
        for worker in stopping:
            if worker.poll() is None:
                worker.send_signal(signal.SIGINT)
        for worker in stopping:
            try:
                worker.wait(60)
            except subprocess.TimeoutExpired:
                worker.kill()
                worker.wait()
        for q in self.workers:
            if queue in (None, q):
                self.workers[q] = []

    def logs(self) -> str:
        out = []
        for path in sorted(self._logs.glob("*.log")):
            out.append(f"--- {path.name}\n{path.read_text(errors='replace')[-3000:]}")
        return "\n".join(out)

    # -- helpers ----------------------------------------------------------
    def upload(self, name: str, label: str | None = None, **fields) -> httpx.Response:
        """Enroll the bundled example ``name`` (e.g. ``"quadruped-0"``)."""
        path = example(name)
        data = {k: v for k, v in {"label": label, **fields}.items() if v is not None}
        with open(path, "rb") as fh:
            return self.client.post("/meshes", files={"file": (path.name, fh)}, data=data)

    def wait_mesh(self, mesh_id: int, statuses=("ready", "failed")) -> dict:
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            body = self.client.get(f"/meshes/{mesh_id}").json()
            if body["status"] in statuses:
                return body
            time.sleep(0.2)
        raise AssertionError(f"mesh {mesh_id} stuck at {body['status']}\n" + self.logs())

    def query(self, name: str, **fields) -> httpx.Response:
        """Search with the bundled example ``name``."""
        path = example(name)
        with open(path, "rb") as fh:
            return self.client.post(
                "/query",
                files={"file": (path.name, fh)},
                data={k: str(v) for k, v in fields.items()},
            )

    def close(self) -> None:
        self.stop_api()
        self.stop_workers()
        self.client.close()


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
