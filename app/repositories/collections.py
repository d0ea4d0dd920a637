"""All queries on collections."""

from __future__ import annotations

from collections.abc import Sequence

from sqlalchemy import case, func, select
from sqlalchemy.orm import Session

from ..models import Collection, Mesh, MeshStatus


def all_rows(session: Session) -> Sequence[Collection]:
    return session.scalars(select(Collection).order_by(Collection.id)).all()


def get_by_name(session: Session, name: str) -> Collection | None:
    return session.scalar(select(Collection).where(Collection.name == name))


def add(session: Session, collection: Collection) -> Collection:
    session.add(collection)
    session.flush()
    return collection


def mesh_counts(session: Session) -> dict[int, tuple[int, int]]:
    """collection id -> (meshes, ready meshes)."""
    ready = func.sum(case((Mesh.status == MeshStatus.ready.value, 1), else_=0))
    rows = session.execute(
        select(Mesh.collection_id, func.count(Mesh.id), ready).group_by(Mesh.collection_id)
    ).tuples()
    return {cid: (int(total), int(done or 0)) for cid, total, done in rows}


def meshes_of(session: Session, collection_id: int) -> Sequence[Mesh]:
    return session.scalars(select(Mesh).where(Mesh.collection_id == collection_id)).all()


def get(session: Session, collection_id: int) -> Collection | None:
    return session.get(Collection, collection_id)
