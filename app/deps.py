"""Injected dependencies (``Annotated`` aliases) used by the routers."""

from __future__ import annotations

from collections.abc import AsyncIterator, Iterator
from typing import Annotated, Any

from fastapi import Depends, Path, Request
from fastapi.security import APIKeyHeader
from pydantic import BeforeValidator
from sqlalchemy.orm import Session

from .db import unit_of_work
from .errors import ForbiddenError, InvalidInputError, UnauthorizedError
from .gallery.service import Gallery
from .keyring import Grant
from .links import NAME_PATTERN
from .models import DEFAULT_COLLECTION, Scope
from .state import AppState
from .storage import ReceivedFile
from .uploads import MultipartUpload, receive_multipart

# The largest id a JSON number holds exactly (JavaScript's, and the schema's own
# numbers are doubles); ids are far below it, and a larger one is invalid input, not a 500.
MAX_ROW_ID = 2**53


def _digits_only(value: object) -> object:
    """An id in a path is its digits: no sign, space or other character around them
    (Python's int() would take " 5\v")."""
    if isinstance(value, str) and not (value.isascii() and value.isdigit()):
        raise ValueError("an id is a whole number written in digits only")
    return value


RowId = Annotated[
    int,
    Path(ge=1, le=MAX_ROW_ID, description="the row's id"),
    BeforeValidator(_digits_only),
]


def get_state(request: Request) -> AppState:
    state: AppState = request.app.state.shapes
    return state


StateDep = Annotated[AppState, Depends(get_state)]


def collection_parameter(
    collection: Annotated[
        str, Path(pattern=NAME_PATTERN, description="the collection's name (GET /collections)")
    ],
) -> None:
    """Declares and checks the ``{collection}`` of every path under
    ``/collections/{collection}/`` (``dependencies=`` of those routes)."""


def get_gallery(request: Request, state: StateDep) -> Gallery:
    """The gallery a request works on: its path's ``{collection}``, else the default."""
    return state.galleries.named(request.path_params.get("collection", DEFAULT_COLLECTION))


GalleryDep = Annotated[Gallery, Depends(get_gallery)]


def get_session(request: Request, state: StateDep) -> Iterator[Session]:
    """One unit of work per request: commit at the end (then run after-commit work,
    such as enqueueing jobs), roll back on error. Reads don't take SQLite's write lock."""
    factory = state.read_sessions if request.method in ("GET", "HEAD") else state.sessions
    with unit_of_work(factory) as session:
        yield session


# scope="function": the commit happens when the endpoint returns, before the
# response is sent, so a client never sees an id that is not committed yet.
SessionDep = Annotated[Session, Depends(get_session, scope="function")]


def get_read_session(state: StateDep) -> Iterator[Session]:
    """A read-only unit of work for a POST that changes nothing (searches, verification).

    A write session holds SQLite's write lock from its first statement to the end
    of the request; a search that waits seconds for its descriptor must not hold it,
    or every enrollment and every other search waits behind it.
    """
    with unit_of_work(state.read_sessions) as session:
        yield session


ReadSessionDep = Annotated[Session, Depends(get_read_session, scope="function")]


API_KEY_HEADER = APIKeyHeader(
    name="X-API-Key",
    auto_error=False,
    description="Needed by every request for a collection's resources when the service "
    "sets SHAPES_API_KEY: that key (the admin), or one it made with POST /keys.",
)


def get_grant(
    state: StateDep, key: Annotated[str | None, Depends(API_KEY_HEADER)] = None
) -> Grant | None:
    """What the request's key may do; None when the service is open (no key configured).

    Runs before the body is read, so an unauthorized upload costs no disk.
    """
    if state.keys.open:
        return None
    grant = None if key is None else state.keys.grant(key)
    if grant is None:
        raise UnauthorizedError(
            "This service needs an API key: send it in the X-API-Key header."
            if key is None
            else "The API key in the X-API-Key header is not valid (or was revoked)."
        )
    return grant


GrantDep = Annotated[Grant | None, Depends(get_grant)]


def check_grant(grant: Grant | None, collection_id: int | None, needed: Scope, what: str) -> None:
    """Refuse (403) a key that may not do ``needed`` in the collection (None: in all)."""
    if grant is not None and not grant.allows(collection_id, needed):
        raise ForbiddenError(f"This API key may not {what}.")


_WHAT = {
    Scope.read: "read this collection",
    Scope.write: "change this collection",
    Scope.admin: "administer this collection",
}


def _access(needed: Scope, *, everything: bool = False) -> Any:
    def check(request: Request, state: StateDep, grant: GrantDep) -> None:
        if grant is None:
            return
        if everything:
            check_grant(grant, None, needed, "administer the service")
            return
        params = request.path_params
        name = params.get("collection") or params.get("name") or DEFAULT_COLLECTION
        gallery = state.galleries.find(name)  # unknown: 403 unless the key may see all
        check_grant(
            grant, None if gallery is None else gallery.collection_id, needed, _WHAT[needed]
        )

    return Depends(check)


READ_ACCESS = [_access(Scope.read)]
"""``dependencies=`` of the routes that read a collection (its path's, or the default)."""
WRITE_ACCESS = [_access(Scope.write)]
"""``dependencies=`` of the routes that change a collection's meshes."""
ADMIN_ACCESS = [_access(Scope.admin)]
"""``dependencies=`` of the routes that delete a collection."""
SERVICE_ADMIN = [_access(Scope.admin, everything=True)]
"""``dependencies=`` of the routes that create collections and manage keys."""


def document_open_access(openapi: dict[str, Any]) -> None:
    """Without a configured key nothing asks for one: drop the key's security
    requirement and its 401 and 403 answers from the schema (in place)."""
    for operations in openapi.get("paths", {}).values():
        for operation in operations.values():
            operation.pop("security", None)
            operation.get("responses", {}).pop("401", None)
            operation.get("responses", {}).pop("403", None)
    schemes = openapi.get("components", {}).get("securitySchemes", {})
    schemes.pop(API_KEY_HEADER.scheme_name, None)
    if not schemes:
        openapi.get("components", {}).pop("securitySchemes", None)


async def get_multipart(request: Request, state: StateDep) -> AsyncIterator[MultipartUpload]:
    settings = state.settings
    upload = await receive_multipart(
        request,
        tmp_dir=settings.tmp_dir,
        max_bytes=settings.max_upload_bytes,
        max_field_bytes=settings.max_field_bytes,
    )
    try:
        yield upload
    finally:
        upload.discard()  # a stored upload was moved away; this removes only leftovers


MultipartDep = Annotated[MultipartUpload, Depends(get_multipart)]


def require_file(upload: MultipartUpload) -> ReceivedFile:
    if upload.file is None:
        raise InvalidInputError(
            "The request has no mesh file: send it in a multipart field called 'file'.",
            code="missing_file",
        )
    if upload.file.size == 0:
        raise InvalidInputError("The uploaded file is empty.", code="empty_mesh")
    return upload.file
