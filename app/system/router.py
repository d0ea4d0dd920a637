"""Liveness, readiness and metrics."""

from __future__ import annotations

from fastapi import APIRouter, Response
from fastapi.responses import JSONResponse
from sqlalchemy import text

from ..deps import StateDep
from ..metrics import CONTENT_TYPE
from ..schemas import ERROR_RESPONSES

router = APIRouter(tags=["system"], responses=ERROR_RESPONSES)


@router.get("/health", summary="The process is up")
def health() -> dict[str, str]:
    return {"status": "ok"}


@router.get(
    "/ready",
    summary="Database reachable and index loaded",
    responses={503: {"description": "Not ready yet (index loading) or database unreachable"}},
)
def ready(state: StateDep) -> JSONResponse:
    checks: dict[str, str] = {}
    try:
        with state.read_sessions() as session:
            session.execute(text("SELECT 1"))
        checks["database"] = "ok"
    except Exception as exc:  # any failure means not ready, with the reason shown
        checks["database"] = f"error: {exc.__class__.__name__}"
    gallery = state.gallery
    if gallery.loaded:
        checks["index"] = f"ok ({len(gallery)} shapes)"
    else:
        checks["index"] = gallery.error or "loading"
    ok = checks["database"] == "ok" and gallery.loaded
    body = {"status": "ready" if ok else "not_ready", "checks": checks}
    if not ok:
        body.update(error="not_ready", detail="The service is starting or its database is down.")
    return JSONResponse(body, status_code=200 if ok else 503)


@router.get("/metrics", summary="Prometheus metrics", response_class=Response)
def metrics(state: StateDep) -> Response:
    return Response(state.metrics.render(), media_type=CONTENT_TYPE)
