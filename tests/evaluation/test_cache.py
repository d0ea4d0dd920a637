"""The descriptor cache's key: preset fields, version and the engine's source."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import worker
from worker.engine.presets import Preset
from worker.evaluation.cache import (
    cache_namespace,
    engine_fingerprint,
    engine_modules,
    variant_mesh_fingerprint,
    worker_modules,
)

EVAL_PRESET = Preset(name="test-eval-small", version=0, n_vertices=500, n_eigenpairs=100)
WORKER = Path(worker.__file__).parent


def test_cache_namespace_follows_preset_and_version():
    base = cache_namespace(EVAL_PRESET)
    assert base.startswith(f"{EVAL_PRESET.name}-v0-")
    assert cache_namespace(dataclasses.replace(EVAL_PRESET, version=1)) != base
    # an edited preset that forgot its version bump must not reuse stale entries
    assert cache_namespace(dataclasses.replace(EVAL_PRESET, n_vertices=600)) != base
    assert cache_namespace(EVAL_PRESET) == base
    # how descriptors are compared does not change them
    reweighted = dataclasses.replace(EVAL_PRESET, fusion_weights={"ddt": 0.5}, dissimilarity="D1")
    assert cache_namespace(reweighted) == base


def test_fingerprint_covers_every_engine_module_the_baseline_and_the_variants_only():
    modules = engine_modules()
    engine = {f"worker.engine.{p.stem}" for p in (WORKER / "engine").glob("*.py")}
    # not used to describe: comparing descriptors, verifying a shortlist
    engine -= {"worker.engine.__init__", "worker.engine.compare", "worker.engine.rigid"}
    # linalg and tol are reached only through other engine modules' imports
    assert engine <= set(modules), engine - set(modules)
    outside = {m for m in modules if not m.startswith("worker.engine.")}
    # the variants' makers: the re-tessellations and the partial copies
    assert outside == {
        "worker.evaluation.shapedna",
        "worker.evaluation.variants",
        "worker.evaluation.partial",
    }
    assert all(path.is_file() for path in modules.values())


def test_fingerprint_changes_with_the_source_of_a_module_imported_indirectly(monkeypatch):
    before = engine_fingerprint()
    linalg = engine_modules()["worker.engine.linalg"]
    real = Path.read_bytes

    def edited(path: Path) -> bytes:
        data = real(path)
        return data + b"\n# edited\n" if path == linalg else data

    monkeypatch.setattr(Path, "read_bytes", edited)
    assert engine_fingerprint() != before


def test_variant_meshes_depend_on_how_they_are_made_not_on_the_pipeline(monkeypatch):
    modules = worker_modules(["worker.evaluation.variants"])
    assert {"worker.evaluation.variants", "worker.engine.mesh_io"} <= set(modules)
    assert not {"worker.engine.resample", "worker.engine.pipeline"} & set(modules)
    before = variant_mesh_fingerprint()
    resample = engine_modules()["worker.engine.resample"]
    mesh_io = modules["worker.engine.mesh_io"]
    real = Path.read_bytes
    edited_file = resample

    def edited(path: Path) -> bytes:
        data = real(path)
        return data + b"\n# edited\n" if path == edited_file else data

    monkeypatch.setattr(Path, "read_bytes", edited)
    assert variant_mesh_fingerprint() == before  # the resampling edited: meshes kept
    edited_file = mesh_io
    assert variant_mesh_fingerprint() != before  # reading and cleaning edited: remade
