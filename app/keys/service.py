"""Rules of API keys: making one (shown once, stored hashed), listing them, and revoking
one (what a request's key may do is :mod:`app.keyring`'s)."""

from __future__ import annotations

import secrets
from dataclasses import dataclass

from sqlalchemy.orm import Session

from ..db import after_commit
from ..errors import ConflictError, NotFoundError
from ..keyring import KEY_PREFIX, KeyRing, key_sha256
from ..models import ApiKey, Scope
from ..repositories import collections, keys

ALL = "*"


@dataclass
class KeyView:
    row: ApiKey
    collection: str


def _collection_name(session: Session, collection_id: int | None) -> str:
    if collection_id is None:
        return ALL
    row = collections.get(session, collection_id)
    return ALL if row is None else row.name


def create(session: Session, *, collection: str, scope: Scope) -> tuple[KeyView, str]:
    """A new key for ``collection`` (a name, or ``*`` for all) and the key itself, which
    is never stored: only its hash.

    Raises
    ------
    NotFoundError
        ``collection_not_found``.
    """
    collection_id = None
    if collection != ALL:
        row = collections.get_by_name(session, collection)
        if row is None:
            raise NotFoundError(
                f"There is no collection called {collection!r} to make a key for.",
                code="collection_not_found",
            )
        collection_id = row.id
    key = KEY_PREFIX + secrets.token_urlsafe(32)
    made = keys.add(
        session, ApiKey(key_sha256=key_sha256(key), collection_id=collection_id, scope=scope.value)
    )
    return KeyView(made, collection), key


def list_all(session: Session) -> list[KeyView]:
    return [KeyView(r, _collection_name(session, r.collection_id)) for r in keys.all_rows(session)]


def revoke(session: Session, ring: KeyRing, key_id: int) -> None:
    """Delete the key: refused at once here, and by other API processes within
    ``CACHE_SECONDS``."""
    row = keys.get(session, key_id)
    if row is None:
        raise NotFoundError(f"There is no key with id {key_id}.", code="key_not_found")
    digest = row.key_sha256
    keys.delete(session, row)
    after_commit(session, lambda: ring.forget(digest))


def require_keys(ring: KeyRing) -> None:
    """Keys are made by the admin key: a service without one is open, and has none.

    Raises
    ------
    ConflictError
        ``no_admin_key``.
    """
    if ring.open:
        raise ConflictError(
            "This service has no admin key (SHAPES_API_KEY), so it is open to every "
            "request and keys would change nothing: set SHAPES_API_KEY to use keys.",
            code="no_admin_key",
        )
