"""Where the service gets a shape's descriptor: an enrolled mesh's is made by a queued
job (:func:`new_job`, :func:`enqueue_soon`) and stored by the collector; a query's
(:func:`upload_descriptor`) is the stored one of the same bytes, a recent query's, or made
now by a query worker; a stored mesh's (:func:`stored_descriptor`) is read back.

Used alike by enrollment, search, similar and verification; it takes plain values
(the upload, the gallery, ids) and the request's session, and no HTTP types.
"""

from __future__ import annotations

import logging
import time
import uuid
from collections.abc import Sequence
from datetime import timedelta
from typing import Literal

from sqlalchemy.orm import Session

from worker.engine.descriptor import ShapeDescriptor
from worker.engine.formats import mesh_format
from worker.engine.presets import Preset
from worker.jobs.queue import FILE_GONE

from .db import DATABASE_ERRORS, unit_of_work
from .errors import ConflictError, NotFoundError
from .gallery.service import Gallery
from .models import Job, JobStatus, Mesh, MeshStatus, utcnow
from .queue import QUEUE_ERRORS
from .repositories import meshes, query_previews
from .state import AppState
from .storage import ReceivedFile

log = logging.getLogger("shapes.descriptors")

#: Failures that say nothing about the file (a crash on every try, a worker that kept
#: dying, a worker on another version or that did not find the file): uploading the
#: same bytes again retries them.
TRANSIENT_FAILURES = frozenset({"describe_crashed", "worker_lost", "preset_mismatch", FILE_GONE})

DescriptorSource = Literal["computed", "enrolled", "recent", "stored"]


# ------------------------------------------------------------ enrolled meshes: jobs
def new_job(preset: Preset, mesh: Mesh) -> Job:
    """A queued job describing ``mesh`` with its collection's ``preset`` (task id chosen
    now, so it can be enqueued after the commit that creates the row)."""
    return Job(
        mesh=mesh,
        preset=preset.name,
        preset_version=preset.version,
        task_id=uuid.uuid4().hex,
        status=JobStatus.queued.value,
        enqueues=1,
    )


def enqueue_job(state: AppState, job: Job) -> None:
    """Hand ``job`` to the workers (call after the commit that created its row)."""
    mesh = job.mesh
    state.queue.enqueue_describe(
        job.task_id,
        state.store.task_source(mesh.storage_path),
        mesh.filename,
        job.preset,
    )


def enqueue_soon(state: AppState, job: Job) -> None:
    """Enqueue ``job``, or, while the queue is unreachable, leave it to the collector's
    sweep (:func:`lost`), which enqueues it once the queue is back: the upload is
    stored and answered either way."""
    try:
        enqueue_job(state, job)
    except QUEUE_ERRORS as exc:
        state.metrics.jobs.labels("deferred").inc()
        log.warning("job %s not enqueued (queue unreachable: %r); the sweep will", job.id, exc)


def lost(state: AppState, unfinished: Sequence[Job], *, grace_seconds: float) -> list[Job]:
    """The unfinished jobs the queue does not know: not waiting, no result, no live
    heartbeat, and unchanged for ``grace_seconds`` (a job committed a moment ago may
    be being enqueued right now). They were never enqueued (the queue was down), or
    were lost with the queue's data or a dead worker."""
    settled = utcnow() - timedelta(seconds=grace_seconds)
    candidates = [j for j in unfinished if j.updated_at <= settled]
    if not candidates:
        return []
    ids = [j.task_id for j in candidates]
    results = state.queue.results(ids)
    beats = state.queue.heartbeats(ids)
    waiting = state.queue.waiting_task_ids()
    return [
        job
        for job in candidates
        if job.task_id not in results
        and job.task_id not in waiting
        and (job.task_id not in beats or state.queue.is_stale(beats[job.task_id]))
    ]


# -------------------------------------------------------------------- stored meshes
def enrolled_mesh(session: Session, gallery: Gallery, mesh_id: int) -> Mesh:
    """The collection's mesh ``mesh_id`` (another collection's is not found here).

    Raises
    ------
    NotFoundError
        No such mesh in the gallery's collection.
    """
    mesh = meshes.get(session, mesh_id)
    if mesh is None or mesh.collection_id != gallery.collection_id:
        raise NotFoundError(f"There is no mesh with id {mesh_id} in collection {gallery.name!r}.")
    return mesh


def stored_descriptor(
    session: Session, gallery: Gallery, mesh_id: int, preset: Preset
) -> ShapeDescriptor:
    """A mesh's descriptor under ``preset``, enrolled in ``gallery``'s collection.

    Raises
    ------
    NotFoundError
        No such mesh.
    ConflictError
        ``mesh_not_ready``: it has no descriptor yet (queued, processing or failed).
    """
    mesh = enrolled_mesh(session, gallery, mesh_id)
    stored = meshes.get_descriptor(session, mesh_id, preset.name, preset.version)
    if stored is None or mesh.status != MeshStatus.ready.value:
        raise ConflictError(
            f"Mesh {mesh_id} is {mesh.status}, not ready; it has no descriptor to compare yet.",
            code="mesh_not_ready",
        )
    return ShapeDescriptor.from_npz_bytes(stored.data)


# ---------------------------------------------------------------------------- uploads
def upload_descriptor(
    session: Session, state: AppState, gallery: Gallery, upload: ReceivedFile, preset: Preset
) -> tuple[ShapeDescriptor, DescriptorSource, dict[str, float], bool]:
    """The descriptor of a file uploaded to ``gallery``'s collection, where it came from,
    its timings, and whether a preview of it was stored just now.

    Bytes already described under the preset in this collection (an enrolled mesh's
    file, or a recent query's) answer from that descriptor; others are described by a
    query worker (blocking, seconds). Nothing of another collection is reused: what a
    query answers, and how fast, never tells whether other collections hold its bytes.
    """
    started = time.perf_counter()
    key = (
        gallery.collection_id,
        upload.sha256,
        mesh_format(upload.filename),
        preset.name,
        preset.version,
    )
    source: DescriptorSource = "enrolled"
    descriptor = _known_descriptor(session, gallery, upload, preset)
    if descriptor is None:
        descriptor, source = state.recent_queries.get(key), "recent"
    stored_preview = False
    if descriptor is None:
        descriptor, preview = state.queue.describe_now(
            uuid.uuid4().hex, upload.path, upload.filename, preset.name
        )
        state.recent_queries.put(key, descriptor)
        if preview is not None:
            stored_preview = _keep_preview(state, gallery, upload.sha256, preview)
        source = "computed"
        timings = dict(descriptor.timings)
    else:
        timings = {}
    timings["describe_wall"] = time.perf_counter() - started
    return descriptor, source, timings, stored_preview


def _known_descriptor(
    session: Session, gallery: Gallery, upload: ReceivedFile, preset: Preset
) -> ShapeDescriptor | None:
    """The stored descriptor of the collection's mesh of these very bytes, read as the
    same format (the same bytes named .stl and .obj are different meshes)."""
    mesh = meshes.get_by_sha256(session, gallery.collection_id, upload.sha256)
    if mesh is None or mesh_format(mesh.filename) != mesh_format(upload.filename):
        return None
    stored = meshes.get_descriptor(session, mesh.id, preset.name, preset.version)
    if stored is None:
        return None
    descriptor = ShapeDescriptor.from_npz_bytes(stored.data)
    # One stored before areas were recorded has no size to compare in metric units.
    return descriptor if descriptor.area is not None or preset.units != "metric" else None


def _keep_preview(state: AppState, gallery: Gallery, sha256: str, glb: bytes) -> bool:
    """Store a query's preview, the collection's own, where every replica finds it (its
    own short write, so the search holds no write lock); True once stored. A preview is
    a convenience: if the database refuses it now, the search still answers."""
    try:
        with unit_of_work(state.sessions) as session:
            query_previews.put_query_preview(
                session,
                gallery.collection_id,
                sha256,
                glb,
                keep=state.settings.query_previews_kept,
            )
    except DATABASE_ERRORS as exc:
        log.warning("query preview not stored: %r", exc)
        return False
    return True
