"""What the key a request sends may do: the admin key's, or a stored key's scope in a
collection, each lookup reused for a moment (:class:`KeyRing`)."""

from __future__ import annotations

import hashlib
import hmac
import threading
import time
from dataclasses import dataclass

from pydantic import SecretStr
from sqlalchemy.orm import Session, sessionmaker

from .models import Scope
from .repositories import keys

#: Every key made by the service starts with this (so a leaked one is recognizable).
KEY_PREFIX = "shp_"
#: How long a key's lookup is reused: a revoked key is refused by every API process
#: within this time.
CACHE_SECONDS = 0.5


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
            row = keys.by_sha256(session, digest)
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
