"""Describe a labelled collection in worker processes, through the descriptor cache."""

from __future__ import annotations

import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from worker.engine.descriptor import ShapeDescriptor
from worker.engine.errors import MeshError
from worker.engine.mesh_io import Mesh, load_mesh, read_numbered_mesh
from worker.engine.pipeline import describe_mesh, load_and_describe, resampled_surface
from worker.engine.presets import MODALITIES, SIZE, Preset
from worker.engine.resample import SharedResampling, carry_resampling

from .cache import DescriptorCache, VariantMeshCache, file_sha256
from .datasets import LabeledMesh
from .shapedna import BASELINE, ShapeDNA, shapedna
from .variants import STORED_VARIANTS, make_variant


@dataclass
class _Job:
    """What a worker process returns for one mesh (npz bytes, or why it failed)."""

    descriptor: bytes | None = None
    baseline: bytes | None = None
    error: str | None = None


def single_threaded_blas() -> None:
    """Give each worker process one BLAS thread.

    ``--jobs`` processes with OpenBLAS's default of one thread per core
    oversubscribe the machine; on a shared 2-core machine that made describing a
    mesh about 10 times slower (measured: 2.4 s against 20-27 s for wolf0).
    """
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)


def _variant_mesh(
    data: bytes, name: str, sha256: str, variant: str, stored: VariantMeshCache | None
) -> Mesh:
    """The variant ``variant`` of the file, from ``stored`` when given (made and stored
    there the first time)."""
    mesh = stored.load(sha256, variant) if stored is not None else None
    if mesh is None:
        mesh = make_variant(load_mesh(data, name), variant, name)
        if stored is not None:
            stored.store(sha256, variant, mesh)
    return mesh


def _describe_job(
    path: str,
    sha256: str,
    preset: Preset,
    variant: str | None,
    need_descriptor: bool,
    need_baseline: bool,
    stored: VariantMeshCache | None,
    carried: SharedResampling | None = None,
) -> _Job:
    """Describe one mesh file (``sha256`` its bytes' digest), or its ``variant`` (its
    mesh kept in ``stored`` when given), or the resampling of its figure ``carried`` to
    it; runs in a worker process, so it only takes picklable data."""
    data = Path(path).read_bytes()
    name = Path(path).name
    job = _Job()
    resampled = carried is not None
    try:
        if carried is not None:  # its figure's resampling, by vertex id
            mesh = carry_resampling(read_numbered_mesh(data, name), carried)
            if need_descriptor:
                job.descriptor = describe_mesh(mesh, preset, resampled=True).to_npz_bytes()
        elif variant is None:  # the file as the service describes an upload
            if need_descriptor:
                mesh, descriptor = load_and_describe(data, preset, filename=name)
                job.descriptor = descriptor.to_npz_bytes()
            else:
                mesh = load_mesh(data, name)
        else:
            mesh = _variant_mesh(data, name, sha256, variant, stored)
            if need_descriptor:
                job.descriptor = describe_mesh(mesh, preset).to_npz_bytes()
        if need_baseline:
            # The mesh the descriptors were made from (the same deterministic steps).
            surface = resampled_surface(mesh, preset, resampled=resampled)
            job.baseline = shapedna(surface.vertices, surface.faces).to_npz_bytes()
    except MeshError as exc:
        job.error = exc.message
    except Exception as exc:  # one mesh's crash must not lose the others' work
        job.error = f"internal error: {type(exc).__name__}: {exc}"
    return job


@dataclass
class ComputedSet:
    """Descriptors of the meshes that could be described, in input order."""

    meshes: list[LabeledMesh]
    descriptors: list[ShapeDescriptor]
    baselines: list[ShapeDNA]
    failures: dict[str, str] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)  # counts, seconds, cache directory


def compute_descriptors(
    meshes: Sequence[LabeledMesh],
    preset: Preset,
    cache_root: str | Path,
    jobs: int = 1,
    progress: bool = True,
    variant: str | None = None,
    carried: tuple[str, SharedResampling] | None = None,
) -> ComputedSet:
    """Descriptors and ShapeDNA of every mesh, from the cache or computed in parallel.

    Parameters
    ----------
    meshes : the objects to describe.
    preset : the descriptor parameters.
    cache_root : cache directory (created if missing).
    jobs : worker processes, each with one BLAS thread; 1 computes in this process.
    progress : show a tqdm progress bar (on a terminal).
    variant : describe this variant of every mesh (:mod:`.variants`) instead of the
        file itself.
    carried : (key, resampling): describe every mesh as this resampling of its figure
        (:func:`~worker.engine.resample.carry_resampling`; the meshes are poses of one
        figure numbered as the one it was made on), cached under ``key`` (which names the
        pose it was made on) as a variant is.

    Returns
    -------
    ComputedSet; meshes the engine refuses are left out and listed in ``failures``.
    """
    from tqdm import tqdm

    if variant is not None and carried is not None:
        raise ValueError("a variant of the files or their figure's resampling, not both")
    cache = DescriptorCache(Path(cache_root), preset, variant if carried is None else carried[0])
    stored = VariantMeshCache.under(cache_root) if variant in STORED_VARIANTS else None
    start = time.perf_counter()
    hashes = [file_sha256(m.path) for m in meshes]
    descriptors: list[ShapeDescriptor | None] = [cache.load_descriptor(h) for h in hashes]
    baselines: list[ShapeDNA | None] = [cache.load_baseline(h) for h in hashes]
    todo = [i for i in range(len(meshes)) if descriptors[i] is None or baselines[i] is None]
    cache_seconds = time.perf_counter() - start
    failures: dict[str, str] = {}

    def collect(i: int, job: _Job) -> None:
        if job.error is not None:
            failures[meshes[i].name] = job.error
            return
        if job.descriptor is not None:
            cache.store(hashes[i], "descriptor", job.descriptor)
            descriptors[i] = ShapeDescriptor.from_npz_bytes(job.descriptor)
        if job.baseline is not None:
            cache.store(hashes[i], BASELINE, job.baseline)
            baselines[i] = ShapeDNA.from_npz_bytes(job.baseline)

    start = time.perf_counter()
    what = preset.name if variant is None else f"{preset.name}, {variant}"
    if carried is not None:
        what = f"{preset.name}, {carried[0]}"
    bar = tqdm(total=len(todo), desc=f"describe ({what})", unit="mesh", disable=not progress)
    args = [
        (
            str(meshes[i].path),
            hashes[i],
            preset,
            variant,
            descriptors[i] is None,
            baselines[i] is None,
            stored,
            None if carried is None else carried[1],
        )
        for i in todo
    ]
    if jobs <= 1 or len(todo) <= 1:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1):
            for i, a in zip(todo, args, strict=True):
                collect(i, _describe_job(*a))
                bar.update()
    elif todo:
        workers = min(jobs, len(todo))
        with ProcessPoolExecutor(max_workers=workers, initializer=single_threaded_blas) as pool:
            futures = {pool.submit(_describe_job, *a): i for i, a in zip(todo, args, strict=True)}
            for future in as_completed(futures):
                try:
                    job = future.result()
                except Exception as exc:  # a worker process died (e.g. out of memory)
                    job = _Job(error=f"worker process failed: {type(exc).__name__}: {exc}")
                collect(futures[future], job)
                bar.update()
    bar.close()
    compute_seconds = time.perf_counter() - start

    def described(i: int) -> tuple[ShapeDescriptor, ShapeDNA]:
        descriptor, baseline = descriptors[i], baselines[i]
        # A mesh that did not fail came from the cache or was just computed.
        assert descriptor is not None and baseline is not None, meshes[i].name
        return descriptor, baseline

    keep = [i for i in range(len(meshes)) if meshes[i].name not in failures]
    pairs = [described(i) for i in keep]
    return ComputedSet(
        meshes=[meshes[i] for i in keep],
        descriptors=[d for d, _ in pairs],
        baselines=[b for _, b in pairs],
        # in the files' order, not the order their jobs ended in: the report reads the same
        failures={m.name: failures[m.name] for m in meshes if m.name in failures},
        stats={
            "meshes": len(meshes),
            "from_cache": len(meshes) - len(todo),
            "computed": len(todo) - len(failures),
            "failed": len(failures),
            "hash_and_cache_seconds": cache_seconds,
            "compute_seconds": compute_seconds,
            "jobs": jobs,
            # Its name (preset, version, engine fingerprint), not the machine's path.
            "cache_namespace": cache.directory.name,
        },
    )


def descriptor_vectors(computed: ComputedSet, *, size: bool = False) -> dict[str, np.ndarray]:
    """modality -> (n, M) float, and ``BASELINE`` -> (n, k): the flat vectors eqs. (8)
    and (9) compare, one row per described mesh; with ``size``, also ``SIZE`` -> (n, 1),
    each mesh's ``sqrt(area)`` (a collection of metric units)."""
    modalities = (*MODALITIES, SIZE) if size else MODALITIES
    vectors = {m: np.stack([d.vector(m) for d in computed.descriptors]) for m in modalities}
    vectors[BASELINE] = np.stack([b.descriptor for b in computed.baselines])
    return vectors
