"""The TOSCA meshes for the benchmarks: labels, and descriptors described once and cached
(in the benchmarks' own cache, or in the evaluation cache that ``shapes evaluate`` fills)."""

from __future__ import annotations

import argparse
import csv
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from worker.engine.descriptor import ShapeDescriptor
from worker.engine.pipeline import describe_file
from worker.engine.presets import DEFAULT_PRESET, Preset, get_preset
from worker.evaluation.compute import ComputedSet, compute_descriptors
from worker.evaluation.datasets import DEFAULT_CACHE, read_labels, shared_dataset

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


def add_evaluation_cache_arguments(parser: argparse.ArgumentParser) -> None:
    """``--preset``, ``--cache`` (the evaluation cache) and ``--jobs``."""
    parser.add_argument("--preset", default=DEFAULT_PRESET)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--jobs", type=int, default=2)


def evaluated_tosca(args: argparse.Namespace) -> tuple[Preset, ComputedSet]:
    """The TOSCA meshes described under ``args.preset`` through the evaluation cache
    (seconds after ``shapes evaluate`` has run with the same cache)."""
    preset = get_preset(args.preset)
    meshes = read_labels(TOSCA / "labels.csv", TOSCA)
    return preset, compute_descriptors(meshes, preset, args.cache, jobs=args.jobs)


if __name__ == "__main__":
    import sys

    for preset_name in sys.argv[1:] or ["smeets2010-shrec"]:
        print(preset_name, len(tosca_descriptors(preset_name)))
