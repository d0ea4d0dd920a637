"""Rules for descriptor jobs: creating one for a mesh, handing it to the queue, reading one."""

from __future__ import annotations

import uuid

from sqlalchemy.orm import Session

from ..errors import NotFoundError
from ..models import Job, JobStatus, Mesh
from ..state import AppState
from . import repository as jobs


def new_job(state: AppState, mesh: Mesh) -> Job:
    """A queued job describing ``mesh`` with the service's preset (task id chosen now,
    so it can be enqueued after the commit that creates the row)."""
    return Job(
        mesh=mesh,
        preset=state.preset.name,
        preset_version=state.preset.version,
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


def get(session: Session, job_id: int) -> Job:
    job = jobs.get(session, job_id)
    if job is None:
        raise NotFoundError(f"There is no job with id {job_id}.")
    return job
