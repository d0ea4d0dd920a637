"""``python -m app``: migrations, API and a worker as children, clean stop."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import httpx
import pytest

from benchmarks.common import REPO, free_port

pytestmark = [pytest.mark.service, pytest.mark.slow]  # runs python -m app itself


def test_serve_starts_api_and_worker_and_stops_cleanly(tmp_path):
    port = free_port()
    log = open(tmp_path / "serve.log", "wb")  # noqa: SIM115
    serve = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "app",
            "--port",
            str(port),
            "--workers",
            "1",
            "--data-dir",
            str(tmp_path / "data"),
        ],
        cwd=REPO,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.monotonic() + 120
        ready = None
        while time.monotonic() < deadline and serve.poll() is None:
            try:
                ready = httpx.get(f"http://127.0.0.1:{port}/ready", timeout=5)
                if ready.status_code == 200:
                    break
            except httpx.TransportError:
                pass
            time.sleep(0.3)
        assert ready is not None and ready.status_code == 200, (tmp_path / "serve.log").read_text()
        assert (tmp_path / "data" / "shapes.sqlite3").exists()
        assert (tmp_path / "data" / "queue.sqlite3").exists()
        children = subprocess.run(
            ["ps", "-o", "pid=,args=", "--ppid", str(serve.pid)],
            capture_output=True,
            text=True,
            check=False,
        ).stdout
        assert "uvicorn" in children and "-m worker" in children
    finally:
        serve.send_signal(signal.SIGTERM)
        code = serve.wait(60)
        log.close()
    assert code == 0, (tmp_path / "serve.log").read_text()
    left = subprocess.run(
        ["ps", "-o", "pid=", "--ppid", str(serve.pid)], capture_output=True, text=True, check=False
    ).stdout
    assert not left.strip()
