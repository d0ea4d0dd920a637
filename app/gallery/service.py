"""A collection's gallery: the one owner of its index, and everything the service asks
of it (every collection has one; :mod:`app.galleries` holds them and feeds them from
the database).

The collector adds described shapes, the mesh service removes deleted ones, the
search service searches; all of them through :class:`Gallery`, which also loads
the index and reconciles it with the enrolled shapes it is given at start, applies
the changes it is given after that (what other API processes on the same database
changed), keeps the labels its calibration and fusion learn from, saves the index,
and publishes its size. It takes plain values: ids, labels, descriptors; never a
database session.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from worker.engine.compare import partiality, query_weights
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.parts import GRID_STEPS_PER_OCTAVE, compared_by_size, compared_profiles
from worker.engine.presets import PARTS, Preset

from ..errors import ConflictError, UnavailableError
from ..metrics import Metrics
from .index import GalleryIndex, Match, SearchStats
from .pairs import GalleryCalibration, NotEnoughPairs, fit_calibration
from .persistence import load_index, save_index
from .reference import PARTS_QUERIES, PartsQuery, Reference, fit_reference
from .weights import (
    IDLE_AFTER_FIT,
    GalleryFusion,
    learn_gallery_fusion,
    pinned_fusion,
    preset_fusion,
    restored_fusion,
    saved_fusion,
)

log = logging.getLogger("shapes.gallery")


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


class Shape(NamedTuple):
    """An enrolled, described shape as a gallery takes it."""

    mesh_id: int
    label: str | None
    descriptor: ShapeDescriptor


class Change(NamedTuple):
    """An entry of the change log: its sequence number, ``add`` or ``remove``, the mesh."""

    seq: int
    action: str
    mesh_id: int


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
        self.followed = 0
        # mesh id -> label of the shapes in the index that have one.
        self._labels: dict[int, str] = {}
        # How far apart its different objects are (.reference), and the whole shapes
        # whose own samples score the parts modality's pairs (a reservoir sample).
        self._reference: Reference | None = None
        self._parts_queries: list[PartsQuery] = []
        self._parts_seen = 0
        self._rng = np.random.default_rng(0)

    # ------------------------------------------------------------- state
    @property
    def loaded(self) -> bool:
        return self._index is not None

    def __len__(self) -> int:
        return 0 if self._index is None else len(self._index)

    def __contains__(self, mesh_id: int) -> bool:
        return self._index is not None and mesh_id in self._index

    def _ready(self) -> GalleryIndex:
        if self._index is None:
            raise UnavailableError(
                "The index is still loading; try again in a moment.", code="index_loading"
            )
        return self._index

    def _settled(self) -> GalleryIndex:
        """The index once a change in flight is applied. The collector holds the lock from
        before its commit until the index has the stored shapes, so a search that starts
        after a client saw a shape ready finds it; searches do not hold the lock."""
        with self._lock:
            return self._ready()

    def _publish_size(self) -> None:
        self.metrics.index_size.labels(self.name).set(len(self))

    # ----------------------------------------------------------- changes
    def add(self, shape: Shape) -> None:
        """Make a described shape searchable (no-op while the index is not loaded yet:
        loading reconciles with the database)."""
        with self._lock:
            if self._index is not None:
                self._add(self._index, shape)
                self._version += 1
                self._publish_size()

    def _add(self, index: GalleryIndex, shape: Shape) -> None:
        index.add(shape.mesh_id, descriptor_vectors(shape.descriptor, self.preset))
        self._labelled(shape.mesh_id, shape.label)
        self._keep_parts_query(shape)

    def _keep_parts_query(self, shape: Shape) -> None:
        """Reservoir sampling (Vitter's algorithm R) of the shapes whose own samples score
        the parts modality's reference pairs."""
        parts = shape.descriptor.parts
        if self.preset.parts_shape() is None or not parts.size:
            return
        query = PartsQuery(shape.mesh_id, parts.astype(np.float64), shape.descriptor.parts_reach)
        self._parts_seen += 1
        if len(self._parts_queries) < PARTS_QUERIES:
            self._parts_queries.append(query)
        elif (slot := int(self._rng.integers(0, self._parts_seen))) < PARTS_QUERIES:
            self._parts_queries[slot] = query

    def _labelled(self, mesh_id: int, label: str | None) -> None:
        if label is None:
            self._labels.pop(mesh_id, None)
        else:
            self._labels[mesh_id] = label

    def remove(self, mesh_id: int) -> None:
        """Take a shape out of every search from now on."""
        with self._lock:
            if self._index is not None and self._index.remove(mesh_id):
                self._labels.pop(mesh_id, None)
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
        index = self._settled()
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
                sized=compared_by_size(preset, descriptor.single_view),
                stats=stats,
            )
            # The parts' scale is one of a grid: the share lies between its neighbours'.
            half_step = 2.0 ** (0.5 / GRID_STEPS_PER_OCTAVE)
            stats.partiality, stats.kept_share = share, 1.0 / scale**2
            stats.parts_scale = scale
            stats.kept_range = (1.0 / (scale * half_step) ** 2, min(1.0, (half_step / scale) ** 2))
            stats.weights = {m: w for m, w in weights.items() if w > 0}
        else:
            matches = index.search(
                vectors, k, fusion=fusion, modalities=modalities, exclude=exclude, stats=stats
            )
            stats.weights = {m: preset.weight(m) for m in modalities}
        self.metrics.search_seconds.observe(stats.seconds)
        return matches, stats

    def scores(
        self, descriptor: ShapeDescriptor, mesh_ids: list[int]
    ) -> dict[int, tuple[float, dict[str, float]]]:
        """The preset's fused and per-modality dissimilarities of ``descriptor`` to each
        of ``mesh_ids`` that is in the index (the others are left out)."""
        index = self._settled()
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

    def calibration(self, *, max_pairs: int, refit_seconds: float) -> GalleryCalibration:
        """The verification calibration of the labelled shapes (:mod:`.pairs`).

        Refitted when shapes were added or removed since the last fit, at most every
        ``refit_seconds`` (a fit of the default 200,000 pairs takes about a second);
        in between the last fit answers.

        Raises
        ------
        UnavailableError
            The index is still loading.
        ConflictError
            ``not_calibrated``: too few labelled pairs, with the sentence saying how many.
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
                with self._lock:
                    labels = dict(self._labels)
                try:
                    fit = fit_calibration(
                        index, labels, self.preset, max_pairs=max_pairs, version=version
                    )
                except NotEnoughPairs as exc:
                    raise ConflictError(str(exc), code="not_calibrated") from None
                self._calibration = fit
            assert fit is not None
            return fit

    @property
    def reference(self) -> Reference | None:
        """How far apart the gallery's different objects are (:mod:`.reference`), as last
        fitted; None before the first fit."""
        return self._reference

    def maybe_refit_reference(self, every: float) -> bool:
        """Fit the reference again when shapes were added or removed since the last fit,
        at most every ``every`` seconds (the collector asks each round; searches read the
        last fit and never wait for one); True if refitted."""
        index, fit = self._index, self._reference
        if index is None or (fit is not None and fit.version == self._version):
            return False
        if fit is not None and time.time() - fit.fitted_at < every:
            return False
        with self._lock:
            labels, version = dict(self._labels), self._version
            queries = list(self._parts_queries)
        self._reference = fit_reference(index, labels, queries, version=version)
        return True

    @property
    def fusion(self) -> GalleryFusion:
        """The fusion weights in use, where they came from and why (:mod:`.fusion`)."""
        return self._fusion

    def maybe_refit_fusion(self, every: float) -> bool:
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
        with self._lock:
            labels, version = dict(self._labels), self._version
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
    def parts_file(self) -> Path:
        """Where every sample's parts profiles are kept, read for a partial search's
        shortlist only (beside the saved index, which refers to its rows)."""
        return self.directory.with_name(self.directory.name + ".parts")

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
    def load(
        self,
        enrolled: Mapping[int, str | None],
        described: Callable[[set[int] | None], Iterable[Shape]],
        *,
        followed: int,
    ) -> None:
        """The saved index brought up to date with the enrolled shapes, or one rebuilt.

        ``enrolled`` maps every described shape's id to its label; ``described(ids)``
        gives the shapes of those ids (None: all of them), read only for what the saved
        index lacks; ``followed`` is the change log's position they were read at. A
        missing, corrupt or other-version index is rebuilt; a stale one gets the missing
        shapes added and the deleted ones removed. A fusion learned before a restart
        ranks until the first fit.
        """
        self._restore_fusion()
        preset, directory = self.preset, self.directory
        started = time.perf_counter()
        missing: set[int] | None
        try:
            index = load_index(directory, preset, refit_fraction=self.refit_fraction)
            if index.store.parts_shape != preset.parts_shape():
                raise ValueError("index made with other parts profiles")
            how = "loaded"
            have = {int(i) for i in index.ids()}
            for stale in have - enrolled.keys():
                index.remove(stale)
            missing = enrolled.keys() - have
        except ValueError as exc:
            if directory.exists():
                log.warning(
                    "index at %s unusable (%s); rebuilding from the database", directory, exc
                )
            self.parts_file.unlink(missing_ok=True)  # its slots start again
            index = GalleryIndex(
                preset,
                preset.modality_sizes(),
                refit_fraction=self.refit_fraction,
                parts_shape=preset.parts_shape(),
                parts_path=self.parts_file,
            )
            how, missing = "rebuilt", None
        labels = dict(enrolled)

        def vectors(shapes: Iterable[Shape]) -> Iterator[tuple[int, dict[str, np.ndarray]]]:
            for shape in shapes:  # streamed: a gallery's descriptors need not fit in memory
                labels[shape.mesh_id] = shape.label
                self._keep_parts_query(shape)
                yield shape.mesh_id, descriptor_vectors(shape.descriptor, preset)

        if missing is None:
            index.add_many(vectors(described(None)))  # one fit at the end
        elif missing:
            for mesh_id, shape_vectors in vectors(described(missing)):
                index.add(mesh_id, shape_vectors)
        # The saved index holds no samples: a few whole shapes are read for the parts'
        # reference (all of a small gallery's, else a seeded sample).
        if preset.parts_shape() is not None and len(self._parts_queries) < PARTS_QUERIES:
            have = {q.mesh_id for q in self._parts_queries}
            ids = [int(i) for i in index.ids() if int(i) not in have]
            chosen = self._rng.permutation(ids)[: PARTS_QUERIES - len(self._parts_queries)]
            if len(chosen):
                for shape in described({int(i) for i in chosen}):
                    self._keep_parts_query(shape)
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
            self._labels = {i: label for i, label in labels.items() if label and i in index}
            self.followed = followed
            self._publish_size()
        self.save()

    def follow(self, changes: Sequence[Change], added: Iterable[Shape]) -> None:
        """Apply entries of the change log: shapes that another API process on the same
        database stored or deleted (this process's own are in the index already);
        ``added`` are the described shapes of the ``add`` entries the index lacks."""
        if self._index is None or not changes:
            return
        stored = {shape.mesh_id: shape for shape in added}
        with self._lock:
            for change in changes:
                if change.action == "add" and change.mesh_id in stored:
                    self._add(self._index, stored.pop(change.mesh_id))
                    self._version += 1
                elif change.action == "remove" and self._index.remove(change.mesh_id):
                    self._labels.pop(change.mesh_id, None)
                    self._version += 1
                # An add whose descriptor is gone was deleted since: its removal follows.
            self.followed = changes[-1].seq
            self._publish_size()

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
