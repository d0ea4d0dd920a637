"""Query latency on an idle service and during a bulk enrollment, side by side.

    python -m benchmarks.query_under_load [--gallery 20] [--bulk 332] [--clients 4] [--queries 12]

Starts ``python -m app`` (its default consumers: two enrollment workers and two
query workers) on a fresh data directory, enrolls a small TOSCA gallery and waits
for it, then:

1. idle, one client: ``--queries`` queries one after the other;
2. idle, ``--clients`` concurrent clients sending ``--queries`` queries each;
3. under load: starts uploading ``--bulk`` enrollments (TOSCA files with a new time in
   their gzip header, so every upload is new work) and, once 20 are queued, the same
   concurrent clients again, while the uploads arrive (the service parses and stores
   each) and are described;
4. once every upload is accepted, the same clients again while the workers describe
   the queued enrollments (the longest part of a bulk import).

Every query sends bytes the service has not seen (a TOSCA file that is not
enrolled, with a new gzip header), so each one is described by a worker, none
answered from a stored or recent descriptor. Prints the latency table (median, p95,
max; the median time waiting for a worker and describing), the ratio of each p95 to
the one-client idle median, the ratio of each loaded p95 to the same clients' idle p95
(what enrollment adds), and how many enrollments were still queued when the last
query answered (the load was real throughout).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import itertools
import statistics
import struct
import threading
import time
from typing import NamedTuple

import httpx

from benchmarks.common import TOSCA, serving, tosca_labels

_variant = itertools.count(1)
GZIP_MAGIC = b"\x1f\x8b"
FHCRC = 0x02


def fresh_bytes(name: str) -> bytes:
    """The file with a new modification time in its gzip header: new bytes (a new
    sha256), the same compressed mesh.

    The header is patched rather than the mesh re-compressed: ``gzip.compress`` of one
    TOSCA file costs this client about 0.5 s of CPU, as much as describing it, and
    the client runs on the cores it measures. TOSCA's files set no header CRC
    (``FHCRC``), so bytes 4-7 (``MTIME``) are free to change.
    """
    data = (TOSCA / name).read_bytes()
    if data[:2] != GZIP_MAGIC or data[3] & FHCRC:
        raise SystemExit(f"{name}: not a gzip file without a header CRC")
    return data[:4] + struct.pack("<I", next(_variant)) + data[8:]


class Timing(NamedTuple):
    """One query, in seconds: the client's wall time, and the parts of it."""

    total: float  # request sent -> answer read, at the client
    waiting: float  # queued, the worker's sandbox and preview, the result's way back
    describing: float  # load, resample and descriptor, in the worker


def timed_query(client: httpx.Client, name: str) -> Timing:
    data = fresh_bytes(name)
    start = time.perf_counter()
    response = client.post("/query", files={"file": (name, data)}, data={"k": "5"})
    elapsed = time.perf_counter() - start
    body = response.json()
    if response.status_code != 200 or body["descriptor_source"] != "computed":
        raise RuntimeError(f"query of {name}: {response.status_code} {response.text[:200]}")
    timings = body["timings"]
    return Timing(elapsed, timings["describe_wall"] - timings["total"], timings["total"])


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q * (len(ordered) - 1))))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gallery", type=int, default=20)
    parser.add_argument("--bulk", type=int, default=332)
    parser.add_argument("--clients", type=int, default=4)
    parser.add_argument("--queries", type=int, default=12)
    parser.add_argument("--port", type=int, default=8142)
    args = parser.parse_args()

    labels = tosca_labels()
    names = sorted(labels)
    gallery = names[:: len(names) // args.gallery][: args.gallery]
    probes = [n for n in names if n not in gallery]
    stop = threading.Event()
    with serving(args.port) as url:
        try:
            client = httpx.Client(base_url=url, timeout=300)
            ids = [
                client.post(
                    "/meshes",
                    files={"file": (n, (TOSCA / n).read_bytes())},
                    data={"label": labels[n]},
                ).json()["id"]
                for n in gallery
            ]
            while client.get("/meshes", params={"status": "ready"}).json()["total"] < len(ids):
                time.sleep(0.5)

            idle = [timed_query(client, probes[i % len(probes)]) for i in range(args.queries)]

            def one_client(c: int) -> list[Timing]:
                with httpx.Client(base_url=url, timeout=300) as own:
                    return [
                        timed_query(own, probes[(c * args.queries + i) % len(probes)])
                        for i in range(args.queries)
                    ]

            def concurrent_clients() -> list[Timing]:
                with concurrent.futures.ThreadPoolExecutor(args.clients) as pool:
                    return [t for ts in pool.map(one_client, range(args.clients)) for t in ts]

            idle_concurrent = concurrent_clients()

            def enroll_bulk() -> None:
                with httpx.Client(base_url=url, timeout=300) as bulk:
                    for i in range(args.bulk):
                        if stop.is_set():
                            return
                        name = names[i % len(names)]
                        bulk.post(
                            "/meshes",
                            files={"file": (name, fresh_bytes(name))},
                            data={"label": labels[name]},
                        )

            uploader = threading.Thread(target=enroll_bulk, daemon=True)
            uploader.start()
            # Let the enrollment queue fill before measuring.
            while client.get("/meshes", params={"status": "queued"}).json()["total"] < 20:
                time.sleep(0.5)

            loaded = concurrent_clients()
            uploader.join()  # every upload accepted: from here on the workers describe them
            described = concurrent_clients()
            queued = client.get("/meshes", params={"status": "queued"}).json()["total"]
            processing = client.get("/meshes", params={"status": "processing"}).json()["total"]
        finally:
            stop.set()

    base = statistics.median(t.total for t in idle)
    print(
        f"{args.gallery} meshes enrolled; queries of fresh bytes (k=5); bulk enrollment "
        f"of {args.bulk} uploads; {args.clients} concurrent query clients\n"
    )
    print(
        "| | queries | median s | p95 s | max s | p95 / idle median "
        "| median waiting s | median describing s |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    rows = (
        ("idle, one client", idle),
        (f"idle, {args.clients} clients", idle_concurrent),
        (f"during bulk enrollment, uploads arriving, {args.clients} clients", loaded),
        (f"during bulk enrollment, all uploaded, {args.clients} clients", described),
    )
    for title, timings in rows:
        values = [t.total for t in timings]
        print(
            f"| {title} | {len(values)} | {statistics.median(values):.2f} | "
            f"{percentile(values, 0.95):.2f} | {max(values):.2f} | "
            f"{percentile(values, 0.95) / base:.2f} | "
            f"{statistics.median(t.waiting for t in timings):.2f} | "
            f"{statistics.median(t.describing for t in timings):.2f} |"
        )
    idle_p95 = percentile([t.total for t in idle_concurrent], 0.95)
    for title, timings in rows[2:]:
        print(
            f"\n{title}: p95 over the same clients' p95 on the idle service: "
            f"{percentile([t.total for t in timings], 0.95) / idle_p95:.2f}",
            end="",
        )
    print(
        f"\n\nwhen the last query answered: {queued} enrollments still queued, "
        f"{processing} being described"
    )


if __name__ == "__main__":
    main()
