"""A collection's gallery: the one owner of its index, and everything the service asks
of it (every collection has one; :mod:`.registry` holds them).

The collector adds described shapes, the mesh service removes deleted ones, the
search service searches; all of them through :class:`Gallery`, which also loads
the index and reconciles it with the database (the source of truth) at start,
follows the database's change log after that (what other API processes on the
same database changed, :mod:`.changes`), saves it, and publishes its size.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np
from sqlalchemy.orm import Session, sessionmaker

from worker.engine.compare import partiality, query_weights
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.parts import compared_profiles
from worker.engine.presets import PARTS, Preset

from ..errors import UnavailableError
from ..meshes import repository as meshes
from ..metrics import Metrics
from . import changes
from .calibration import GalleryCalibration, fit_calibration
from .fusion import (
    IDLE_AFTER_FIT,
    GalleryFusion,
    learn_gallery_fusion,
    pinned_fusion,
    preset_fusion,
    restored_fusion,
    saved_fusion,
)
from .index import GalleryIndex, Match, SearchStats
from .persistence import load_index, save_index

log = logging.getLogger("shapes.gallery")

FOLLOW_BATCH = 1000  # changes applied per round of following the log


def flat_vectors(descriptor: ShapeDescriptor, preset: Preset) -> dict[str, np.ndarray]:
    """modality -> (M_m,) float, the flat vectors the index compares (all a query needs:
    its parts are compared from its own profiles): the shape's, and the size in a
    collection of metric units."""
    return {m: descriptor.vector(m) for m in preset.modality_sizes()}


def descriptor_vectors(descriptor: ShapeDescriptor, preset: Preset) -> dict[str, np.ndarray]:
    """What the index keeps of an enrolled shape: its :func:`flat_vectors`, and ``PARTS``
    -> the (m, K) profiles a whole is compared by when the preset has the parts modality
    (a surface with fewer samples repeats some: a nearest sample is found all the same).
    """
    vectors = flat_vectors(descriptor, preset)
    shape = preset.parts_shape()
    if shape is not None:
        compared = compared_profiles(descriptor.parts, preset)
        if not 0 < len(compared) <= shape[0]:
            raise ValueError(f"a descriptor with {len(compared)} parts profiles")
        vectors[PARTS] = compared[np.arange(shape[0]) % len(compared)]
    return vectors


def _decoded(
    rows: Iterable[tuple[int, bytes]], preset: Preset
) -> Iterator[tuple[int, dict[str, np.ndarray]]]:
    for mesh_id, blob in rows:
        yield mesh_id, descriptor_vectors(ShapeDescriptor.from_npz_bytes(blob), preset)


class Gallery:
    """One collection's enrolled shapes: their index under the collection's preset.

    Parameters
    ----------
    collection : the collection's id and name.
    preset : the preset every enrolled descriptor of the collection is made with.
    directory : where the index is saved (``<index dir>/<preset>-v<version>`` for the
        default collection).
    refit_fraction : see :class:`~.index.GalleryIndex`.
    metrics : ``index_size`` and ``search_seconds`` are published here.
    lock : held while the database and the index change together; one for every
        collection's gallery (the collector's round stores the results of all).
    """

    def __init__(
        self,
        collection: tuple[int, str],
        preset: Preset,
        directory: Path,
        *,
        refit_fraction: float,
        metrics: Metrics,
        lock: threading.RLock,
        fusion: GalleryFusion | None = None,
        learn_fusion: bool = False,
        fusion_max_shapes: int = 300,
    ) -> None:
        self.collection_id, self.name = collection
        #: The collection's preset; ``preset`` is it with the fusion in use.
        self.base_preset = preset
        self._fusion = fusion or preset_fusion(preset, "the preset's weights")
        self.preset = self._fusion.applied(preset)
        self.learn_fusion = learn_fusion
        self.fusion_max_shapes = fusion_max_shapes
        self._fusion_thread: threading.Thread | None = None
        self.directory = directory
        self.refit_fraction = refit_fraction
        self.metrics = metrics
        self.error: str | None = None  # why loading failed, shown by /ready
        self._index: GalleryIndex | None = None
        # Held while the database and the index change together (collector, delete),
        # so a shape deleted while its descriptor is being stored never reaches the index.
        self._lock = lock
        # Counts adds and removes; a calibration fitted at another count is stale.
        self._version = 0
        self._calibration: GalleryCalibration | None = None
        self._calibration_lock = threading.Lock()
        # The position in the change log this index reflects (see follow).
        self._followed = 0

    # ------------------------------------------------------------- state
    @property
    def loaded(self) -> bool:
        return self._index is not None

    def __len__(self) -> int:
        return 0 if self._index is None else len(self._index)

    def _ready(self) -> GalleryIndex:
        if self._index is None:
            raise UnavailableError(
                "The index is still loading; try again in a moment.", code="index_loading"
            )
        return self._index

    def _publish_size(self) -> None:
        self.metrics.index_size.labels(self.name).set(len(self))

    # ----------------------------------------------------------- changes
    def add(self, mesh_id: int, descriptor: ShapeDescriptor) -> None:
        """Make a described shape searchable (no-op while the index is not loaded yet:
        loading reconciles with the database)."""
        with self._lock:
            if self._index is not None:
                self._index.add(mesh_id, descriptor_vectors(descriptor, self.preset))
                self._version += 1
                self._publish_size()

    def remove(self, mesh_id: int) -> None:
        """Take a shape out of every search from now on."""
        with self._lock:
            if self._index is not None and self._index.remove(mesh_id):
                self._version += 1
                self._publish_size()

    # ------------------------------------------------------------ search
    def search(
        self,
        descriptor: ShapeDescriptor,
        k: int,
        *,
        fusion: str | None,
        modalities: tuple[str, ...],
        exclude: tuple[int, ...] = (),
    ) -> tuple[list[Match], SearchStats]:
        """The ``k`` enrolled shapes most similar to ``descriptor``, and how the search went.

        With the preset's own score, a query that looks partial is ranked with the parts
        modality at its weights (:func:`~worker.engine.compare.query_weights`).

        Raises
        ------
        UnavailableError
            The index is still loading (``index_loading``).
        """
        index = self._ready()
        preset = self.preset
        stats = SearchStats()
        vectors = flat_vectors(descriptor, preset)
        own = modalities == preset.scored_modalities and fusion in (None, preset.fusion)
        share = partiality(descriptor.longest_open_loop, descriptor.kept_area_fraction, preset)
        weights = query_weights(preset, share)
        if own and PARTS in weights:
            matches, scale = index.partial_search(
                vectors,
                descriptor.parts.astype(np.float64),
                descriptor.parts_reach,
                weights,
                k,
                exclude=exclude,
                stats=stats,
            )
            stats.partiality, stats.kept_share = share, 1.0 / scale**2
        else:
            matches = index.search(
                vectors, k, fusion=fusion, modalities=modalities, exclude=exclude, stats=stats
            )
        self.metrics.search_seconds.observe(stats.seconds)
        return matches, stats

    def scores(
        self, descriptor: ShapeDescriptor, mesh_ids: list[int]
    ) -> dict[int, tuple[float, dict[str, float]]]:
        """The preset's fused and per-modality dissimilarities of ``descriptor`` to each
        of ``mesh_ids`` that is in the index (the others are left out)."""
        index = self._ready()
        preset = self.preset
        with index.lock:
            present = np.array([i for i in mesh_ids if i in index], dtype=np.int64)
            if not len(present):
                return {}
            fused, per = index.exact_scores(
                flat_vectors(descriptor, preset),
                index.store.positions(present),
                preset.scored_modalities,
                preset.fusion,
            )
        return {
            int(mesh_id): (float(fused[j]), {m: float(v[j]) for m, v in per.items()})
            for j, mesh_id in enumerate(present)
        }

    def calibration(
        self, session: Session, *, max_pairs: int, refit_seconds: float
    ) -> GalleryCalibration:
        """The verification calibration of the labelled shapes (:mod:`.calibration`).

        Refitted when shapes were added or removed since the last fit, at most every
        ``refit_seconds`` (a fit of the default 200,000 pairs takes about a second);
        in between the last fit answers.

        Raises
        ------
        UnavailableError
            The index is still loading.
        NotEnoughPairs
            Too few labelled pairs to calibrate.
        """
        index = self._ready()
        with self._calibration_lock:
            fit, version = self._calibration, self._version
            due = (
                fit is None
                or fit.preset is not self.preset  # fitted under other fusion weights
                or (fit.version != version and time.time() - fit.fitted_at >= refit_seconds)
            )
            if due:
                labels = meshes.labels(session, self.collection_id)
                fit = fit_calibration(
                    index, labels, self.preset, max_pairs=max_pairs, version=version
                )
                self._calibration = fit
            assert fit is not None
            return fit

    @property
    def fusion(self) -> GalleryFusion:
        """The fusion weights in use, where they came from and why (:mod:`.fusion`)."""
        return self._fusion

    def maybe_refit_fusion(self, read_sessions: sessionmaker[Session], every: float) -> bool:
        """Start learning the fusion weights again in a thread of its own when shapes were
        added or removed since the last fit, at most every ``every`` seconds and
        ``IDLE_AFTER_FIT`` times the last fit's duration after it (the collector asks each
        round); True if started."""
        index = self._index
        fusion = self._fusion
        if not self.learn_fusion or index is None or fusion.version == self._version:
            return False
        if self._fusion_thread is not None and self._fusion_thread.is_alive():
            return False
        # Throttled like the calibration when the last fit learned (seconds of work), and
        # by its own duration; a fit that found too few labels cost nothing and runs again
        # at once.
        pause = max(every, IDLE_AFTER_FIT * fusion.seconds)
        if fusion.tuning is not None and time.time() - fusion.fitted_at < pause:
            return False
        with read_sessions() as session:
            labels = meshes.labels(session, self.collection_id)
        version = self._version
        self._fusion_thread = threading.Thread(
            target=self._refit_fusion, args=(index, labels, version), name="fusion", daemon=True
        )
        self._fusion_thread.start()
        return True

    def _refit_fusion(self, index: GalleryIndex, labels: dict[int, str], version: int) -> None:
        try:
            fit = learn_gallery_fusion(
                index,
                labels,
                self.base_preset,
                max_shapes=self.fusion_max_shapes,
                version=version,
            )
        except Exception:  # the weights in use stay; the next change tries again
            log.exception("learning the fusion weights failed")
            return
        with self._lock:
            if not self.learn_fusion:  # pinned while this fit ran
                return
            self.adopt_fusion(fit)
        self._keep_fusion(fit)

    @property
    def fusion_file(self) -> Path:
        """Where an adopted learned fusion is kept for a restart (beside the saved index,
        which a save replaces whole)."""
        return self.directory.with_name(self.directory.name + ".fusion.json")

    def _keep_fusion(self, fusion: GalleryFusion) -> None:
        """Save a learned fusion for the next start, or forget the last one."""
        try:
            if fusion.source == "learned":
                self.fusion_file.parent.mkdir(parents=True, exist_ok=True)
                tmp = self.fusion_file.with_suffix(".tmp")
                tmp.write_text(json.dumps(saved_fusion(fusion)))
                tmp.replace(self.fusion_file)
            else:
                self.fusion_file.unlink(missing_ok=True)
        except OSError as exc:  # a restart then ranks with the preset's until its first fit
            log.error("could not keep the learned fusion: %s", exc)

    def _restore_fusion(self) -> None:
        """Rank with the fusion learned before a restart until the first fit."""
        if not self.learn_fusion or not self.fusion_file.is_file():
            return
        try:
            saved = json.loads(self.fusion_file.read_text())
            self.adopt_fusion(restored_fusion(saved, self.base_preset))
        except (OSError, ValueError) as exc:
            log.warning("the saved learned fusion is not used (%s): learning again", exc)

    def pin_fusion(self, weights: dict[str, float] | None, *, learn: bool, where: str) -> None:
        """Rank with ``weights`` (pinned by ``where``) from now on; None: with the preset's,
        and learn again when ``learn``."""
        with self._lock:
            self.learn_fusion = learn and weights is None
            self.adopt_fusion(
                preset_fusion(self.base_preset, "the preset's weights (unpinned)")
                if weights is None
                else pinned_fusion(self.base_preset, weights, where)
            )

    def adopt_fusion(self, fusion: GalleryFusion) -> None:
        """Rank and calibrate with ``fusion``'s weights and comparisons from now on."""
        with self._lock:
            self._fusion = fusion
            preset = fusion.applied(self.base_preset)
            if preset == self.preset:
                return
            self.preset = preset
            if self._index is not None:
                self._index.compare_with(preset)
            with self._calibration_lock:
                self._calibration = None  # the calibration follows the fusion in use
        log.info("fusion %s %s (%s)", fusion.weights, fusion.comparisons, fusion.source)

    def check_ready(self) -> None:
        """Raise ``index_loading`` now rather than after a query's descriptor is computed."""
        self._ready()

    # ------------------------------------------------------- load / save
    def load(self, read_sessions: sessionmaker[Session]) -> None:
        """The saved index brought up to date with the database, or one rebuilt from it.

        A missing, corrupt or other-version index is rebuilt from the stored
        descriptors; a stale one gets the missing shapes added and the deleted
        ones removed. A fusion learned before a restart ranks until the first fit.
        """
        self._restore_fusion()
        preset, directory = self.preset, self.directory
        started = time.perf_counter()
        with read_sessions() as session:
            # Read first: a change committed while loading is applied again by follow
            # (adds and removes are idempotent), never missed.
            followed = changes.latest(session)
            db_ids = meshes.descriptor_mesh_ids(
                session, self.collection_id, preset.name, preset.version
            )
            try:
                index = load_index(directory, preset, refit_fraction=self.refit_fraction)
                if index.store.parts_shape != preset.parts_shape():
                    raise ValueError("index made with other parts profiles")
                how = "loaded"
            except ValueError as exc:
                if directory.exists():
                    log.warning(
                        "index at %s unusable (%s); rebuilding from the database", directory, exc
                    )
                index = GalleryIndex(
                    preset,
                    preset.modality_sizes(),
                    refit_fraction=self.refit_fraction,
                    parts_shape=preset.parts_shape(),
                )
                rows = meshes.iter_descriptors(
                    session, self.collection_id, preset.name, preset.version
                )
                index.add_many(_decoded(rows, preset))
                how = "rebuilt"
            else:
                self._reconcile(index, db_ids, session)
        log.info(
            "index of %s (%s): %d shapes (%s) in %.2fs",
            self.name,
            preset.name,
            len(index),
            how,
            time.perf_counter() - started,
        )
        with self._lock:
            self._index = index
            self._followed = followed
            self._publish_size()
        self.save()

    def follow(self, read_sessions: sessionmaker[Session]) -> int:
        """Apply the change log's new entries to the index: shapes that another API
        process on the same database stored or deleted (this process's own are in
        the index already). Returns how many entries were read."""
        if self._index is None:
            return 0
        with read_sessions() as session:
            log_rows = changes.since(session, self.collection_id, self._followed, FOLLOW_BATCH)
            if not log_rows:
                return 0
            index = self._index
            added = {r.mesh_id for r in log_rows if r.action == "add" and r.mesh_id not in index}
            p = self.preset
            rows = meshes.iter_descriptors(session, self.collection_id, p.name, p.version, added)
            stored = dict(_decoded(rows, p))
        with self._lock:
            for row in log_rows:
                if row.action == "add" and row.mesh_id in stored:
                    self._index.add(row.mesh_id, stored.pop(row.mesh_id))
                    self._version += 1
                elif row.action == "remove" and self._index.remove(row.mesh_id):
                    self._version += 1
                # An add whose descriptor is gone was deleted since: its removal follows.
            self._followed = log_rows[-1].id
            self._publish_size()
        return len(log_rows)

    def _reconcile(self, index: GalleryIndex, db_ids: set[int], session: Session) -> None:
        have = {int(i) for i in index.ids()}
        for stale in have - db_ids:
            index.remove(stale)
        missing = db_ids - have
        if missing:
            p = self.preset
            for mesh_id, vectors in _decoded(
                meshes.iter_descriptors(session, self.collection_id, p.name, p.version, missing), p
            ):
                index.add(mesh_id, vectors)

    @property
    def dirty(self) -> bool:
        """The index changed since it was last saved."""
        return self._index is not None and self._index.dirty

    def save(self) -> None:
        """Save the index if it changed since it was last saved."""
        index = self._index
        if index is None or not index.dirty:
            return
        try:
            save_index(index, self.directory)
        except OSError as exc:  # the database still has everything; the index is a cache
            log.error("could not save the index: %s", exc)
