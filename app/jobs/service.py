"""Rules for reading a descriptor job (how jobs are made and queued is
:mod:`app.descriptors`')."""

from __future__ import annotations

from sqlalchemy.orm import Session

from ..errors import NotFoundError
from ..models import Job
from ..repositories import jobs


def get(session: Session, job_id: int) -> Job:
    job = jobs.get(session, job_id)
    if job is None:
        raise NotFoundError(f"There is no job with id {job_id}.")
    return job
