"""Rules for enrolling, listing and deleting meshes (no HTTP types here)."""

from __future__ import annotations

import functools
import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from worker.engine.formats import mesh_format

from ..db import after_commit
from ..descriptors import TRANSIENT_FAILURES, enqueue_soon, enrolled_mesh, lost, new_job
from ..errors import ConflictError, InvalidInputError, NotFoundError
from ..gallery.service import Gallery
from ..models import UNFINISHED_JOB, Descriptor, Mesh, MeshStatus, Preview
from ..queue import QUEUE_ERRORS
from ..repositories import changes, jobs, meshes
from ..schemas import check_text
from ..state import AppState
from ..storage import ReceivedFile

log = logging.getLogger("shapes.meshes")

MAX_NAME = 255


def parse_metadata(text: str | None) -> dict[str, Any]:
    """The ``metadata`` form field: a JSON object (or nothing)."""
    if text is None or not text.strip():
        return {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        raise InvalidInputError(
            'The metadata field must be a JSON object, e.g. {"source": "scanner 3"}.',
            code="invalid_metadata",
        ) from None
    if not isinstance(value, dict):
        raise InvalidInputError(
            "The metadata field must be a JSON object, not a list or a single value.",
            code="invalid_metadata",
        )
    return value


def _text(value: str | None, what: str) -> str | None:
    if value is None:
        return None
    if len(value) > MAX_NAME:  # as sent, as the schema's maxLength counts
        raise InvalidInputError(f"The {what} is longer than {MAX_NAME} characters.")
    return check_text(value, what).strip() or None


def enroll(
    session: Session,
    state: AppState,
    gallery: Gallery,
    upload: ReceivedFile,
    *,
    name: str | None,
    label: str | None,
    metadata: str | None,
) -> tuple[Mesh, bool]:
    """Store an upload in ``gallery``'s collection and queue its descriptor; ``(mesh,
    queued)``: whether this request queued a description.

    The same bytes uploaded again to the collection return the existing mesh, described
    again when it failed for a transient reason or its job was lost (:func:`_retry`). The
    job is
    enqueued only after the commit that creates its row; while the queue is down,
    by the collector's sweep once it is back.
    """
    meta = parse_metadata(metadata)
    name = _text(name, "name") or upload.filename.split(".")[0] or upload.filename
    label = _text(label, "label")
    existing = meshes.get_by_sha256(session, gallery.collection_id, upload.sha256)
    if existing is not None:
        _same_format(existing, upload)
        return existing, _retry(session, state, gallery, existing)
    reference = state.store.put(session, upload)
    mesh = Mesh(
        collection_id=gallery.collection_id,
        sha256=upload.sha256,
        name=name,
        label=label,
        meta=meta,
        filename=upload.filename,
        size_bytes=upload.size,
        storage_path=reference,
        status=MeshStatus.queued.value,
    )
    try:
        meshes.add(session, mesh)
    except IntegrityError:  # the same bytes, uploaded concurrently, won the race
        session.rollback()
        existing = meshes.get_by_sha256(session, gallery.collection_id, upload.sha256)
        if existing is None:
            raise
        _same_format(existing, upload)
        return existing, False
    job = jobs.add(session, new_job(gallery.base_preset, mesh))
    after_commit(session, lambda: enqueue_soon(state, job))
    return mesh, True


def _retry(session: Session, state: AppState, gallery: Gallery, mesh: Mesh) -> bool:
    """Describe ``mesh`` again if its last try failed for a reason that says nothing
    about the file, or its job is unknown to the queue (stuck); True if queued."""
    if mesh.status == MeshStatus.failed.value:
        if mesh.error_code not in TRANSIENT_FAILURES:
            return False  # the file's own fault: the same bytes fail the same way
        mesh.status = MeshStatus.queued.value
        mesh.error_code = mesh.error_detail = None
        stuck = [jobs.add(session, new_job(gallery.base_preset, mesh))]
    else:
        unfinished = [j for j in mesh.jobs if j.status in UNFINISHED_JOB]
        try:
            stuck = lost(state, unfinished, grace_seconds=state.settings.sweep_interval_seconds)
        except QUEUE_ERRORS:  # the sweep enqueues it once the queue is back
            return False
    for job in stuck:
        after_commit(session, functools.partial(enqueue_soon, state, job))
    return bool(stuck)


def _same_format(existing: Mesh, upload: ReceivedFile) -> None:
    """The stored mesh is these bytes read in its own file's format; the same bytes
    named as another format would be read differently, so they are not the same mesh."""
    if mesh_format(existing.filename) != mesh_format(upload.filename):
        raise ConflictError(
            f"These exact bytes are already enrolled as mesh {existing.id} "
            f"({existing.filename!r}), in another file format than {upload.filename!r}; "
            "upload them with the right extension.",
            code="same_bytes_other_format",
        )


def original_file(
    session: Session, state: AppState, gallery: Gallery, mesh_id: int
) -> tuple[Mesh, Path | bytes]:
    """The mesh and its uploaded file (a local path, or the bytes from the database)."""
    mesh = enrolled_mesh(session, gallery, mesh_id)
    file = state.store.read(session, mesh.storage_path)
    if file is None:
        raise NotFoundError(
            f"The file of mesh {mesh_id} is missing from storage.", code="file_missing"
        )
    return mesh, file


def preview(session: Session, gallery: Gallery, mesh_id: int) -> Preview:
    """A mesh's preview and thumbnail.

    Raises
    ------
    NotFoundError
        No such mesh, or ``no_preview``: it failed, or was described before the
        service made previews.
    ConflictError
        ``mesh_not_ready``: it is queued or being described; the preview comes with it.
    """
    mesh = enrolled_mesh(session, gallery, mesh_id)
    stored = meshes.get_preview(session, mesh_id)
    if stored is not None:
        return stored
    if mesh.status in (MeshStatus.queued.value, MeshStatus.processing.value):
        raise ConflictError(
            f"Mesh {mesh_id} is {mesh.status}; its preview is made when it is described.",
            code="mesh_not_ready",
        )
    raise NotFoundError(f"Mesh {mesh_id} is {mesh.status} and has no preview.", code="no_preview")


def delete(session: Session, state: AppState, gallery: Gallery, mesh_id: int) -> None:
    """Delete a mesh, its descriptors and jobs, and its file unless another collection
    enrolled the same bytes; it leaves the index at once (after commit)."""
    mesh = enrolled_mesh(session, gallery, mesh_id)
    task_ids = [j.task_id for j in mesh.jobs if j.status in UNFINISHED_JOB]
    if not meshes.storage_shared(session, mesh.storage_path, gallery.collection_id):
        state.store.remove(session, mesh.storage_path)
    meshes.delete(session, mesh)
    changes.record(session, mesh_id, gallery.collection_id, "remove")

    def _after() -> None:
        # Waits for a collector round that may have just stored this mesh's
        # descriptor (it holds the gallery), so its add cannot come after this removal.
        gallery.remove(mesh_id)
        for task_id in task_ids:
            try:
                state.queue.cancel(task_id)
            except QUEUE_ERRORS as exc:  # deleted all the same: its result will be ignored
                log.warning("mesh %d deleted; its task %s not cancelled: %r", mesh_id, task_id, exc)

    after_commit(session, _after)


def descriptor_of(session: Session, gallery: Gallery, mesh: Mesh) -> Descriptor | None:
    """The mesh's descriptor under its collection's preset, if it has one yet."""
    preset = gallery.base_preset
    return meshes.get_descriptor(session, mesh.id, preset.name, preset.version)


@dataclass
class MeshPage:
    """One page of meshes, each with its descriptor (None until described)."""

    items: list[tuple[Mesh, Descriptor | None]]
    total: int
    offset: int
    limit: int


def list_page(
    session: Session,
    state: AppState,
    gallery: Gallery,
    *,
    label: str | None,
    status: MeshStatus | None,
    offset: int,
    limit: int,
    order: meshes.Order = "oldest",
) -> MeshPage:
    """A collection's meshes in ``order`` (:data:`~app.repositories.meshes.ORDERS`),
    filtered by label and status; ``limit`` capped by the settings."""
    limit = min(limit, state.settings.max_page_size)
    rows, total = meshes.list_page(
        session,
        gallery.collection_id,
        label=None if label is None else check_text(label, "label"),
        status=status.value if status else None,
        offset=offset,
        limit=limit,
        order=order,
    )
    preset = gallery.base_preset
    descriptors = meshes.descriptors_for(session, [m.id for m in rows], preset.name, preset.version)
    return MeshPage([(m, descriptors.get(m.id)) for m in rows], total, offset, limit)
