"""End-to-end enrollment of all 83 TOSCA meshes through the HTTP API.

    python -m benchmarks.enroll                       # starts `python -m app` on a fresh data dir
    python -m benchmarks.enroll --url http://127.0.0.1:8000    # against a running service

Uploads every mesh (with its class label), polls ``GET /meshes`` until all are
ready or failed, and prints the total wall time (first upload to last ready),
the upload time, and per-mesh medians of the queue-to-ready time and of the
worker's descriptor time. Then it runs every mesh's ``/similar`` (top-1
nearest-neighbour accuracy by class) as a sanity check, waits for the fusion the gallery
learns from the labels, prints it fold by fold, and compares ``GET /calibration``'s EERs
with the engine's on the same files under the fusion in use.
"""

from __future__ import annotations

import argparse
import statistics
import time
from datetime import datetime
from typing import Any

import httpx
import numpy as np

from benchmarks.common import TOSCA, serving, tosca_descriptors, tosca_labels
from worker.engine.compare import fused_dissimilarity, preset_dissimilarity
from worker.engine.presets import get_preset, with_fusion
from worker.recognition.metrics import equal_error_rate


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
    compare_calibration(client, labels, ids)


def compare_calibration(client: httpx.Client, labels: dict[str, str], ids: dict[str, int]) -> None:
    """Wait for the gallery's fusion fit and calibration on every labelled mesh, print
    what the fit chose and why, and compare ``GET /calibration``'s EERs with the
    engine's on the same files: each modality by its comparison in use, and the fused
    score under the fusion in use (:func:`worker.engine.compare.fused_dissimilarity`)."""
    deadline = time.monotonic() + 600
    while True:
        live = client.get("/calibration").json()
        fusion = live["fusion"]
        # The calibration follows an adopted fusion at once; the comparison below shows
        # which fusion it calibrated.
        if fusion["labelled_shapes"] == len(ids) == live["labelled_shapes"]:
            break
        if time.monotonic() > deadline:
            raise TimeoutError(f"no fusion fit on all {len(ids)} meshes: {fusion['reason']}")
        time.sleep(1)
    print_fusion(fusion)
    preset = with_fusion(get_preset(live["preset"]), fusion["weights"], fusion["comparisons"])
    descriptors = tosca_descriptors(preset.name)
    names = sorted(ids)
    vectors = {
        m: np.stack([descriptors[n].vector(m) for n in names]) for m in preset.modality_sizes()
    }
    classes = [labels[n] for n in names]
    fused = fused_dissimilarity(vectors, vectors, preset)
    engine = {live["score"]: equal_error_rate(fused, classes)}
    for m in live["modalities"]:
        per = preset_dissimilarity(m, vectors[m], vectors[m], preset)
        engine[m] = equal_error_rate(per, classes)
    print(f"\n/calibration ({live['genuine_pairs']} genuine, {live['impostor_pairs']} impostor")
    print("pairs) against the engine's all-to-all scores of the same files:\n")
    print("| score | comparison | /calibration EER | engine EER | difference (points) |")
    print("|---|---|---:|---:|---:|")
    live_eers = {live["score"]: live["eer"]} | {m: c["eer"] for m, c in live["modalities"].items()}
    for name, eer in live_eers.items():
        how = preset.comparison(name) if name in live["modalities"] else "the fusion in use"
        print(
            f"| {name} | {how} | {eer:.2%} | {engine[name]:.2%} | "
            f"{100 * (eer - engine[name]):+.2f} |"
        )


def print_fusion(fusion: dict[str, Any]) -> None:
    """The fusion a gallery uses, its test against the preset's, and each fold's choice."""

    def weighed(weights: dict[str, float], comparisons: dict[str, str]) -> str:
        return ", ".join(f"{m} {w:g} ({comparisons[m]})" for m, w in weights.items())

    print(f"\nfusion: {fusion['source']}: {weighed(fusion['weights'], fusion['comparisons'])}")
    print(f"why: {fusion['reason']}\n")
    print("| fold | meshes | weights (comparison) | EER | mAP | preset's EER | preset's mAP |")
    print("|---|---:|---|---:|---:|---:|---:|")
    for i, fold in enumerate(fusion["folds"]):
        own, base = fold["held_out"], fold["preset"]
        print(
            f"| {i} | {fold['held_out_shapes']} | {weighed(fold['weights'], fold['comparisons'])}"
            f" | {own['eer']:.2%} | {own['map']:.1%} | {base['eer']:.2%} | {base['map']:.1%} |"
        )
    own, base = fusion["held_out"], fusion["preset_held_out"]
    print(
        f"| mean | | | {own['eer']:.2%} | {own['map']:.1%} | {base['eer']:.2%} | "
        f"{base['map']:.1%} |"
    )


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
