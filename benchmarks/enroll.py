"""End-to-end enrollment of all 83 TOSCA meshes through the HTTP API.

    python -m benchmarks.enroll                       # starts `python -m app` on a fresh data dir
    python -m benchmarks.enroll --url http://127.0.0.1:8000    # against a running service

Uploads every mesh (with its class label), polls ``GET /meshes`` until all are
ready or failed, and prints the total wall time (first upload to last ready),
the upload time, and per-mesh medians of the queue-to-ready time and of the
worker's descriptor time. Then it runs every mesh's ``/similar`` (top-1
nearest-neighbour accuracy by class) as a sanity check, and compares
``GET /calibration``'s EER with the recorded ``shapes evaluate`` report.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from datetime import datetime

import httpx

from benchmarks.common import REPO, TOSCA, serving, tosca_labels


def run(url: str) -> None:
    labels = tosca_labels()
    client = httpx.Client(base_url=url, timeout=120)
    start = time.perf_counter()
    ids = {}
    for name, label in sorted(labels.items()):
        with open(TOSCA / name, "rb") as fh:
            response = client.post("/meshes", files={"file": (name, fh)}, data={"label": label})
        response.raise_for_status()
        ids[name] = response.json()["id"]
    uploaded = time.perf_counter() - start
    pending = set(ids.values())
    rows = {}
    while pending:
        time.sleep(0.5)
        offset = 0
        while True:
            page = client.get("/meshes", params={"limit": 200, "offset": offset}).json()
            for mesh in page["items"]:
                if mesh["id"] in pending and mesh["status"] in ("ready", "failed"):
                    pending.discard(mesh["id"])
                    rows[mesh["id"]] = mesh
            offset += page["limit"]
            if offset >= page["total"]:
                break
    total = time.perf_counter() - start
    failed = [m for m in rows.values() if m["status"] == "failed"]
    latency, describe = [], []
    for mesh in rows.values():
        if mesh["status"] != "ready":
            continue
        job = client.get(mesh["links"]["job"]).json()
        created = datetime.fromisoformat(job["created_at"])
        finished = datetime.fromisoformat(job["finished_at"])
        latency.append((finished - created).total_seconds())
        describe.append(mesh["descriptor"]["timings"]["total"])
    correct = 0
    search = []
    for name, mesh_id in ids.items():
        body = client.post(f"/meshes/{mesh_id}/similar", params={"k": 1}).json()
        correct += body["matches"][0]["label"] == labels[name]
        search.append(body["timings"]["search"])
    print(f"meshes: {len(ids)} ready: {len(rows) - len(failed)} failed: {len(failed)}")
    print(f"upload all: {uploaded:.1f} s")
    print(f"total wall time (first upload -> last ready): {total:.1f} s")
    print(f"per mesh, median queue-to-ready: {statistics.median(latency):.1f} s")
    print(f"per mesh, median descriptor time in the worker: {statistics.median(describe):.2f} s")
    print(f"throughput: {len(ids) / total * 60:.1f} meshes/min")
    print(f"/similar top-1 class accuracy: {correct}/{len(ids)}")
    print(f"/similar search step, median: {statistics.median(search) * 1000:.2f} ms")
    compare_calibration(client)


def compare_calibration(client: httpx.Client) -> None:
    """``GET /calibration``'s EER beside ``shapes evaluate``'s recorded report for the
    same preset (issue 11: the live endpoint and the offline report agree)."""
    live = client.get("/calibration").json()
    report_path = REPO / "docs" / "evaluation" / live["preset"] / "report.json"
    if not report_path.is_file():
        print(f"no recorded report at {report_path}: EER not compared")
        return
    rows = json.loads(report_path.read_text())["rows"]
    print(f"\n/calibration ({live['genuine_pairs']} genuine, {live['impostor_pairs']} impostor")
    print(f"pairs) against {report_path.relative_to(REPO)}:\n")
    print("| score | /calibration EER | report EER | difference (points) |")
    print("|---|---:|---:|---:|")
    live_eers = {live["score"]: live["eer"]} | {m: c["eer"] for m, c in live["modalities"].items()}
    for name, eer in live_eers.items():
        recorded = rows[name]["eer"]
        print(f"| {name} | {eer:.2%} | {recorded:.2%} | {100 * (eer - recorded):+.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", help="a running service (default: start one)")
    parser.add_argument(
        "--workers", type=int, help="enrollment consumers (default: the service's, 2)"
    )
    parser.add_argument("--port", type=int, default=8765)
    args = parser.parse_args()
    if args.url:
        run(args.url)
        return
    with serving(args.port, args.workers) as url:
        shown = "" if args.workers is None else f" --workers {args.workers}"
        print(f"service: python -m app{shown} (fresh data dir)")
        run(url)


if __name__ == "__main__":
    main()
