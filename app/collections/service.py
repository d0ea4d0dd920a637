"""Rules for creating, listing and deleting collections (no HTTP types here)."""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass

from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from worker.engine.presets import PRESETS

from ..db import after_commit
from ..errors import ConflictError, InvalidInputError, NotFoundError
from ..links import NAME_PATTERN
from ..models import DEFAULT_COLLECTION, UNFINISHED_JOB, Collection, Units
from ..queue import QUEUE_ERRORS
from ..repositories import collections, meshes
from ..state import AppState

log = logging.getLogger("shapes.collections")

#: The largest fusion weight a collection may pin (an exponent of the product rule).
MAX_WEIGHT = 100.0


@dataclass
class CollectionView:
    """A collection with its preset resolved and its meshes counted."""

    row: Collection
    preset: str
    preset_version: int
    meshes: int
    ready: int


def _view(state: AppState, row: Collection, counts: tuple[int, int]) -> CollectionView:
    gallery = state.galleries.of(row.id)
    if gallery is not None:
        preset = gallery.base_preset
    else:  # created by another API process a moment ago
        preset = PRESETS[row.preset or state.preset.name]
    return CollectionView(row, preset.name, preset.version, *counts)


def get(session: Session, state: AppState, name: str) -> CollectionView:
    row = collections.get_by_name(session, name)
    if row is None:
        raise NotFoundError(
            f"There is no collection called {name!r}; GET /collections lists them.",
            code="collection_not_found",
        )
    return _view(state, row, collections.mesh_counts(session).get(row.id, (0, 0)))


def list_all(session: Session, state: AppState) -> list[CollectionView]:
    counts = collections.mesh_counts(session)
    return [_view(state, r, counts.get(r.id, (0, 0))) for r in collections.all_rows(session)]


def create(
    session: Session, state: AppState, *, name: str, units: Units, preset: str | None
) -> CollectionView:
    """A new, empty collection; its gallery exists on this API process once committed.

    Raises
    ------
    InvalidInputError
        ``invalid_name`` or ``unknown_preset``.
    ConflictError
        ``collection_exists``.
    """
    if not re.fullmatch(NAME_PATTERN, name):
        raise InvalidInputError(
            "A collection's name is 1 to 64 letters, digits, '-' or '_', starting with a "
            "letter or digit (it is part of the collection's paths).",
            code="invalid_name",
        )
    if preset is not None and preset not in PRESETS:
        known = ", ".join(sorted(PRESETS))
        raise InvalidInputError(
            f"There is no preset called {preset!r}; known presets: {known}.",
            code="unknown_preset",
        )
    exists = ConflictError(
        f"A collection called {name!r} exists already.", code="collection_exists"
    )
    if collections.get_by_name(session, name) is not None:
        raise exists
    try:
        row = collections.add(session, Collection(name=name, units=units.value, preset=preset))
    except IntegrityError:  # created concurrently
        raise exists from None
    after_commit(session, state.galleries.sync)
    return _view(state, row, (0, 0))


def pin_fusion(
    session: Session, state: AppState, name: str, weights: dict[str, float] | None
) -> CollectionView:
    """Pin the collection's fusion weights (None: unpin, so that it learns them again, or
    uses the preset's); every API process's gallery follows at its next sync. A modality
    left out keeps the preset's weight (:func:`~app.gallery.weights.pinned_fusion`).

    Raises
    ------
    NotFoundError
        ``collection_not_found``.
    """
    row = collections.get_by_name(session, name)
    if row is None:
        raise NotFoundError(f"There is no collection called {name!r}.", code="collection_not_found")
    row.fusion_weights = weights
    session.flush()
    after_commit(session, state.galleries.sync)
    return _view(state, row, collections.mesh_counts(session).get(row.id, (0, 0)))


def delete(session: Session, state: AppState, name: str) -> None:
    """Delete a collection with its meshes, their descriptors and the files no other
    collection shares; its gallery goes once committed (other API processes' at their
    next sync).

    Raises
    ------
    NotFoundError
        ``collection_not_found``.
    ConflictError
        ``default_collection``: the default collection stays (the paths without
        ``/collections/{name}`` work on it).
    """
    if name == DEFAULT_COLLECTION:
        raise ConflictError(
            "The default collection cannot be deleted: the paths without "
            "/collections/{name} work on it. Delete its meshes instead.",
            code="default_collection",
        )
    row = collections.get_by_name(session, name)
    if row is None:
        raise NotFoundError(f"There is no collection called {name!r}.", code="collection_not_found")
    task_ids: list[str] = []
    for mesh in collections.meshes_of(session, row.id):
        task_ids += [j.task_id for j in mesh.jobs if j.status in UNFINISHED_JOB]
        if not meshes.storage_shared(session, mesh.storage_path, row.id):
            state.store.remove(session, mesh.storage_path)
    session.delete(row)  # its meshes, descriptors, jobs, previews and keys with it (cascade)
    session.flush()

    def _after() -> None:
        state.galleries.sync()
        state.keys.forget()  # its keys went with it
        for task_id in task_ids:
            try:
                state.queue.cancel(task_id)
            except QUEUE_ERRORS as exc:  # its result will be ignored
                log.warning("collection %s deleted; task %s not cancelled: %r", name, task_id, exc)

    after_commit(session, _after)
