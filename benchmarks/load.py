"""Load: 16 clients enrolling and querying concurrently against a running service.

    python -m benchmarks.load --url http://127.0.0.1:8000 --clients 16 --seconds 60

Loopback only, bounded in time (``--seconds``, at most 600) and in requests
(``--max-requests``); it stops by itself. Each client loops: with probability
``--enroll-fraction`` it uploads a TOSCA mesh made unique by a trailing
comment (so it is a new enrollment with a real descriptor job), otherwise it
queries with a TOSCA mesh. Prints throughput, p50/p95/p99 latency of
``POST /query`` and ``POST /meshes``, the error count (any status other than
200/202) and the search step's latency (``timings.search`` of each answer).
The meshes it enrolled are deleted at the end unless ``--keep``.
"""

from __future__ import annotations

import argparse
import asyncio
import gzip
import random
import sys
import time
import uuid
from collections import Counter
from urllib.parse import urlparse

import httpx

from benchmarks.common import TOSCA


def percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100 * (len(ordered) - 1))))]


class Load:
    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.files = sorted(TOSCA.glob("*.off.gz"))
        self.raw = {p: gzip.decompress(p.read_bytes()) for p in self.files}
        self.latency: dict[str, list[float]] = {"query": [], "enroll": []}
        self.search: list[float] = []
        self.errors: Counter[str] = Counter()
        self.enrolled: list[int] = []
        self.requests = 0

    async def client(self, http: httpx.AsyncClient, seed: int, deadline: float) -> None:
        rng = random.Random(seed)
        while time.monotonic() < deadline and self.requests < self.args.max_requests:
            self.requests += 1
            path = rng.choice(self.files)
            enroll = rng.random() < self.args.enroll_fraction
            if enroll:  # new bytes: a real enrollment, not the idempotent 200
                data = gzip.compress(self.raw[path] + f"# load {uuid.uuid4().hex}\n".encode(), 1)
                url, kind, fields = "/meshes", "enroll", {"label": "load"}
            else:
                data, url, kind, fields = path.read_bytes(), "/query", "query", {"k": "5"}
            started = time.perf_counter()
            try:
                response = await http.post(url, files={"file": (path.name, data)}, data=fields)
            except httpx.HTTPError as exc:
                self.errors[f"{kind} {type(exc).__name__}"] += 1
                continue
            self.latency[kind].append(time.perf_counter() - started)
            if response.status_code not in (200, 202):
                self.errors[f"{kind} {response.status_code} {response.text[:80]}"] += 1
            elif kind == "query":
                self.search.append(response.json()["timings"]["search"])
            else:
                self.enrolled.append(response.json()["id"])

    async def run(self) -> float:
        timeout = httpx.Timeout(self.args.seconds + 180)
        limits = httpx.Limits(max_connections=self.args.clients)
        async with httpx.AsyncClient(
            base_url=self.args.url, timeout=timeout, limits=limits
        ) as http:
            started = time.monotonic()
            deadline = started + self.args.seconds
            await asyncio.gather(
                *(self.client(http, i, deadline) for i in range(self.args.clients))
            )
            elapsed = time.monotonic() - started
            if not self.args.keep:
                for mesh_id in self.enrolled:
                    await http.delete(f"/meshes/{mesh_id}")
        return elapsed

    def report(self, elapsed: float) -> None:
        done = sum(len(v) for v in self.latency.values())
        print(f"\n{self.args.clients} clients, {elapsed:.1f} s, {done} requests answered, "
              f"{done / elapsed:.2f} req/s, errors: {sum(self.errors.values())}\n")  # fmt: skip
        print("| request | count | req/s | p50 ms | p95 ms | p99 ms | max ms |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        rows = [("POST /query", self.latency["query"]), ("POST /meshes", self.latency["enroll"]),
                ("search step (timings.search)", self.search)]  # fmt: skip
        for name, values in rows:
            ms = [v * 1000 for v in values]
            print(f"| {name} | {len(ms)} | {len(ms) / elapsed:.2f} | {percentile(ms, 50):.1f} | "
                  f"{percentile(ms, 95):.1f} | {percentile(ms, 99):.1f} | "
                  f"{max(ms, default=float('nan')):.1f} |")  # fmt: skip
        for error, count in self.errors.most_common():
            print(f"error x{count}: {error}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="http://127.0.0.1:8000")
    parser.add_argument("--clients", type=int, default=16)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--max-requests", type=int, default=20_000)
    parser.add_argument("--enroll-fraction", type=float, default=0.25)
    parser.add_argument("--keep", action="store_true", help="keep the meshes it enrolled")
    args = parser.parse_args(argv)
    if urlparse(args.url).hostname not in ("127.0.0.1", "localhost", "::1"):
        parser.error("the load test runs against a loopback address only")
    if not 0 < args.seconds <= 600 or not 1 <= args.clients <= 64:
        parser.error("--seconds must be in (0, 600] and --clients in [1, 64]")
    load = Load(args)
    elapsed = asyncio.run(load.run())
    load.report(elapsed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
