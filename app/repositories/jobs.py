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


def unfinished(session: Session, limit: int | None = None, *, lock: bool = False) -> list[Job]:
    """Queued and processing jobs, oldest first; with ``lock``, locked until the
    transaction ends, skipping those another transaction holds (PostgreSQL;
    SQLite, whose writers are serialized anyway, ignores the clause)."""
    query = (
        select(Job)
        .where(Job.status.in_(UNFINISHED_JOB))
        .order_by(Job.id)
        .options(selectinload(Job.mesh))
    )
    if limit is not None:
        query = query.limit(limit)
    if lock:
        query = query.with_for_update(skip_locked=True, of=Job)
    return list(session.scalars(query))
