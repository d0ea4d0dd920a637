"""Rules for reading a descriptor job (how jobs are made and queued is
:mod:`app.descriptors`')."""

from __future__ import annotations

from sqlalchemy.orm import Session

from ..errors import NotFoundError
from ..keyring import Grant
from ..models import Job, Scope
from ..repositories import jobs


def get(session: Session, job_id: int, grant: Grant | None) -> Job:
    """The job, if the request's key may read its collection (None: an open service).

    Raises
    ------
    NotFoundError
        No such job, or one of a collection the key may not read: the same answer, so
        that a key learns nothing of another collection's jobs.
    """
    job = jobs.get(session, job_id)
    if job is None or (grant is not None and not grant.allows(job.mesh.collection_id, Scope.read)):
        raise NotFoundError(f"There is no job with id {job_id}.")
    return job
