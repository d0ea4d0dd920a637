"""HTTP layer of /jobs."""

from __future__ import annotations

from fastapi import APIRouter

from ..deps import GrantDep, RowId, SessionDep, StateDep
from ..links import collection_path
from ..models import DEFAULT_COLLECTION, JobStatus
from ..schemas import ACCESS_RESPONSES, ERROR_RESPONSES
from . import service
from .schemas import JobOut

router = APIRouter(prefix="/jobs", tags=["jobs"], responses=ERROR_RESPONSES | ACCESS_RESPONSES)


@router.get(
    "/{job_id}",
    response_model=JobOut,
    operation_id="get_job",
    summary="A descriptor job",
    responses={404: {"description": "Unknown id"}},
)
def get_job(job_id: RowId, session: SessionDep, state: StateDep, grant: GrantDep) -> JobOut:
    job = service.get(session, job_id, grant)
    gallery = state.galleries.of(job.mesh.collection_id)
    base = collection_path(DEFAULT_COLLECTION if gallery is None else gallery.name)
    return JobOut(
        id=job.id,
        mesh_id=job.mesh_id,
        preset=job.preset,
        preset_version=job.preset_version,
        status=JobStatus(job.status),
        enqueues=job.enqueues,
        worker=job.worker,
        error=job.error_code,
        detail=job.error_detail,
        created_at=job.created_at,
        started_at=job.started_at,
        finished_at=job.finished_at,
        links={"self": f"/jobs/{job.id}", "mesh": f"{base}/meshes/{job.mesh_id}"},
    )
