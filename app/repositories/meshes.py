"""All queries on meshes and their descriptors."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, Literal

from sqlalchemy import func, select
from sqlalchemy.orm import Session, selectinload

from ..models import Descriptor, Job, Mesh, MeshStatus, Preview


def get(session: Session, mesh_id: int) -> Mesh | None:
    return session.get(Mesh, mesh_id)


def get_by_sha256(session: Session, collection_id: int, sha256: str) -> Mesh | None:
    """The collection's mesh of these bytes."""
    return session.scalar(
        select(Mesh).where(Mesh.collection_id == collection_id, Mesh.sha256 == sha256)
    )


def storage_shared(session: Session, storage_path: str, collection_id: int) -> bool:
    """Whether a mesh outside ``collection_id`` keeps its bytes at ``storage_path``."""
    other = select(Mesh.id).where(
        Mesh.storage_path == storage_path, Mesh.collection_id != collection_id
    )
    return session.scalar(other.limit(1)) is not None


def ids_with_label(session: Session, collection_id: int, label: str) -> list[int]:
    query = select(Mesh.id).where(Mesh.collection_id == collection_id, Mesh.label == label)
    return list(session.scalars(query.order_by(Mesh.id)))


def add(session: Session, mesh: Mesh) -> Mesh:
    session.add(mesh)
    session.flush()
    return mesh


def delete(session: Session, mesh: Mesh) -> None:
    session.delete(mesh)
    session.flush()


Order = Literal["oldest", "newest", "name", "label", "status"]
#: The orders a listing can be sorted in (each ends on the id, so pages never overlap).
ORDERS: dict[Order, tuple[Any, ...]] = {
    "oldest": (Mesh.id,),
    "newest": (Mesh.id.desc(),),
    "name": (Mesh.name, Mesh.id),
    "label": (Mesh.label, Mesh.name, Mesh.id),
    "status": (Mesh.status, Mesh.id),
}


def list_page(
    session: Session,
    collection_id: int,
    *,
    label: str | None,
    status: str | None,
    offset: int,
    limit: int,
    order: Order = "oldest",
) -> tuple[list[Mesh], int]:
    query = select(Mesh).where(Mesh.collection_id == collection_id)
    if label is not None:
        query = query.where(Mesh.label == label)
    if status is not None:
        query = query.where(Mesh.status == status)
    total = session.scalar(select(func.count()).select_from(query.subquery())) or 0
    rows = session.scalars(
        query.order_by(*ORDERS[order]).offset(offset).limit(limit).options(selectinload(Mesh.jobs))
    ).all()
    return list(rows), total


def by_ids(session: Session, ids: list[int]) -> dict[int, Mesh]:
    if not ids:
        return {}
    return {m.id: m for m in session.scalars(select(Mesh).where(Mesh.id.in_(ids)))}


def get_descriptor(session: Session, mesh_id: int, preset: str, version: int) -> Descriptor | None:
    return session.scalar(
        select(Descriptor).where(
            Descriptor.mesh_id == mesh_id,
            Descriptor.preset == preset,
            Descriptor.preset_version == version,
        )
    )


def upsert_descriptor(session: Session, descriptor: Descriptor) -> Descriptor:
    existing = get_descriptor(
        session, descriptor.mesh_id, descriptor.preset, descriptor.preset_version
    )
    if existing is not None:
        session.delete(existing)
        session.flush()
    session.add(descriptor)
    session.flush()
    return descriptor


def get_preview(session: Session, mesh_id: int) -> Preview | None:
    return session.get(Preview, mesh_id)


def has_preview(session: Session, mesh_id: int) -> bool:
    """Whether the mesh has a preview (without reading its bytes)."""
    return session.scalar(select(Preview.mesh_id).where(Preview.mesh_id == mesh_id)) is not None


def put_preview(session: Session, mesh_id: int, glb: bytes, png: bytes) -> None:
    """Store (or replace) a mesh's preview and thumbnail."""
    existing = session.get(Preview, mesh_id)
    if existing is None:
        session.add(Preview(mesh_id=mesh_id, glb=glb, png=png))
    else:
        existing.glb, existing.png = glb, png
    session.flush()


def _in_collection(collection_id: int) -> Any:
    """The condition "the descriptor's mesh is in the collection"."""
    return Descriptor.mesh_id.in_(select(Mesh.id).where(Mesh.collection_id == collection_id))


def described_labels(
    session: Session, collection_id: int, preset: str, version: int
) -> dict[int, str | None]:
    """mesh id -> label (None without one) of a collection's meshes with a descriptor of
    this preset version."""
    query = (
        select(Mesh.id, Mesh.label)
        .join(Descriptor, Descriptor.mesh_id == Mesh.id)
        .where(
            Mesh.collection_id == collection_id,
            Descriptor.preset == preset,
            Descriptor.preset_version == version,
        )
    )
    return dict(session.execute(query).tuples().all())


def description_progress(
    session: Session, collection_id: int, preset: str, version: int
) -> tuple[int, int]:
    """``(described, describable)`` of a collection: meshes with a descriptor of this
    preset version, and meshes that have one or are waiting for one (the failed left
    out)."""
    described = session.scalar(
        select(func.count(Descriptor.id)).where(
            _in_collection(collection_id),
            Descriptor.preset == preset,
            Descriptor.preset_version == version,
        )
    )
    describable = session.scalar(
        select(func.count(Mesh.id)).where(
            Mesh.collection_id == collection_id, Mesh.status != MeshStatus.failed.value
        )
    )
    return int(described or 0), int(describable or 0)


def iter_descriptors(
    session: Session,
    collection_id: int,
    preset: str,
    version: int,
    mesh_ids: set[int] | None = None,
    batch: int = 500,
) -> Iterator[tuple[int, str | None, bytes]]:
    """(mesh id, label, npz bytes) of a collection's stored descriptors, streamed in
    batches."""
    query = (
        select(Descriptor.mesh_id, Mesh.label, Descriptor.data)
        .join(Mesh, Mesh.id == Descriptor.mesh_id)
        .where(
            Mesh.collection_id == collection_id,
            Descriptor.preset == preset,
            Descriptor.preset_version == version,
        )
    )
    if mesh_ids is not None:
        ids = sorted(mesh_ids)
        for start in range(0, len(ids), batch):
            chunk = ids[start : start + batch]
            yield from session.execute(query.where(Descriptor.mesh_id.in_(chunk))).tuples()
        return
    yield from session.execute(query.execution_options(yield_per=batch)).tuples()


def meshes_missing_descriptor(
    session: Session, collection_id: int, preset: str, version: int
) -> list[Mesh]:
    """A collection's meshes with neither a descriptor nor a job for this preset version."""
    has_descriptor = select(Descriptor.id).where(
        Descriptor.mesh_id == Mesh.id,
        Descriptor.preset == preset,
        Descriptor.preset_version == version,
    )
    has_job = select(Job.id).where(
        Job.mesh_id == Mesh.id, Job.preset == preset, Job.preset_version == version
    )
    query = select(Mesh).where(
        Mesh.collection_id == collection_id, ~has_descriptor.exists(), ~has_job.exists()
    )
    return list(session.scalars(query))


def descriptors_for(
    session: Session, mesh_ids: list[int], preset: str, version: int
) -> dict[int, Descriptor]:
    if not mesh_ids:
        return {}
    rows = session.scalars(
        select(Descriptor).where(
            Descriptor.mesh_id.in_(mesh_ids),
            Descriptor.preset == preset,
            Descriptor.preset_version == version,
        )
    )
    return {d.mesh_id: d for d in rows}
