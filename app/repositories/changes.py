"""The gallery's change log: shapes added and removed, in commit order.

Every transaction that makes a shape searchable (the collector storing its
descriptor) or takes it away (a delete) records a change in the same
transaction. Each API process follows the log from the position it loaded its
index at (:meth:`app.gallery.service.Gallery.follow`), so several replicas on one
database keep identical indexes, and a shape enrolled through one is searchable
on all of them after one collector interval.

Sequence numbers must become visible in order, or a follower that has read
change 11 would never see a change 10 committed after it. SQLite has one writer
at a time; on PostgreSQL the writers of changes take a lock on the table
(released at commit) before inserting, which serializes them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

from sqlalchemy import func, select, text
from sqlalchemy.orm import Session

from ..models import GalleryChange

Action = Literal["add", "remove"]


def record(session: Session, mesh_id: int, collection_id: int, action: Action) -> None:
    """Log that ``mesh_id`` enters (``add``) or leaves (``remove``) its collection's gallery."""
    if session.get_bind().dialect.name == "postgresql":
        # Conflicts with itself only: readers and other tables are not held up.
        session.execute(text("LOCK TABLE gallery_changes IN SHARE ROW EXCLUSIVE MODE"))
    session.add(GalleryChange(mesh_id=mesh_id, collection_id=collection_id, action=action))


def latest(session: Session) -> int:
    """The last sequence number committed (0 for an empty log)."""
    return int(session.scalar(select(func.coalesce(func.max(GalleryChange.id), 0))) or 0)


def since(session: Session, collection_id: int, after: int, limit: int) -> Sequence[GalleryChange]:
    """A collection's changes after sequence number ``after``, oldest first, at most
    ``limit``."""
    query = (
        select(GalleryChange)
        .where(GalleryChange.collection_id == collection_id, GalleryChange.id > after)
        .order_by(GalleryChange.id)
        .limit(limit)
    )
    return session.scalars(query).all()
