"""Response models shared by every resource: the error body and UTC timestamps."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Annotated

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


ERROR_RESPONSES: dict[int | str, dict] = {
    422: {"model": ErrorOut, "description": "Invalid input (`invalid_input` or a specific code)"},
}
"""Responses every router declares, replacing FastAPI's default validation-error schema."""

FILE_RESPONSES: dict[int | str, dict] = {
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

UNAUTHORIZED_RESPONSE: dict[int | str, dict] = {
    401: {"model": ErrorOut, "description": "API key missing or wrong (`unauthorized`)"},
}
"""Declared by every POST and DELETE (they need the API key when one is configured)."""
