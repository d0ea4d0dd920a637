"""The evaluation's on-disk caches: descriptors, keyed by file bytes, preset and engine
code; and the variant meshes that are slow to make, keyed by file bytes and the code
that makes them."""

from __future__ import annotations

import ast
import functools
import hashlib
import io
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worker.engine.descriptor import ShapeDescriptor
from worker.engine.mesh_io import Mesh
from worker.engine.presets import Preset

from .shapedna import BASELINE, SHAPEDNA_K, ShapeDNA

#: The modules a cache entry is made by; everything they import from ``worker`` counts too.
FINGERPRINT_ROOTS = (
    "worker.engine.pipeline",
    "worker.evaluation.shapedna",
    "worker.evaluation.variants",
)
_WORKER_DIR = Path(__file__).resolve().parents[1]


def _module_file(name: str) -> Path | None:
    """Source file of module ``worker.<...>`` (its ``__init__.py`` for a package), if any."""
    parts = name.split(".")
    if parts[0] != "worker":
        return None
    base = _WORKER_DIR.joinpath(*parts[1:])
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _worker_imports(name: str, path: Path) -> frozenset[str]:
    """Names a module's source imports (anywhere in it) that may be ``worker`` modules.

    ``from .x import y`` yields both ``<package>.x`` and ``<package>.x.y`` (``y`` may be
    a submodule); names that are not modules are dropped by :func:`_module_file`.
    """
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    return _imports(package, path.read_bytes())


@functools.lru_cache(maxsize=256)
def _imports(package: str, source: bytes) -> frozenset[str]:
    """:func:`_worker_imports` of a module of ``package`` with this source (parsed once
    per source: the fingerprint is taken at each use of the cache)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1])
                module = f"{base}.{node.module}" if node.module else base
            else:
                module = node.module or ""
            found.add(module)
            found.update(f"{module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return frozenset(m for m in found if m == "worker" or m.startswith("worker."))


def worker_modules(roots: Sequence[str]) -> dict[str, Path]:
    """The ``worker`` modules ``roots`` and, transitively, the ``worker`` modules they
    import: name -> source file."""
    seen: dict[str, Path] = {}
    todo = list(roots)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        path = _module_file(name)
        if path is None:
            continue
        seen[name] = path
        todo.extend(_worker_imports(name, path))
    return seen


def engine_modules() -> dict[str, Path]:
    """Every ``worker`` module a cached entry depends on: :data:`FINGERPRINT_ROOTS` and
    what they import (the engine's)."""
    return worker_modules(FINGERPRINT_ROOTS)


class _WithoutProse(ast.NodeTransformer):
    """Drops the statements that are a bare string (docstrings): they compute nothing."""

    def visit_Expr(self, node: ast.Expr) -> ast.Expr | None:
        if isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            return None
        return node


@functools.lru_cache(maxsize=256)
def _code(source: bytes) -> bytes:
    """What a module with this source computes: its syntax tree without comments,
    docstrings or line numbers (``ast.dump``), so that rewording them keeps a fingerprint
    (parsed once per source). The dump's form follows the Python version: another
    interpreter describes afresh."""
    return ast.dump(_WithoutProse().visit(ast.parse(source))).encode()


def _code_digest(modules: dict[str, Path]) -> str:
    digest = hashlib.sha256()
    for name, path in sorted(modules.items()):
        digest.update(name.encode())
        digest.update(_code(path.read_bytes()))
    return digest.hexdigest()


def engine_fingerprint() -> str:
    """sha256 of the code of every module of :func:`engine_modules` (:func:`_code`).

    Editing the engine's code (even without a preset version bump) or the baseline's
    never serves stale descriptors, while editing the service, the job runner, the
    metrics, this harness or any comment or docstring keeps the cache.
    """
    return _code_digest(engine_modules())


def variant_mesh_fingerprint() -> str:
    """sha256 of the code a stored variant mesh (:data:`.variants.STORED_VARIANTS`, the
    remeshes) is made by: :mod:`.remesh` and what it imports (reading and cleaning the
    file), and :mod:`.variants`' own code (which variant is which), not the descriptor
    pipeline nor the partial copies, so editing the resampling, the operators or a
    partial copy keeps the stored remeshes."""
    modules = worker_modules(["worker.evaluation.remesh"])
    variants = _module_file("worker.evaluation.variants")
    if variants is not None:
        modules["worker.evaluation.variants"] = variants
    return _code_digest(modules)


def cache_namespace(preset: Preset) -> str:
    """Directory name of a preset's cache entries.

    ``<name>-v<version>-<digest>``: the digest covers every preset field a
    descriptor depends on and the engine's code (:func:`engine_fingerprint`), so a
    preset edited without a version bump, or an edited pipeline, gets a fresh
    namespace, while a change of how descriptors are compared (dissimilarity,
    fusion, weights) reuses them.
    """
    digest = hashlib.sha256()
    fields = preset.descriptor_fields()
    digest.update(json.dumps(fields, sort_keys=True, default=list).encode())
    digest.update(engine_fingerprint().encode())
    return f"{preset.name}-v{preset.version}-{digest.hexdigest()[:12]}"


@dataclass
class DescriptorCache:
    """Descriptors on disk as npz, keyed by sha256(file bytes) within a preset namespace.

    Layout: ``<root>/<cache_namespace(preset)>/<sha256>.descriptor.npz`` and
    ``<sha256>.shapedna-k<k>.npz`` for the baseline (same resampled mesh, so the
    same namespace); a variant of the file (:mod:`.variants`) puts its name after
    the digest, ``<sha256>.<variant>.descriptor.npz``.
    """

    root: Path
    preset: Preset
    variant: str | None = None

    @property
    def directory(self) -> Path:
        return Path(self.root) / cache_namespace(self.preset)

    def _path(self, sha256: str, kind: str) -> Path:
        suffix = "descriptor" if kind == "descriptor" else f"{BASELINE}-k{SHAPEDNA_K}"
        key = sha256 if self.variant is None else f"{sha256}.{self.variant}"
        return self.directory / f"{key}.{suffix}.npz"

    def load_descriptor(self, sha256: str) -> ShapeDescriptor | None:
        path = self._path(sha256, "descriptor")
        if not path.is_file():
            return None
        descriptor = ShapeDescriptor.from_npz_bytes(path.read_bytes())
        same = (descriptor.preset, descriptor.preset_version) == (
            self.preset.name,
            self.preset.version,
        )
        return descriptor if same else None

    def load_baseline(self, sha256: str) -> ShapeDNA | None:
        path = self._path(sha256, BASELINE)
        return ShapeDNA.from_npz_bytes(path.read_bytes()) if path.is_file() else None

    def store(self, sha256: str, kind: str, data: bytes) -> None:
        _write_atomically(self._path(sha256, kind), data)


def _write_atomically(path: Path, data: bytes) -> None:
    """Write so that an interrupted run never leaves a truncated entry."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


@dataclass
class VariantMeshCache:
    """The variant meshes that are slow to make (:data:`.variants.STORED_VARIANTS`), on
    disk as compressed npz (under 0.3 MB for a remesh of 9,300 vertices), keyed by
    sha256(file bytes) and variant name.

    Layout: ``<root>/variants-<digest>/<sha256>.<variant>.npz``, the digest that of
    :func:`variant_mesh_fingerprint` (:meth:`under`): a change of the descriptor
    pipeline describes the same variant meshes again without remaking them.
    """

    directory: Path

    @classmethod
    def under(cls, root: str | Path) -> VariantMeshCache:
        return cls(Path(root) / f"variants-{variant_mesh_fingerprint()[:12]}")

    def _path(self, sha256: str, variant: str) -> Path:
        return self.directory / f"{sha256}.{variant}.npz"

    def load(self, sha256: str, variant: str) -> Mesh | None:
        path = self._path(sha256, variant)
        if not path.is_file():
            return None
        with np.load(path) as data:
            return Mesh(vertices=data["vertices"], faces=data["faces"])

    def store(self, sha256: str, variant: str, mesh: Mesh) -> None:
        buffer = io.BytesIO()
        np.savez_compressed(buffer, vertices=mesh.vertices, faces=mesh.faces)
        _write_atomically(self._path(sha256, variant), buffer.getvalue())


def file_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
