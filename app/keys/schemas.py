"""Request and response models of the key endpoints."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from ..models import Scope
from ..schemas import UtcDatetime


class KeyIn(BaseModel):
    model_config = ConfigDict(extra="forbid")

    collection: str = Field(
        pattern="^([A-Za-z0-9][A-Za-z0-9_-]{0,63}|\\*)$",
        description="the collection the key opens, or `*` for every collection",
    )
    scope: Scope = Field(
        description="`read`: list, download, search, verify; `write`: also enroll and "
        "delete meshes; `admin`: also delete the collection (and, for `*`, create "
        "collections and manage keys)"
    )


class KeyOut(BaseModel):
    id: int
    collection: str
    scope: Scope
    created_at: UtcDatetime


class NewKeyOut(KeyOut):
    key: str = Field(description="the key itself: shown this once, never stored")


class KeyList(BaseModel):
    items: list[KeyOut]
