"""Shared by every resource: the error body, UTC timestamps, and the OpenAPI description
of a multipart request body."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, Field


def _as_utc(value: datetime) -> datetime:
    # SQLite stores naive datetimes; the service writes them in UTC (models.utcnow).
    return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


UtcDatetime = Annotated[datetime, AfterValidator(_as_utc)]
"""A timestamp in UTC, serialized as RFC 3339 with its offset (``...+00:00``)."""


class ErrorOut(BaseModel):
    """Every error response: a machine-readable code and a sentence for a person."""

    error: str = Field(description="machine-readable code, e.g. invalid_k, not_found")
    detail: str = Field(description="what went wrong, as a sentence")


ERROR_RESPONSES: dict[int | str, dict[str, Any]] = {
    422: {"model": ErrorOut, "description": "Invalid input (`invalid_input` or a specific code)"},
}
"""Responses every router declares, replacing FastAPI's default validation-error schema."""

FILE_RESPONSES: dict[int | str, dict[str, Any]] = {
    413: {
        "model": ErrorOut,
        "description": "File over the size limit (`too_large`) or with more faces than "
        "the limit (`too_many_faces`)",
    },
    415: {
        "model": ErrorOut,
        "description": "Not a mesh file type (`unsupported_format`) or not multipart",
    },
}
"""Declared by every request that can carry a mesh file."""

UNAUTHORIZED_RESPONSE: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorOut, "description": "API key missing or wrong (`unauthorized`)"},
}
"""Declared by every POST and DELETE (they need the API key when one is configured)."""


def multipart_body(
    properties: dict[str, Any],
    *,
    required: tuple[str, ...] = (),
    encoding: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """``openapi_extra`` of a route that reads its multipart form itself (streaming):
    the form's fields as OpenAPI describes them."""
    schema: dict[str, Any] = {"type": "object"}
    if required:
        schema["required"] = list(required)
    schema["properties"] = properties
    form: dict[str, Any] = {"schema": schema}
    if encoding is not None:
        form["encoding"] = encoding
    return {"requestBody": {"required": True, "content": {"multipart/form-data": form}}}
