"""Loading, reconciling and saving the index against the database (the source of truth)."""

from __future__ import annotations

import logging
import time

import numpy as np
from sqlalchemy.orm import Session

from worker.engine.pipeline import ShapeDescriptor

from .index import GalleryIndex, descriptor_dims
from .meshes import repository as meshes
from .state import AppState

log = logging.getLogger("shapes.gallery")


def index_directory(state: AppState):
    p = state.preset
    return state.settings.index_dir / f"{p.name}-v{p.version}"


def vectors_of(descriptor: ShapeDescriptor) -> dict[str, np.ndarray]:
    return {m: descriptor.vector(m) for m in ("gdm", "ddt", "spectrum")}


def _decoded(rows):
    for mesh_id, blob in rows:
        yield mesh_id, vectors_of(ShapeDescriptor.from_npz_bytes(blob))


def load_index(state: AppState) -> GalleryIndex:
    """The persisted index brought up to date with the database, or one rebuilt from it.

    A missing, corrupt or other-version index is rebuilt from the stored
    descriptors; a stale one gets the missing shapes added and the deleted
    ones removed.
    """
    preset, settings = state.preset, state.settings
    directory = index_directory(state)
    started = time.perf_counter()
    refit = settings.index_refit_fraction
    with state.read_sessions() as session:
        db_ids = meshes.descriptor_mesh_ids(session, preset.name, preset.version)
        try:
            index = GalleryIndex.load(directory, preset, refit_fraction=refit)
            how = "loaded"
        except ValueError as exc:
            if directory.exists():
                log.warning(
                    "index at %s unusable (%s); rebuilding from the database", directory, exc
                )
            index = GalleryIndex(preset, descriptor_dims(preset), refit_fraction=refit)
            index.add_many(_decoded(meshes.iter_descriptors(session, preset.name, preset.version)))
            how = "rebuilt"
        else:
            _reconcile(index, db_ids, session, state)
    log.info(
        "index %s: %d shapes (%s) in %.2fs",
        preset.name,
        len(index),
        how,
        time.perf_counter() - started,
    )
    if index.dirty:
        save_index(state, index)
    return index


def _reconcile(index: GalleryIndex, db_ids: set[int], session: Session, state: AppState) -> None:
    have = {int(i) for i in index.ids()}
    for stale in have - db_ids:
        index.remove(stale)
    missing = db_ids - have
    if missing:
        p = state.preset
        for mesh_id, vectors in _decoded(
            meshes.iter_descriptors(session, p.name, p.version, missing)
        ):
            index.add(mesh_id, vectors)


def save_index(state: AppState, index: GalleryIndex) -> None:
    try:
        index.save(index_directory(state))
    except OSError as exc:  # the database still has everything; the index is a cache
        log.error("could not save the index: %s", exc)
