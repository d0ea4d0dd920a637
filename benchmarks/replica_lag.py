"""How long API replica B takes to see what was enrolled or deleted through replica A.

    python -m benchmarks.replica_lag [--meshes 10]

Starts a real PostgreSQL and redis-server (the scale-out tests' throwaway servers,
:mod:`benchmarks.common`), two API processes on them with uploads in the database, one
enrollment and one query worker. Then, one mesh at a time: enroll through A, poll A
until the mesh is ready and B (every 10 ms) until its index has one more shape; then,
once A's own index holds every enrolled mesh, delete each through B and poll A until
its index has one fewer. Prints the median and maximum lag over the meshes, with the
collector interval they run with (the design bound: a replica applies the change log
once per round).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from app.migrations import upgrade_head
from benchmarks.common import TOSCA, Postgres, Redis, Service, tosca_labels

POLL = 0.01
#: The service's default: a replica applies the change log once per round.
COLLECTOR_INTERVAL = 0.5


def wait(condition: Callable[[], bool], timeout: float = 120.0) -> float:
    """Poll ``condition`` until true; the time it became true."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError
        time.sleep(POLL)
    return time.monotonic()


def is_ready(service: Service, mesh_id: int) -> Callable[[], bool]:
    """Whether ``service`` says the mesh is ready (its database's word)."""
    return lambda: bool(service.client.get(f"/meshes/{mesh_id}").json()["status"] == "ready")


def holds(service: Service, size: int) -> Callable[[], bool]:
    """Whether ``service``'s own index holds ``size`` shapes."""
    return lambda: service.index_size() == size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", type=int, default=10)
    args = parser.parse_args()
    labels = tosca_labels()
    names = [n.removesuffix(".off.gz") for n in sorted(labels)][:: 83 // args.meshes][: args.meshes]
    postgres, redis_server = Postgres().start(), Redis().start()
    processes: list[Service] = []
    added: list[float] = []
    removed: list[float] = []
    try:
        upgrade_head(postgres.url)
        with tempfile.TemporaryDirectory(prefix="shapes-lag-") as tmp:
            env = {
                "SHAPES_DATABASE_URL": postgres.url,
                "SHAPES_REDIS_URL": redis_server.url,
                "SHAPES_UPLOADS": "database",
                "SHAPES_COLLECTOR_INTERVAL_SECONDS": str(COLLECTOR_INTERVAL),
                "SHAPES_MAX_UPLOAD_BYTES": str(64 * 1024 * 1024),
            }
            a, b, workers = (Service(Path(tmp) / d, TOSCA) for d in ("a", "b", "workers"))
            processes = [a, b, workers]
            for process in processes:
                process.env.update(env)
            workers.start_worker()
            workers.start_worker("query")
            a.start_api()
            b.start_api()
            ids = []
            for name in names:
                before = b.index_size()
                mesh_id = a.upload(name, labels[f"{name}.off.gz"]).json()["id"]
                ids.append(mesh_id)
                on_a = wait(is_ready(a, mesh_id))
                on_b = wait(holds(b, before + 1))
                added.append(on_b - on_a)
            # "Ready" is the database's word: the last mesh enters A's index when a
            # collector or change-log round of A's gets to it. A delete timed from before
            # that round lands in the same round as the add, and A's index never shows
            # one fewer.
            wait(holds(a, len(ids)))
            for mesh_id in ids:
                before = a.index_size()
                start = time.monotonic()
                b.client.delete(f"/meshes/{mesh_id}")
                removed.append(wait(holds(a, before - 1)) - start)
    finally:
        for process in processes:
            process.close()
        redis_server.stop()
        postgres.stop()
    print(
        f"{len(names)} meshes; collector interval {COLLECTOR_INTERVAL} s; "
        f"polled every {POLL * 1000:.0f} ms\n"
    )
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
