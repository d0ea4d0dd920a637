"""HTTP layer of POST /query."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from ..deps import WRITE_ACCESS, MultipartDep, SessionDep, StateDep, require_file
from ..errors import InvalidInputError
from ..schemas import ERROR_RESPONSES, UNAUTHORIZED_RESPONSE
from . import service
from .schemas import QueryOut

router = APIRouter(tags=["search"], responses=ERROR_RESPONSES)

QUERY_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["file"],
                    "properties": {
                        "file": {"type": "string", "format": "binary"},
                        "k": {"type": "integer", "default": 10, "minimum": 1},
                        "preset": {"type": "string", "example": "smeets2010-shrec"},
                        "fusion": {"type": "string", "enum": ["sum", "product"]},
                        "modalities": {"type": "string", "example": "gdm,ddt"},
                    },
                }
            }
        },
    }
}


QUERY_ERRORS: dict[int | str, dict[str, Any]] = {
    413: {"description": "File over the size limit, or too many faces"},
    415: {"description": "Not a mesh file type"},
    422: {"description": "Unreadable mesh, bad k/preset/fusion/modalities"},
    503: {"description": "Index loading, or no worker answered in time"},
}


def _int_field(value: str | None, name: str, default: int) -> int:
    if value is None or not value.strip():
        return default
    try:
        return int(value)
    except ValueError:
        raise InvalidInputError(f"{name} must be a whole number.", code=f"invalid_{name}") from None


@router.post(
    "/query",
    dependencies=WRITE_ACCESS,
    response_model=QueryOut,
    summary="Rank the gallery by similarity to an uploaded mesh",
    description=(
        "Computes the query's descriptor in the worker pool (a few seconds), then ranks the "
        "gallery by the preset's exact fused dissimilarity (D2 + product rule for the "
        "default preset; lower is more similar).\n\n"
        "`curl -F file=@wolf2.off.gz -F k=3 http://127.0.0.1:8000/query`"
    ),
    responses=QUERY_ERRORS | UNAUTHORIZED_RESPONSE,
    openapi_extra=QUERY_BODY,
)
def query(upload: MultipartDep, session: SessionDep, state: StateDep) -> QueryOut:
    file = require_file(upload)
    fields = upload.fields
    unknown = set(fields) - {"k", "preset", "fusion", "modalities"}
    if unknown:
        raise InvalidInputError(
            f"Unknown form fields: {', '.join(sorted(unknown))}; "
            "use file, k, preset, fusion and modalities.",
            code="unknown_field",
        )
    fusion = (fields.get("fusion") or "").strip() or None
    if fusion not in (None, "sum", "product"):
        raise InvalidInputError("fusion must be 'sum' or 'product'.", code="invalid_fusion")
    return service.query_by_upload(
        session,
        state,
        file,
        k=_int_field(fields.get("k"), "k", 10),
        preset_name=(fields.get("preset") or "").strip() or None,
        fusion=fusion,
        modalities=fields.get("modalities"),
    )
