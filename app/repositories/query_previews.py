"""All queries on the previews of recent query uploads."""

from __future__ import annotations

from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from ..models import QueryPreview, utcnow


def get_query_preview(session: Session, sha256: str) -> bytes | None:
    glb: bytes | None = session.scalar(
        select(QueryPreview.glb).where(QueryPreview.sha256 == sha256)
    )
    return glb


def has_query_preview(session: Session, sha256: str) -> bool:
    """Whether a recent query of these bytes left a preview (without reading it)."""
    found = session.scalar(select(QueryPreview.sha256).where(QueryPreview.sha256 == sha256))
    return found is not None


def put_query_preview(session: Session, sha256: str, glb: bytes, *, keep: int) -> None:
    """Store (or refresh) the preview of the file ``sha256``, then drop all but the
    ``keep`` most recent."""
    existing = session.get(QueryPreview, sha256)
    if existing is None:
        session.add(QueryPreview(sha256=sha256, glb=glb))
    else:
        existing.glb, existing.created_at = glb, utcnow()
    session.flush()
    newest = select(QueryPreview.sha256).order_by(QueryPreview.created_at.desc()).limit(keep)
    session.execute(delete(QueryPreview).where(QueryPreview.sha256.not_in(newest)))
