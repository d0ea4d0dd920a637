"""Every collection's gallery (:class:`Galleries`): made from the ``collections`` table,
kept equal to it on every API process, and fed from the database: each gallery loaded
from its collection's stored descriptors and labels, then following the change log.

A collection created or deleted through one process reaches the others when their
collector next syncs (every round), or at once when a request names a collection
this process does not know yet.
"""

from __future__ import annotations

import logging
import shutil
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy.orm import Session, sessionmaker

from worker.engine.descriptor import ShapeDescriptor
from worker.engine.presets import Preset, get_preset, with_units

from .config import Settings
from .errors import NotFoundError
from .gallery.service import Change, Gallery, Shape
from .gallery.weights import pinned_fusion
from .metrics import Metrics
from .models import DEFAULT_COLLECTION, Collection
from .repositories import changes, collections, meshes

log = logging.getLogger("shapes.gallery")

FOLLOW_BATCH = 1000  # changes applied per round of following the log

#: Where a collection's own pinned weights are set (the reason /calibration shows).
PINNED_HERE = "PUT /collections/{name}/fusion"


@dataclass(frozen=True)
class CollectionSpec:
    """What a collection's gallery is made of (a ``collections`` row)."""

    id: int
    name: str
    units: str
    preset: Preset
    #: Weights an admin pinned for the collection (None: learned, or the preset's).
    pinned: dict[str, float] | None

    @classmethod
    def of(cls, row: Collection, default_preset: str) -> CollectionSpec:
        """The row's, its preset compared in its units (the size scored when metric)."""
        preset = with_units(get_preset(row.preset or default_preset), row.units)
        return cls(row.id, row.name, row.units, preset, row.fusion_weights)


class Galleries:
    """The galleries of the service's collections, by collection id."""

    def __init__(
        self, settings: Settings, metrics: Metrics, read_sessions: sessionmaker[Session]
    ) -> None:
        self.settings = settings
        self.metrics = metrics
        self.read_sessions = read_sessions
        self.error: str | None = None  # why loading failed, shown by /ready
        self._by_id: dict[int, Gallery] = {}
        self._specs: dict[int, CollectionSpec] = {}
        # One for every gallery: a collector round stores the results of all of them.
        self._lock = threading.RLock()
        self._sync_lock = threading.Lock()
        self._synced = False

    # ------------------------------------------------------------ access
    @property
    def loaded(self) -> bool:
        """Synced with the collections table, and every gallery's index loaded."""
        return self._synced and all(g.loaded for g in list(self._by_id.values()))

    def __iter__(self) -> Iterator[Gallery]:
        return iter(list(self._by_id.values()))

    def __len__(self) -> int:
        """Shapes in every collection's index."""
        return sum(len(g) for g in self)

    def of(self, collection_id: int) -> Gallery | None:
        """The gallery of a collection (None if it was deleted)."""
        return self._by_id.get(collection_id)

    def named(self, name: str) -> Gallery:
        """The gallery of the collection called ``name``.

        Raises
        ------
        NotFoundError
            ``collection_not_found``: there is no such collection (also after asking the
            database, for one another API process created a moment ago).
        """
        gallery = self.find(name)
        if gallery is None:
            raise NotFoundError(
                f"There is no collection called {name!r}; GET /collections lists them.",
                code="collection_not_found",
            )
        return gallery

    @property
    def default(self) -> Gallery:
        return self.named(DEFAULT_COLLECTION)

    def find(self, name: str) -> Gallery | None:
        """The gallery of the collection called ``name``, None if there is none (also
        after asking the database, for one another API process created a moment ago)."""
        gallery = self._known(name)
        if gallery is None:
            self.sync()
            gallery = self._known(name)
        return gallery

    def _known(self, name: str) -> Gallery | None:
        for gallery in self:
            if gallery.name == name:
                return gallery
        return None

    @contextmanager
    def changing(self) -> Iterator[None]:
        """Hold every gallery while a database transaction and its index changes happen."""
        with self._lock:
            yield

    # -------------------------------------------------------------- sync
    def sync(self) -> None:
        """Make a gallery for each new collection (its index loaded now), drop the
        deleted ones' (their saved index removed), and follow pinned weights."""
        with self._sync_lock:
            with self.read_sessions() as session:
                rows = collections.all_rows(session)
            specs = {row.id: CollectionSpec.of(row, self.settings.preset) for row in rows}
            gone = [i for i in self._by_id if i not in specs]
            for collection_id in gone:
                self._drop(collection_id)
            for collection_id, gallery in list(self._by_id.items()):
                spec = specs[collection_id]
                if spec.pinned != self._specs[collection_id].pinned:
                    pin, learn, where = self._fusion_of(spec)
                    gallery.pin_fusion(pin, learn=learn, where=where)
                    self._specs[collection_id] = spec
            new = [spec for i, spec in specs.items() if i not in self._by_id]
            for spec in new:
                gallery = self._make(spec)
                self._load(gallery)
                self._specs[spec.id] = spec
                self._by_id[spec.id] = gallery
            self._synced = True

    def _drop(self, collection_id: int) -> None:
        with self._lock:
            gallery = self._by_id.pop(collection_id)
            self._specs.pop(collection_id)
        self.metrics.index_size.remove(gallery.name)
        if collection_id != 1:  # never the default's, which other versions share
            shutil.rmtree(self._directory(collection_id, gallery.base_preset).parent, True)
        log.info("collection %s deleted: its gallery is gone", gallery.name)

    def _directory(self, collection_id: int, preset: Preset) -> Path:
        """Where a collection's index is saved: the default collection's where the
        service kept its one gallery's, the others' under ``collections/<id>``."""
        root = self.settings.index_directory
        if collection_id != 1:
            root = root / "collections" / str(collection_id)
        return root / f"{preset.name}-v{preset.version}"

    def _fusion_of(self, spec: CollectionSpec) -> tuple[dict[str, float] | None, bool, str]:
        """The weights a collection's gallery is pinned to (its own, else the operator's
        SHAPES_FUSION_WEIGHTS for the service's preset, else None), whether it learns, and
        where the pin was set."""
        settings = self.settings
        if spec.pinned is not None:
            return spec.pinned, False, PINNED_HERE
        pin = settings.fusion_weights if spec.preset.name == settings.preset else None
        return pin, pin is None and settings.fusion == "learned", "SHAPES_FUSION_WEIGHTS"

    def _make(self, spec: CollectionSpec) -> Gallery:
        settings = self.settings
        pin, learn, where = self._fusion_of(spec)
        return Gallery(
            (spec.id, spec.name),
            spec.preset,
            self._directory(spec.id, spec.preset),
            refit_fraction=settings.index_refit_fraction,
            metrics=self.metrics,
            lock=self._lock,
            fusion=None if pin is None else pinned_fusion(spec.preset, pin, where),
            learn_fusion=learn,
            fusion_max_shapes=settings.fusion_max_shapes,
        )

    def _described(
        self, session: Session, gallery: Gallery, mesh_ids: set[int] | None
    ) -> Iterator[Shape]:
        """The gallery's stored shapes of ``mesh_ids`` (None: all), decoded."""
        p = gallery.preset
        rows = meshes.iter_descriptors(session, gallery.collection_id, p.name, p.version, mesh_ids)
        for mesh_id, label, blob in rows:
            yield Shape(mesh_id, label, ShapeDescriptor.from_npz_bytes(blob))

    def _load(self, gallery: Gallery) -> None:
        """Load a gallery's index: the saved one reconciled with the database, or one
        rebuilt from it (:meth:`Gallery.load`)."""
        p = gallery.preset
        with self.read_sessions() as session:
            # Read first: a change committed while loading is applied again by follow
            # (adds and removes are idempotent), never missed.
            followed = changes.latest(session)
            enrolled = meshes.described_labels(session, gallery.collection_id, p.name, p.version)
            gallery.load(
                enrolled,
                lambda ids: self._described(session, gallery, ids),
                followed=followed,
            )

    # --------------------------------------------------------- each round
    def follow(self) -> int:
        """Apply every collection's new change-log entries (:meth:`Gallery.follow`);
        returns how many entries were read."""
        return sum(self._follow(g) for g in self)

    def _follow(self, gallery: Gallery) -> int:
        if not gallery.loaded:
            return 0
        with self.read_sessions() as session:
            rows = changes.since(session, gallery.collection_id, gallery.followed, FOLLOW_BATCH)
            if not rows:
                return 0
            log_rows = [Change(r.id, r.action, r.mesh_id) for r in rows]
            added = {c.mesh_id for c in log_rows if c.action == "add" and c.mesh_id not in gallery}
            shapes = list(self._described(session, gallery, added)) if added else []
        gallery.follow(log_rows, shapes)
        return len(log_rows)

    def maybe_refit_fusion(self, every: float) -> None:
        for gallery in self:
            gallery.maybe_refit_fusion(every)

    def maybe_refit_references(self, every: float) -> None:
        """Each gallery's yardstick of closeness, refitted after changes (seconds of
        work at most, in the collector's thread: searches never wait for it)."""
        for gallery in self:
            gallery.maybe_refit_reference(every)

    @property
    def dirty(self) -> bool:
        return any(g.dirty for g in self)

    def save(self) -> None:
        for gallery in self:
            gallery.save()
