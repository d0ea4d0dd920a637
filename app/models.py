"""Tables: collections, meshes (uploads), descriptors (per preset and version), jobs,
previews."""

from __future__ import annotations

from datetime import UTC, datetime
from enum import StrEnum
from typing import Any

from sqlalchemy import JSON, ForeignKey, Index, LargeBinary, String, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column, relationship

from .db import Base


def utcnow() -> datetime:
    return datetime.now(UTC).replace(tzinfo=None)


class MeshStatus(StrEnum):
    queued = "queued"
    processing = "processing"
    ready = "ready"
    failed = "failed"


class JobStatus(StrEnum):
    queued = "queued"
    processing = "processing"
    succeeded = "succeeded"
    failed = "failed"


UNFINISHED_JOB = (JobStatus.queued.value, JobStatus.processing.value)


#: The collection the paths without ``/collections/{name}`` work on (made by migration 0007).
DEFAULT_COLLECTION = "default"


class Units(StrEnum):
    """What a collection's files' coordinates mean: ``any``, arbitrary units (shapes are
    compared scale-free); ``metric``, one physical unit for every file, so size is a cue."""

    any = "any"
    metric = "metric"


class Collection(Base):
    """One gallery: its own meshes, index, calibration, preset and units."""

    __tablename__ = "collections"
    __table_args__ = {"sqlite_autoincrement": True}  # a re-made name is another collection

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    units: Mapped[str] = mapped_column(String(16), default=Units.any.value)
    # None: the service's preset (SHAPES_PRESET), followed when it changes.
    preset: Mapped[str | None] = mapped_column(String(64))
    # Weights pinned by an admin (PUT /collections/{name}/fusion); None: learned or preset.
    fusion_weights: Mapped[dict[str, float] | None] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Scope(StrEnum):
    """What an API key may do in its collections, each including the one before."""

    read = "read"  # list, download, search, verify, read the calibration
    write = "write"  # also enroll and delete meshes
    admin = "admin"  # also create and delete collections and keys

    def allows(self, needed: Scope) -> bool:
        order = list(Scope)
        return order.index(self) >= order.index(needed)


class ApiKey(Base):
    """A key made with ``POST /keys``: only its SHA-256 is stored (a key is 32 random
    bytes, so its hash cannot be reversed by guessing)."""

    __tablename__ = "api_keys"
    __table_args__ = {"sqlite_autoincrement": True}  # a revoked key's id is never reused

    id: Mapped[int] = mapped_column(primary_key=True)
    key_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    # None: every collection ("*").
    collection_id: Mapped[int | None] = mapped_column(
        ForeignKey("collections.id", ondelete="CASCADE"), index=True
    )
    scope: Mapped[str] = mapped_column(String(8))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Mesh(Base):
    """One uploaded file in a collection, its bytes stored content-addressed under
    ``uploads/`` (shared by the collections that enrolled the same bytes)."""

    __tablename__ = "meshes"
    __table_args__ = (
        UniqueConstraint("collection_id", "sha256"),
        {"sqlite_autoincrement": True},  # ids of deleted meshes are never reused
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    # Server default: a row written by an API process of the version before collections.
    collection_id: Mapped[int] = mapped_column(
        ForeignKey("collections.id", ondelete="CASCADE"), index=True, server_default="1"
    )
    sha256: Mapped[str] = mapped_column(String(64), index=True)
    name: Mapped[str] = mapped_column(String(255))
    label: Mapped[str | None] = mapped_column(String(255), index=True)
    meta: Mapped[dict[str, Any]] = mapped_column("metadata", JSON, default=dict)
    filename: Mapped[str] = mapped_column(String(255))
    size_bytes: Mapped[int]
    storage_path: Mapped[str] = mapped_column(String(512))
    status: Mapped[str] = mapped_column(String(16), index=True, default=MeshStatus.queued.value)
    error_code: Mapped[str | None] = mapped_column(String(64))
    error_detail: Mapped[str | None] = mapped_column(String(1024))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)

    descriptors: Mapped[list[Descriptor]] = relationship(
        back_populates="mesh", cascade="all, delete-orphan", passive_deletes=True
    )
    jobs: Mapped[list[Job]] = relationship(
        back_populates="mesh",
        cascade="all, delete-orphan",
        passive_deletes=True,
        order_by="Job.id",
    )
    preview: Mapped[Preview | None] = relationship(
        back_populates="mesh", cascade="all, delete-orphan", passive_deletes=True
    )


class Descriptor(Base):
    """A mesh's modal descriptors under one preset version (``ShapeDescriptor`` as npz)."""

    __tablename__ = "descriptors"
    __table_args__ = (UniqueConstraint("mesh_id", "preset", "preset_version"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    mesh_id: Mapped[int] = mapped_column(ForeignKey("meshes.id", ondelete="CASCADE"), index=True)
    preset: Mapped[str] = mapped_column(String(64))
    preset_version: Mapped[int]
    data: Mapped[bytes] = mapped_column(LargeBinary)
    input_vertices: Mapped[int]
    input_faces: Mapped[int]
    vertices: Mapped[int]
    timings: Mapped[dict[str, float]] = mapped_column(JSON, default=dict)
    # The described part's share of the file's surface (None: made before it was kept).
    kept_area_fraction: Mapped[float | None]
    # The point cloud the file was: its points and, organized, its grid [width, height]
    # (None: a mesh, a cloud without a grid, or made before they were kept).
    input_points: Mapped[int | None]
    input_grid: Mapped[list[int] | None] = mapped_column(JSON)
    # Of an organized cloud: the points of a floor, table or wall left out (None: not an
    # organized cloud, or made before they were left out).
    input_support: Mapped[int | None]
    # Of a cloud that was not one view (a whole object's): its points hidden from where it
    # was seen, left out (None: a mesh, one view, or made before they were left out).
    input_hidden: Mapped[int | None]
    # The largest share of the surface facing one way (None: made before it was kept).
    facing_share: Mapped[float | None]
    # Whether it was smoothed of a scanner's noise (None: made before it was kept).
    smoothed: Mapped[bool | None]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    mesh: Mapped[Mesh] = relationship(back_populates="descriptors")


class Job(Base):
    """One attempt series at describing a mesh with a preset, run by the queue."""

    __tablename__ = "jobs"
    __table_args__ = (
        Index("ix_jobs_status_id", "status", "id"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    mesh_id: Mapped[int] = mapped_column(ForeignKey("meshes.id", ondelete="CASCADE"), index=True)
    preset: Mapped[str] = mapped_column(String(64))
    preset_version: Mapped[int]
    task_id: Mapped[str] = mapped_column(String(64), unique=True)
    status: Mapped[str] = mapped_column(String(16), default=JobStatus.queued.value)
    enqueues: Mapped[int] = mapped_column(default=1)
    worker: Mapped[str | None] = mapped_column(String(255))
    error_code: Mapped[str | None] = mapped_column(String(64))
    error_detail: Mapped[str | None] = mapped_column(String(1024))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)

    mesh: Mapped[Mesh] = relationship(back_populates="jobs")


class Preview(Base):
    """What the web page shows of a described mesh: a small GLB and a PNG thumbnail
    (made by the descriptor job, ``worker/jobs/previews.py``)."""

    __tablename__ = "previews"

    mesh_id: Mapped[int] = mapped_column(
        ForeignKey("meshes.id", ondelete="CASCADE"), primary_key=True
    )
    glb: Mapped[bytes] = mapped_column(LargeBinary)
    png: Mapped[bytes] = mapped_column(LargeBinary)

    mesh: Mapped[Mesh] = relationship(back_populates="preview")


class QueryPreview(Base):
    """The preview (GLB) of a file recently searched with in a collection, by its
    content: in the database so that the link in a ``/query`` answer works on every API
    replica, and per collection so that only the collection searched serves it. Only the
    most recent ``query_previews_kept`` are kept (:mod:`app.repositories.query_previews`)."""

    __tablename__ = "query_previews"

    collection_id: Mapped[int] = mapped_column(
        ForeignKey("collections.id", ondelete="CASCADE"), primary_key=True
    )
    sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    glb: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)


class GalleryChange(Base):
    """One shape entering or leaving the gallery, in commit order: every API process
    follows this log to keep its in-memory index equal to the database
    (``app/repositories/changes.py``)."""

    __tablename__ = "gallery_changes"
    __table_args__ = {"sqlite_autoincrement": True}  # sequence numbers are never reused

    id: Mapped[int] = mapped_column(primary_key=True)
    mesh_id: Mapped[int]  # no foreign keys: a removal outlives its mesh and collection
    collection_id: Mapped[int] = mapped_column(index=True, server_default="1")
    action: Mapped[str] = mapped_column(String(8))  # "add" or "remove"
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Upload(Base):
    """An uploaded file's bytes, when the service keeps uploads in the database
    (``SHAPES_UPLOADS=database``; :class:`app.storage.DatabaseStore`)."""

    __tablename__ = "uploads"

    sha256: Mapped[str] = mapped_column(String(64), primary_key=True)
    # Deferred: checking that an upload exists, or deleting it, never loads its bytes.
    data: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)
