"""The operator's fault drill, with real PostgreSQL and Redis, at the service's defaults.

    python -m benchmarks.fault_drill [--outage 20]

Starts a real PostgreSQL and redis-server (:mod:`benchmarks.common`), two API replicas
on them with uploads in the database, one enrollment and one query worker, each with
its own data directory and the default heartbeat and stall settings. Then: Redis is
killed for ``--outage`` seconds while a mesh is uploaded, a query sent and ``/ready``
asked; the time from Redis's return to the mesh being ready (no restart) is measured;
a query's preview link is fetched from both replicas; a malformed OFF file is sent as
a query and enrolled; and a describing child process is killed with SIGKILL mid-job.
Prints what each step answered.
"""

from __future__ import annotations

import argparse
import os
import signal
import tempfile
import time
from pathlib import Path

from app.migrations import upgrade_head
from benchmarks.common import Postgres, Redis, Service, describing_children

MALFORMED_OFF = b"OFF\n3 1 0\nx 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
PARTIAL = "partial/quadruped-3-top-cut"


def drill(root: Path, outage: float) -> list[tuple[str, str]]:
    postgres, redis = Postgres().start(), Redis().start()
    upgrade_head(postgres.url)
    shared = {"SHAPES_DATABASE_URL": postgres.url, "SHAPES_REDIS_URL": redis.url}
    a, b, workers = (Service(root / name) for name in ("api-a", "api-b", "workers"))
    for process in (a, b, workers):
        process.env.update(shared, SHAPES_UPLOADS="database")
        for test_setting in ("SHAPES_STALLED_AFTER_SECONDS", "SHAPES_HEARTBEAT_SECONDS"):
            process.env.pop(test_setting)  # the defaults, as an operator runs it
    rows: list[tuple[str, str]] = []
    try:
        workers.start_worker()
        workers.start_worker("query")
        a.start_api()
        b.start_api()

        redis.kill()
        down = time.monotonic()
        upload = a.upload("spider-3", "spider")
        rows.append(
            ("upload while Redis is down", f"{upload.status_code}, {upload.json()['status']}")
        )
        query = a.query("biped-3")
        rows.append(
            (
                "query while Redis is down",
                f"{query.status_code} Retry-After {query.headers.get('retry-after')} "
                f"{query.json()['error']}",
            )
        )
        ready = a.client.get("/ready")
        rows.append(("/ready while Redis is down", f"{ready.status_code} {ready.json()['checks']}"))
        time.sleep(max(0.0, outage - (time.monotonic() - down)))
        redis.start()
        back = time.monotonic()
        mesh = a.wait_mesh(upload.json()["id"])
        rows.append(
            (
                f"that upload, after a {back - down:.0f} s outage",
                f"{mesh['status']} {time.monotonic() - back:.1f} s after Redis returned, "
                "no restart",
            )
        )

        link = a.query(PARTIAL, k=1).json()["preview"]
        rows.append(
            (
                "a query's preview link",
                f"replica A {a.client.get(link).status_code}, "
                f"replica B {b.client.get(link).status_code}",
            )
        )

        bad = a.client.post("/query", files={"file": ("bad.off", MALFORMED_OFF)})
        rows.append(("malformed OFF as a query", f"{bad.status_code} {bad.json()['error']}"))
        enrolled = a.client.post("/meshes", files={"file": ("bad.off", MALFORMED_OFF)}).json()
        failed = a.wait_mesh(enrolled["id"])
        rows.append(("malformed OFF enrolled", f"{failed['status']} {failed['error']}"))

        upload = a.upload("bird-3", "bird")
        children = describing_children(workers, 60.0)
        for child in children:
            os.kill(child, signal.SIGKILL)
        mesh = a.wait_mesh(upload.json()["id"])
        job = a.client.get(f"/jobs/{mesh['job_id']}").json()
        rows.append(
            (
                "describing child killed (SIGKILL)",
                f"{len(children)} killed; mesh {mesh['status']}, job {job['status']}",
            )
        )
    finally:
        for process in (b, a, workers):
            process.close()
        postgres.stop()
        redis.stop()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outage", type=float, default=20.0, help="seconds Redis is down")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="shapes-drill-") as root:
        rows = drill(Path(root), args.outage)
    print("| step | answer |\n|---|---|")
    for step, answer in rows:
        print(f"| {step} | {answer} |")


if __name__ == "__main__":
    main()
