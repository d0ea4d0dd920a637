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
READ_BYTES = Path.read_bytes


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
    # the variants' makers: the re-tessellations (MeshLab's remeshing) and the partial copies
    assert outside == {
        "worker.evaluation.shapedna",
        "worker.evaluation.variants",
        "worker.evaluation.remesh",
        "worker.evaluation.partial",
    }
    assert all(path.is_file() for path in modules.values())


def _edited_reads(monkeypatch, edits: dict[Path, bytes]) -> None:
    """Every read of a file in ``edits`` returns its bytes with the edit appended (the
    edits of an earlier call undone)."""

    def read(path: Path) -> bytes:
        return READ_BYTES(path) + edits.get(path, b"")

    monkeypatch.setattr(Path, "read_bytes", read)


def test_fingerprint_changes_with_the_code_of_a_module_imported_indirectly(monkeypatch):
    before = engine_fingerprint()
    linalg = engine_modules()["worker.engine.linalg"]
    _edited_reads(monkeypatch, {linalg: b"\nEDITED = 1\n"})
    assert engine_fingerprint() != before


def test_fingerprint_keeps_through_comments_and_docstrings(monkeypatch):
    before = engine_fingerprint()
    modules = engine_modules()
    prose = b'\n# a comment reworded\ndef helper():\n    """A docstring."""\n    return 1\n'
    code = b"\ndef helper():\n    return 1\n"
    _edited_reads(monkeypatch, {modules["worker.engine.denoise"]: prose})
    with_prose = engine_fingerprint()
    _edited_reads(monkeypatch, {modules["worker.engine.denoise"]: code})
    assert engine_fingerprint() == with_prose != before
    # the same code lower in the file: line numbers are not the code
    _edited_reads(monkeypatch, {modules["worker.engine.denoise"]: b"\n\n\n" + code})
    assert engine_fingerprint() == with_prose


def test_variant_meshes_depend_on_how_they_are_made_not_on_the_pipeline(monkeypatch):
    """The stored remeshes (166 for TOSCA and SCAPE, 20-40 s each on a loaded machine) are
    remade when MeshLab's remeshing, the reading and cleaning of the file (scans' reading
    among it) or the variants' own code is edited, and kept when the resampling or a
    partial copy is."""
    modules = worker_modules(["worker.evaluation.variants"])
    assert {"worker.evaluation.remesh", "worker.engine.mesh_io"} <= set(modules)
    assert not {"worker.engine.resample", "worker.engine.pipeline"} & set(modules)
    before = variant_mesh_fingerprint()
    for kept in ("worker.engine.resample", "worker.evaluation.partial"):
        _edited_reads(monkeypatch, {engine_modules()[kept]: b"\nEDITED = 1\n"})
        assert variant_mesh_fingerprint() == before, kept  # meshes kept
    for remade in (
        "worker.engine.mesh_io",
        "worker.evaluation.remesh",
        "worker.evaluation.variants",
    ):
        _edited_reads(monkeypatch, {modules[remade]: b"\nEDITED = 1\n"})
        assert variant_mesh_fingerprint() != before, remade  # remade
