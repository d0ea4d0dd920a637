"""How long API replica B takes to see what was enrolled or deleted through replica A.

    python bench/replica_lag.py [--meshes 10]

Starts a real PostgreSQL and redis-server (the scale-out tests' servers,
``tests/service/servers.py``), two API processes on them with uploads in the
database, one enrollment and one query worker. Then, one mesh at a time: enroll
through A, poll A until the mesh is ready and B (every 10 ms) until its index has
one more shape; then delete each through B and poll A until it has one fewer.
Prints the median and maximum lag over the meshes, with the collector interval
they run with (the design bound: a replica applies the change log once per round).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.migrations import upgrade_head  # noqa: E402
from bench._tosca import tosca_labels  # noqa: E402
from tests.service.conftest import Service  # noqa: E402
from tests.service.servers import Postgres, Redis  # noqa: E402

POLL = 0.01


def index_size(service: Service) -> int:
    check = service.client.get("/ready").json()["checks"]["index"]
    return int(check.removeprefix("ok (").split()[0])


def wait(condition, timeout: float = 120.0) -> float:
    """Poll ``condition`` until true; the time it became true."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError
        time.sleep(POLL)
    return time.monotonic()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", type=int, default=10)
    args = parser.parse_args()
    labels = tosca_labels()
    names = [n.removesuffix(".off.gz") for n in sorted(labels)][:: 83 // args.meshes][: args.meshes]
    postgres, redis_server = Postgres().start(), Redis().start()
    processes: list[Service] = []
    try:
        upgrade_head(postgres.url)
        with tempfile.TemporaryDirectory(prefix="shapes-lag-") as tmp:
            env = {
                "SHAPES_DATABASE_URL": postgres.url,
                "SHAPES_REDIS_URL": redis_server.url,
                "SHAPES_UPLOADS": "database",
                "SHAPES_COLLECTOR_INTERVAL_SECONDS": "0.5",  # the service's defaults
                "SHAPES_MAX_UPLOAD_BYTES": str(64 * 1024 * 1024),
            }
            a, b, workers = (Service(Path(tmp) / d) for d in ("a", "b", "workers"))
            processes = [a, b, workers]
            for process in processes:
                process.env.update(env)
            workers.start_worker()
            workers.start_worker("query")
            a.start_api()
            b.start_api()
            added, removed, ids = [], [], []
            for name in names:
                before = index_size(b)
                mesh_id = a.upload(name, labels[f"{name}.off.gz"]).json()["id"]
                ids.append(mesh_id)
                url = f"/meshes/{mesh_id}"
                on_a = wait(lambda u=url: a.client.get(u).json()["status"] == "ready")
                on_b = wait(lambda n=before: index_size(b) == n + 1)
                added.append(on_b - on_a)
            for mesh_id in ids:
                before = index_size(a)
                start = time.monotonic()
                b.client.delete(f"/meshes/{mesh_id}")
                removed.append(wait(lambda n=before: index_size(a) == n - 1) - start)
    finally:
        for process in processes:
            process.close()
        redis_server.stop()
        postgres.stop()
    print(f"{len(names)} meshes; collector interval 0.5 s; polled every {POLL * 1000:.0f} ms\n")
    print("| change | median s | max s |")
    print("|---|---:|---:|")
    print(
        f"| enrolled through A (ready on A) -> in B's index | {statistics.median(added):.2f} | "
        f"{max(added):.2f} |"
    )
    print(
        f"| deleted through B (request sent) -> out of A's index | "
        f"{statistics.median(removed):.2f} | {max(removed):.2f} |"
    )


if __name__ == "__main__":
    main()
