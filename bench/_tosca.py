"""Describe the TOSCA meshes once and cache the descriptors (shared by the benchmarks)."""

from __future__ import annotations

import csv
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from worker.engine.pipeline import ShapeDescriptor, describe_file
from worker.engine.presets import get_preset
from worker.evaluation.datasets import shared_dataset

REPO = Path(__file__).resolve().parents[1]
TOSCA = shared_dataset("tosca")
CACHE = REPO / ".cache" / "tosca-descriptors"


def tosca_labels() -> dict[str, str]:
    """File name -> class, from ``labels.csv``."""
    with open(TOSCA / "labels.csv", newline="") as fh:
        return {row["file"]: row["class"] for row in csv.DictReader(fh)}


def _describe(args: tuple[str, str]) -> tuple[str, bytes]:
    name, preset_name = args
    return name, describe_file(TOSCA / name, get_preset(preset_name)).to_npz_bytes()


def tosca_descriptors(preset_name: str, workers: int = 2) -> dict[str, ShapeDescriptor]:
    """Descriptors of all TOSCA meshes under ``preset_name`` (computed once, then cached)."""
    preset = get_preset(preset_name)
    cache = CACHE / f"{preset.name}-v{preset.version}"
    cache.mkdir(parents=True, exist_ok=True)
    names = sorted(tosca_labels())
    missing = [n for n in names if not (cache / f"{n}.npz").exists()]
    if missing:
        with ProcessPoolExecutor(workers) as pool:
            for name, blob in pool.map(_describe, [(n, preset_name) for n in missing]):
                (cache / f"{name}.npz").write_bytes(blob)
    return {n: ShapeDescriptor.from_npz_bytes((cache / f"{n}.npz").read_bytes()) for n in names}


if __name__ == "__main__":
    import sys

    for preset_name in sys.argv[1:] or ["smeets2010-shrec"]:
        print(preset_name, len(tosca_descriptors(preset_name)))
