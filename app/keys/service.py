"""Rules of API keys: making one (shown once, stored hashed), resolving the key a request
sends to what it may do (:class:`KeyRing`), and revoking one."""

from __future__ import annotations

import hashlib
import hmac
import secrets
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

from pydantic import SecretStr
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from ..collections import repository as collections
from ..db import after_commit
from ..errors import ConflictError, NotFoundError
from ..models import ApiKey, Collection, Scope

#: Every key made by the service starts with this (so a leaked one is recognizable).
KEY_PREFIX = "shp_"
#: How long a key's lookup is reused: a revoked key is refused by every API process
#: within this time.
CACHE_SECONDS = 0.5
ALL = "*"


@dataclass(frozen=True)
class Grant:
    """What a key may do: ``scope`` in one collection, or in all (``collection_id`` None)."""

    collection_id: int | None
    scope: Scope

    def allows(self, collection_id: int | None, needed: Scope) -> bool:
        """Whether it may do ``needed`` in the collection (None: in every collection)."""
        mine = self.collection_id is None or self.collection_id == collection_id
        return mine and self.scope.allows(needed)


def key_sha256(key: str) -> str:
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


class KeyRing:
    """Resolves the key a request sends to its :class:`Grant`.

    The configured key (``SHAPES_API_KEY``) is the admin of everything; the others are
    looked up by their hash, each answer reused for ``CACHE_SECONDS``. Without a
    configured key the service is open: :attr:`open`, and no key means anything.
    """

    def __init__(self, admin_key: SecretStr | None, read_sessions: sessionmaker[Session]) -> None:
        self._admin = None if admin_key is None else admin_key.get_secret_value().encode()
        self._read_sessions = read_sessions
        self._cache: dict[str, tuple[Grant | None, float]] = {}
        self._lock = threading.Lock()

    @property
    def open(self) -> bool:
        return self._admin is None

    def grant(self, key: str) -> Grant | None:
        """The key's grant; None if it is not a key of this service (or was revoked)."""
        # Constant time: how much of a guess matches must not show in the response time.
        if self._admin is not None and hmac.compare_digest(key.encode("utf-8"), self._admin):
            return Grant(None, Scope.admin)
        if not key.startswith(KEY_PREFIX):
            return None
        digest = key_sha256(key)
        now = time.monotonic()
        with self._lock:
            cached = self._cache.get(digest)
        if cached is not None and cached[1] > now:
            return cached[0]
        with self._read_sessions() as session:
            row = session.scalar(select(ApiKey).where(ApiKey.key_sha256 == digest))
        grant = None if row is None else Grant(row.collection_id, Scope(row.scope))
        with self._lock:
            if len(self._cache) > 10_000:  # keys guessed at random: forget them all
                self._cache.clear()
            self._cache[digest] = (grant, now + CACHE_SECONDS)
        return grant

    def forget(self, digest: str | None = None) -> None:
        """Drop a revoked key's cached grant on this API process at once (None: every
        key's, as when a collection and its keys are deleted)."""
        with self._lock:
            if digest is None:
                self._cache.clear()
            else:
                self._cache.pop(digest, None)


@dataclass
class KeyView:
    row: ApiKey
    collection: str


def _collection_name(session: Session, collection_id: int | None) -> str:
    if collection_id is None:
        return ALL
    row = session.get(Collection, collection_id)
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
    made = ApiKey(key_sha256=key_sha256(key), collection_id=collection_id, scope=scope.value)
    session.add(made)
    session.flush()
    return KeyView(made, collection), key


def list_all(session: Session) -> list[KeyView]:
    rows: Sequence[ApiKey] = session.scalars(select(ApiKey).order_by(ApiKey.id)).all()
    return [KeyView(r, _collection_name(session, r.collection_id)) for r in rows]


def revoke(session: Session, ring: KeyRing, key_id: int) -> None:
    """Delete the key: refused at once here, and by other API processes within
    ``CACHE_SECONDS``."""
    row = session.get(ApiKey, key_id)
    if row is None:
        raise NotFoundError(f"There is no key with id {key_id}.", code="key_not_found")
    digest = row.key_sha256
    session.delete(row)
    session.flush()
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
