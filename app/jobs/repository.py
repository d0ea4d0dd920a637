"""All queries on descriptor jobs."""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload

from ..models import UNFINISHED_JOB, Job


def get(session: Session, job_id: int) -> Job | None:
    return session.get(Job, job_id)


def add(session: Session, job: Job) -> Job:
    session.add(job)
    session.flush()
    return job


def unfinished(session: Session, limit: int | None = None) -> list[Job]:
    query = (
        select(Job)
        .where(Job.status.in_(UNFINISHED_JOB))
        .order_by(Job.id)
        .options(selectinload(Job.mesh))
    )
    if limit is not None:
        query = query.limit(limit)
    return list(session.scalars(query))
