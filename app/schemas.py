"""Shared by every resource: the error body, UTC timestamps, the OpenAPI description
of a multipart request body, and the false acceptance rate a search or a verification
takes (:func:`parse_far`)."""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, Field

from worker.engine.formats import MESH_FORMATS

from .errors import InvalidInputError


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
    503: {
        "model": ErrorOut,
        "description": "A dependency is down (`database_unavailable`, `queue_unavailable`; "
        "with `Retry-After`), or the index is still loading (`index_loading`)",
        "headers": {
            "Retry-After": {"description": "seconds to wait", "schema": {"type": "integer"}}
        },
    },
}
"""Responses every router declares, replacing FastAPI's default validation-error schema."""

#: What every text the service keeps (a name, a label) or looks up may hold: any
#: character but NUL, which PostgreSQL cannot store; the same rule on every database.
TEXT_PATTERN = "^[^\\x00]*$"


def check_text(value: str, what: str) -> str:
    """``value`` if it follows :data:`TEXT_PATTERN`.

    Raises
    ------
    InvalidInputError
        ``invalid_text``: it holds a NUL character.
    """
    if "\x00" in value:
        raise InvalidInputError(
            f"The {what} contains a NUL character (U+0000), which no text field may hold.",
            code="invalid_text",
        )
    return value


def threshold_out(threshold: float) -> float | None:
    """A score threshold as the answers give it: None when it accepts nothing (-inf: at
    that FAR even the closest impostor pair is too close to accept any score), which JSON
    cannot write as a number."""
    return threshold if math.isfinite(threshold) else None


THRESHOLD_DESCRIPTION = (
    "accept a pair whose score is at most this; null: nothing is accepted at this FAR "
    "(even the closest impostor pair is too close)"
)


#: The longest file name an upload may carry (as the names and labels it may take).
MAX_FILENAME = 255
_EXTENSIONS = "|".join(MESH_FORMATS)
MESH_FILE: dict[str, Any] = {
    "type": "string",
    # OpenAPI 3.1's spelling of a file part; "mesh" says which files (JSON Schema's
    # formats are annotations: a client or fuzzer that knows it generates real meshes).
    "contentMediaType": "application/octet-stream",
    "format": "mesh",
    "minLength": 1,  # an empty file is 422 empty_mesh
    "description": "a triangle mesh file, the organized point cloud a depth camera "
    "writes (.pcd: one point per pixel, triangulated by its grid), a laser scanner's "
    "structured scan (.e57, one scan: its points' rows and columns are its grid), or one "
    "view's points without a grid (.xyz, .pts, .csv, a .ply or .obj without faces: in "
    "the sensor's frame, or any other and seen from afar along their thinnest "
    "direction; a .pcd of HEIGHT 1 from its VIEWPOINT), triangulated as seen from the "
    "sensor (points that are not one view are 422 `no_faces`): "
    + " ".join(f".{f}" for f in MESH_FORMATS)
    + ", optionally .gz-compressed, told by the file name's extension (any other is "
    "415 `unsupported_format`); a file that is not a readable surface of at least 10 "
    "vertices is 422 (`unreadable_mesh`, `degenerate_mesh`, ...)",
}
"""The schema of a mesh file in a multipart form."""

MESH_FILE_ENCODING: dict[str, Any] = {
    "contentType": "application/octet-stream",
    "headers": {
        "Content-Disposition": {
            "description": "the file name's extension tells the format",
            "schema": {
                "type": "string",
                # At most MAX_FILENAME characters (filename_too_long beyond).
                "pattern": rf'filename="(?=[^"]{{1,{MAX_FILENAME}}}")'
                rf'[^"]*\.({_EXTENSIONS})(\.gz)?"',
                "example": 'form-data; name="file"; filename="wolf0.off"',
            },
        }
    },
}
"""The multipart encoding of a mesh file part (its name's extension)."""

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

ACCESS_RESPONSES: dict[int | str, dict[str, Any]] = {
    401: {"model": ErrorOut, "description": "API key missing, wrong or revoked (`unauthorized`)"},
    403: {
        "model": ErrorOut,
        "description": "The key may not do this: another collection's, or too small a scope "
        "(`forbidden`)",
    },
}
"""Declared by every route that needs a key when the service sets one."""


def or_blank(schema: dict[str, Any]) -> dict[str, Any]:
    """A form field's schema: the field's, or blank (the default), as an HTML form sends
    a field left empty."""
    value = {k: v for k, v in schema.items() if k != "description"}
    return {
        "anyOf": [value, {"type": "string", "maxLength": 0}],
        "description": schema["description"] + " (blank: the default)",
    }


def _is_object(schema: dict[str, Any]) -> bool:
    return any(s.get("type") == "object" for s in [schema, *schema.get("anyOf", [])])


def multipart_body(
    properties: dict[str, Any],
    *,
    required: tuple[str, ...] = (),
    one_of_each: tuple[tuple[str, str], ...] = (),
) -> dict[str, Any]:
    """``openapi_extra`` of a route that reads its multipart form itself (streaming):
    the form's fields as OpenAPI describes them. No other field is accepted;
    ``one_of_each`` lists the pairs of fields of which exactly one must be sent; a
    ``file`` field is a mesh file (:data:`MESH_FILE`)."""
    schema: dict[str, Any] = {"type": "object", "additionalProperties": False}
    if required:
        schema["required"] = list(required)
    if one_of_each:
        schema["allOf"] = [
            {"oneOf": [{"required": [a]}, {"required": [b]}]} for a, b in one_of_each
        ]
    schema["properties"] = properties
    form: dict[str, Any] = {"schema": schema}
    encoding = {"file": MESH_FILE_ENCODING} if "file" in properties else {}
    encoding |= {  # objects travel as JSON text
        name: {"contentType": "application/json"}
        for name, value in properties.items()
        if _is_object(value)
    }
    if encoding:
        form["encoding"] = encoding
    return {"requestBody": {"required": True, "content": {"multipart/form-data": form}}}


def parse_far(text: str | None) -> float | None:
    """A false acceptance rate: a number strictly between 0 and 1, or nothing."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 < value < 1.0:
        raise InvalidInputError(
            "far must be a false acceptance rate between 0 and 1, e.g. 0.01.", code="invalid_far"
        )
    return value
