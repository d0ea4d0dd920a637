"""Injected dependencies (``Annotated`` aliases) used by the routers."""

from __future__ import annotations

from collections.abc import AsyncIterator, Iterator
from typing import Annotated

from fastapi import Depends, Path, Request
from sqlalchemy.orm import Session

from .config import Settings
from .db import unit_of_work
from .errors import InvalidInputError
from .state import AppState
from .uploads import MultipartUpload, UploadedFile, receive_multipart

# SQLite's INTEGER is 64-bit: a larger id in a path is invalid input, not a 500.
RowId = Annotated[int, Path(ge=1, le=2**63 - 1, description="the row's id")]


def get_state(request: Request) -> AppState:
    return request.app.state.shapes


StateDep = Annotated[AppState, Depends(get_state)]


def get_settings(state: StateDep) -> Settings:
    return state.settings


SettingsDep = Annotated[Settings, Depends(get_settings)]


def get_session(request: Request, state: StateDep) -> Iterator[Session]:
    """One unit of work per request: commit at the end (then run after-commit work,
    such as enqueueing jobs), roll back on error. Reads don't take SQLite's write lock."""
    factory = state.read_sessions if request.method in ("GET", "HEAD") else state.sessions
    with unit_of_work(factory) as session:
        yield session


# scope="function": the commit happens when the endpoint returns, before the
# response is sent, so a client never sees an id that is not committed yet.
SessionDep = Annotated[Session, Depends(get_session, scope="function")]


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


def require_file(upload: MultipartUpload) -> UploadedFile:
    if upload.file is None:
        raise InvalidInputError(
            "The request has no mesh file: send it in a multipart field called 'file'.",
            code="missing_file",
        )
    if upload.file.size == 0:
        raise InvalidInputError("The uploaded file is empty.", code="empty_mesh")
    return upload.file
