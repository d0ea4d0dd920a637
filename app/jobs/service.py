"""Rules for descriptor jobs: creating one for a mesh, handing it to the queue, reading one."""

from __future__ import annotations

import logging
import uuid
from collections.abc import Sequence
from datetime import timedelta

from sqlalchemy.orm import Session

from worker.engine.presets import Preset

from ..errors import NotFoundError
from ..models import Job, JobStatus, Mesh, utcnow
from ..queue import QUEUE_ERRORS
from ..state import AppState
from . import repository as jobs

log = logging.getLogger("shapes.jobs")

#: Failures that say nothing about the file (a crash on every try, a worker that kept
#: dying, a worker on another version): uploading the same bytes again retries them.
TRANSIENT_FAILURES = frozenset({"describe_crashed", "worker_lost", "preset_mismatch"})


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


def get(session: Session, job_id: int) -> Job:
    job = jobs.get(session, job_id)
    if job is None:
        raise NotFoundError(f"There is no job with id {job_id}.")
    return job
