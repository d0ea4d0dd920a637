"""Liveness, readiness and metrics."""

from __future__ import annotations

from fastapi import APIRouter, Response
from fastapi.responses import JSONResponse

from ..deps import StateDep
from ..errors import RETRY_AFTER_SECONDS
from ..metrics import CONTENT_TYPE
from ..schemas import ERROR_RESPONSES
from . import service

router = APIRouter(tags=["system"], responses=ERROR_RESPONSES)


@router.get("/health", summary="The process is up")
def health() -> dict[str, str]:
    return {"status": "ok"}


@router.get(
    "/ready",
    summary="Database and queue reachable, index loaded",
    description="`checks` has one entry per dependency (`database`, `queue`, `index`): "
    "`ok ...` or why not; the answer is 503 unless all are ok. "
    "`descriptors` says how many enrolled meshes are described with the current "
    "preset version (after an upgrade the others are described again in the background, "
    "and are searchable once done).",
    responses={
        503: {"description": "Not ready yet (index loading), or the database or queue is down"}
    },
)
def ready(state: StateDep) -> JSONResponse:
    ok, checks = service.readiness(state)
    body: dict[str, object] = {"status": "ready" if ok else "not_ready", "checks": checks}
    if checks["database"] == "ok":
        body["descriptors"] = service.description_progress(state)
    if not ok:
        down = [name for name, check in checks.items() if not check.startswith("ok")]
        body.update(
            error="not_ready",
            detail=f"Not ready: {', '.join(down)} (see checks); the service is starting "
            "or a dependency is down.",
        )
    retry = None if ok else {"Retry-After": str(RETRY_AFTER_SECONDS)}
    return JSONResponse(body, status_code=200 if ok else 503, headers=retry)


@router.get("/metrics", summary="Prometheus metrics", response_class=Response)
def metrics(state: StateDep) -> Response:
    return Response(state.metrics.render(), media_type=CONTENT_TYPE)
