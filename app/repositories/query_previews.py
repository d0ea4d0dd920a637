"""All queries on the previews of recent query uploads (each collection's own)."""

from __future__ import annotations

from typing import Any

from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from ..models import QueryPreview, utcnow


def _of(collection_id: int, sha256: str) -> tuple[Any, Any]:
    """The condition "the collection's preview of these bytes"."""
    return QueryPreview.collection_id == collection_id, QueryPreview.sha256 == sha256


def get_query_preview(session: Session, collection_id: int, sha256: str) -> bytes | None:
    glb: bytes | None = session.scalar(select(QueryPreview.glb).where(*_of(collection_id, sha256)))
    return glb


def has_query_preview(session: Session, collection_id: int, sha256: str) -> bool:
    """Whether a recent query of these bytes in the collection left a preview (without
    reading it)."""
    found = session.scalar(select(QueryPreview.sha256).where(*_of(collection_id, sha256)))
    return found is not None


def put_query_preview(
    session: Session, collection_id: int, sha256: str, glb: bytes, *, keep: int
) -> None:
    """Store (or refresh) the collection's preview of the file ``sha256``, then drop all
    but the ``keep`` most recent of every collection."""
    existing = session.get(QueryPreview, (collection_id, sha256))
    if existing is None:
        session.add(QueryPreview(collection_id=collection_id, sha256=sha256, glb=glb))
    else:
        existing.glb, existing.created_at = glb, utcnow()
    session.flush()
    newest = select(QueryPreview.created_at).order_by(QueryPreview.created_at.desc())
    oldest_kept = session.scalar(newest.offset(keep - 1).limit(1))
    if oldest_kept is not None:
        session.execute(delete(QueryPreview).where(QueryPreview.created_at < oldest_kept))
