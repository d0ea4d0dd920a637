"""Response model of the job endpoint."""

from __future__ import annotations

from pydantic import BaseModel, Field

from ..models import JobStatus
from ..schemas import UtcDatetime


class JobOut(BaseModel):
    id: int
    mesh_id: int
    preset: str
    preset_version: int
    status: JobStatus
    enqueues: int = Field(
        description="times handed to the queue (1 + re-enqueues after a lost worker)"
    )
    worker: str | None = Field(None, description="pid@host of the worker that ran it")
    error: str | None = None
    detail: str | None = None
    created_at: UtcDatetime
    started_at: UtcDatetime | None
    finished_at: UtcDatetime | None
    links: dict[str, str]
