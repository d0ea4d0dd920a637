"""``python -m app``: the embedded deployment in one command.

Runs ``alembic upgrade head``, then starts the API (uvicorn, one process),
``SHAPES_WORKERS`` enrollment consumers and ``SHAPES_QUERY_WORKERS`` query consumers
(``python -m worker --queue ...``) as child processes, and stops them all
cleanly on Ctrl-C / SIGTERM: consumers get SIGINT (finish the running task), then
SIGTERM, then SIGKILL after a grace period. A consumer that dies is restarted.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import subprocess
import sys
import time
from types import FrameType

from pydantic import ValidationError

from .config import Settings, access_notice
from .migrations import upgrade_head

log = logging.getLogger("shapes.serve")

GRACE_SECONDS = 20.0


def _consumer_env(settings: Settings) -> dict[str, str]:
    env = dict(os.environ)
    env["SHAPES_DATA_DIR"] = str(settings.data_dir.resolve())
    # Several numpy processes on few cores: share the cores instead of oversubscribing.
    threads = str(max(1, (os.cpu_count() or 1) // max(settings.workers, 1)))
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, threads)
    return env


def _stop(processes: list[subprocess.Popen[bytes]], first_signal: int) -> None:
    for p in processes:
        if p.poll() is None:
            p.send_signal(first_signal)
    deadline = time.monotonic() + GRACE_SECONDS
    for p in processes:
        try:
            p.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.terminate()
    for p in processes:
        try:
            p.wait(5)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def serve(settings: Settings) -> int:
    try:
        notice = access_notice(settings)
    except ValueError as refusal:
        log.error("%s", refusal)
        return 2
    log.log(logging.WARNING if settings.api_key is None else logging.INFO, "%s", notice)
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    log.info("migrating %s", settings.sqlalchemy_url)
    upgrade_head(settings.sqlalchemy_url)
    env = _consumer_env(settings)

    def start_consumer(queue: str) -> subprocess.Popen[bytes]:
        return subprocess.Popen([sys.executable, "-m", "worker", "--queue", queue], env=env)

    queues = ["enroll"] * settings.workers + ["query"] * settings.query_workers
    consumers = [start_consumer(queue) for queue in queues]
    api_env = dict(os.environ, SHAPES_DATA_DIR=env["SHAPES_DATA_DIR"])
    # The API's numeric work is many small searches: BLAS threads only add
    # synchronisation (a refit took 3x longer with two threads on a busy machine).
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        api_env.setdefault(var, "1")
    api = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "uvicorn",
            "app.main:app",
            "--host",
            settings.host,
            "--port",
            str(settings.port),
            "--workers",
            "1",
            "--no-access-log",
        ],
        env=api_env,
    )
    stopping = {"signal": 0}

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        stopping["signal"] = signum

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    log.info(
        "serving on http://%s:%d with %d enrollment and %d query worker(s)",
        settings.host,
        settings.port,
        settings.workers,
        settings.query_workers,
    )
    code = 0
    while not stopping["signal"]:
        if api.poll() is not None:
            log.error("the API process exited with %s", api.returncode)
            code = api.returncode or 1
            break
        for i, p in enumerate(consumers):
            if p.poll() is not None:
                log.warning("worker %d exited with %s; restarting it", p.pid, p.returncode)
                consumers[i] = start_consumer(queues[i])
        time.sleep(0.5)
    # The API first (it stops taking requests and saves the index), then the workers.
    _stop([api], signal.SIGTERM)
    _stop(consumers, signal.SIGINT)
    return code


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m app", description=__doc__.splitlines()[0])
    parser.add_argument("--host", help="default SHAPES_HOST or 127.0.0.1")
    parser.add_argument("--port", type=int, help="default SHAPES_PORT or 8000")
    parser.add_argument(
        "--workers", type=int, help="enrollment consumers (default SHAPES_WORKERS or 2)"
    )
    parser.add_argument(
        "--query-workers", type=int, help="query consumers (default SHAPES_QUERY_WORKERS or 2)"
    )
    parser.add_argument("--data-dir", help="default SHAPES_DATA_DIR or ./data")
    args = parser.parse_args(argv)
    overrides = {
        k: v
        for k, v in {
            "host": args.host,
            "port": args.port,
            "workers": args.workers,
            "query_workers": args.query_workers,
            "data_dir": args.data_dir,
        }.items()
        if v is not None
    }
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        settings = Settings(**overrides)
    except ValidationError as refused:  # a setting out of its range: say which, and stop
        for error in refused.errors():
            message = str(error["msg"]).removeprefix("Value error, ")
            if error["loc"]:  # a field's own range (a check across fields names them)
                message = f"SHAPES_{str(error['loc'][0]).upper()}: {message}"
            log.error("%s", message)
        return 2
    return serve(settings)


if __name__ == "__main__":
    raise SystemExit(main())
