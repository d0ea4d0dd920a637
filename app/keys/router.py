"""HTTP layer of /keys: make, list and revoke API keys (the admin key's business)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Response, status

from ..deps import SERVICE_ADMIN, RowId, SessionDep, StateDep
from ..models import Scope
from ..schemas import ACCESS_RESPONSES, ERROR_RESPONSES
from . import service
from .schemas import KeyIn, KeyList, KeyOut, NewKeyOut

router = APIRouter(
    prefix="/keys",
    tags=["keys"],
    dependencies=SERVICE_ADMIN,
    responses=ERROR_RESPONSES
    | ACCESS_RESPONSES
    | {409: {"description": "The service has no admin key, so no keys (`no_admin_key`)"}},
)

NOT_FOUND: dict[int | str, dict[str, Any]] = {
    404: {"description": "No such key (`key_not_found`) or collection (`collection_not_found`)"}
}


def key_out(view: service.KeyView) -> KeyOut:
    row = view.row
    return KeyOut(
        id=row.id, collection=view.collection, scope=Scope(row.scope), created_at=row.created_at
    )


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=NewKeyOut,
    operation_id="create_key",
    summary="Make an API key for one collection (or all) with a scope",
    description=(
        "The answer holds the key itself, shown this once: only its SHA-256 is stored.\n\n"
        "`curl -H \"X-API-Key: $SHAPES_API_KEY\" -H 'Content-Type: application/json' "
        '-d \'{"collection": "casts", "scope": "read"}\' http://127.0.0.1:8000/keys`'
    ),
    responses=NOT_FOUND,
)
def create_key(body: KeyIn, session: SessionDep, state: StateDep) -> NewKeyOut:
    service.require_keys(state.keys)
    view, key = service.create(session, collection=body.collection, scope=body.scope)
    return NewKeyOut(**key_out(view).model_dump(), key=key)


@router.get(
    "", response_model=KeyList, operation_id="list_keys", summary="Every key (not the keys)"
)
def list_keys(session: SessionDep, state: StateDep) -> KeyList:
    service.require_keys(state.keys)
    return KeyList(items=[key_out(v) for v in service.list_all(session)])


@router.delete(
    "/{key_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    operation_id="revoke_key",
    summary="Revoke a key (refused by every API process within a second)",
    responses=NOT_FOUND,
)
def revoke_key(key_id: RowId, session: SessionDep, state: StateDep) -> Response:
    service.require_keys(state.keys)
    service.revoke(session, state.keys, key_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
