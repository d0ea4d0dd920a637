"""The gallery's exact descriptor vectors by position, and eq. (9)'s sigma kept current.

Rows are packed: shape ``item`` is at position ``pos[item]``; removing a row moves
the last one into its place. ``sigma`` comes from running sums of ``x - shift``
and its square, updated on every add and remove and re-centred on the current
mean at each refit (``shift``) to avoid cancellation, so it always equals
``gallery_sigma`` over the enrolled vectors.

The parts modality's profiles (:mod:`worker.engine.parts`), when the preset has it, are
kept as float16 (the precision they are stored in) in two places: the first
``COARSE_SAMPLES`` samples of each shape in memory, by position, their area profiles
alone (what the coarse pass and the inverted file read, for many shapes), and every
sample in :class:`PartsRows`, by slot, with its centroid profiles (what the exact pass
reads, for a shortlist): in memory, or in a file read row by row, so that a gallery of a
million shapes keeps 1.9 KB a shape of profiles in memory instead of 24 KB. Slots are
never reused, so the file only grows, and a saved index's rows are never overwritten.
"""

from __future__ import annotations

import hashlib
import os
import weakref
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from worker.engine.parts import COARSE_SAMPLES
from worker.engine.presets import MODALITIES, PARTS, SIZE

INITIAL_CAPACITY = 64


def ids_fingerprint(ids: np.ndarray) -> str:
    """A digest of a set of ids (order-free), to compare an index with the database."""
    return hashlib.sha256(np.sort(np.asarray(ids, dtype=np.int64)).tobytes()).hexdigest()


class PartsRows:
    """Every sample's profiles of each shape, by slot: (m, K) float16 a slot.

    Parameters
    ----------
    shape : (m, K) of a shape's profiles.
    path : a file to keep them in (read and written row by row, never mapped: read
        rows stay out of the process's memory); None keeps them in memory.
    """

    def __init__(self, shape: tuple[int, int], path: Path | None = None) -> None:
        self.shape = shape
        self.path = path
        self.row_bytes = int(np.prod(shape)) * 2
        self.count = 0  # slots used
        self._memory = np.empty((0 if path else INITIAL_CAPACITY, *shape), dtype=np.float16)
        self._fd: int | None = None
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            weakref.finalize(self, os.close, self._fd)  # an index replaced lets its file go

    def append(self, rows: np.ndarray) -> int:
        """Store a shape's rows in the next slot; the slot."""
        slot = self.count
        data = np.ascontiguousarray(rows, dtype=np.float16)
        if self._fd is not None:
            os.pwrite(self._fd, data.tobytes(), slot * self.row_bytes)
        else:
            if slot == len(self._memory):
                grown = np.empty((max(2 * slot, INITIAL_CAPACITY), *self.shape), np.float16)
                grown[:slot] = self._memory[:slot]
                self._memory = grown
            self._memory[slot] = data
        self.count += 1
        return slot

    def read(self, slots: np.ndarray) -> np.ndarray:
        """(len(slots), m, K) float16, the rows of ``slots``."""
        slots = np.asarray(slots, dtype=np.int64)
        if self._fd is None:
            rows: np.ndarray = self._memory[slots]
            return rows
        out = np.empty((len(slots), *self.shape), dtype=np.float16)
        for row, slot in enumerate(slots):
            data = os.pread(self._fd, self.row_bytes, int(slot) * self.row_bytes)
            out[row] = np.frombuffer(data, dtype=np.float16).reshape(self.shape)
        return out

    def flush(self) -> None:
        """Make the file's rows durable (a saved index refers to them)."""
        if self._fd is not None:
            os.fsync(self._fd)


class GalleryVectors:
    """Exact vectors of every modality, by position, with running sums for sigma.

    Parameters
    ----------
    dims : modality -> M_m, the length of its flat vector.
    parts_shape : (m, K) of a shape's compared parts profiles; None: no parts.
    parts_path : the file of every sample's profiles (:class:`PartsRows`); None: in memory.
    coarse_values : the first values of each sample the coarse rows keep (the area
        profiles', :func:`worker.engine.parts.coarse`).
    """

    def __init__(
        self,
        dims: Mapping[str, int],
        parts_shape: tuple[int, int] | None,
        parts_path: Path | None,
        coarse_values: int,
    ) -> None:
        self.dims = dict(dims)
        self.parts_shape = parts_shape
        m, k = parts_shape or (0, 0)
        # The first samples of each shape by position, and every sample's by slot.
        shape = (INITIAL_CAPACITY, min(m, COARSE_SAMPLES), min(k, coarse_values))
        self.coarse = np.empty(shape, dtype=np.float16)
        self.rows = PartsRows((m, k), parts_path) if parts_shape else None
        self.slots = np.full(INITIAL_CAPACITY, -1, dtype=np.int64)
        self.modalities = tuple(m for m in (*MODALITIES, SIZE) if m in self.dims)
        self.ids = np.empty(INITIAL_CAPACITY, dtype=np.int64)  # (capacity,) id by position
        self.pos: dict[int, int] = {}
        self.n = 0
        self.vectors = {m: np.empty((INITIAL_CAPACITY, d)) for m, d in self.dims.items()}
        self.shift = {m: np.zeros(d) for m, d in self.dims.items()}
        self.sum = {m: np.zeros(d) for m, d in self.dims.items()}
        self.sumsq = {m: np.zeros(d) for m, d in self.dims.items()}
        self._sigma: dict[str, np.ndarray] | None = None
        self._pos_table: np.ndarray | None = None

    @property
    def capacity(self) -> int:
        return len(self.ids)

    def current_ids(self) -> np.ndarray:
        """(n,) int64, the enrolled ids by position (a copy)."""
        return self.ids[: self.n].copy()

    def append(self, item: int, vectors: Mapping[str, np.ndarray]) -> int:
        """Store ``item``'s vectors (modality -> (M_m,) float, and ``PARTS`` -> (m, K)
        when the store keeps parts) at the end; its position."""
        self.ensure_capacity(self.n + 1)
        i = self.n
        rows = {}
        for m in self.modalities:
            x = np.asarray(vectors[m], dtype=np.float64).ravel()
            if x.shape != (self.dims[m],):
                raise ValueError(f"{m}: expected {self.dims[m]} values, got {x.size}")
            rows[m] = x
        if self.rows is not None:
            parts = np.asarray(vectors[PARTS])
            if parts.shape != self.parts_shape:
                raise ValueError(f"parts: expected {self.parts_shape}, got {parts.shape}")
            self.coarse[i] = parts[: self.coarse.shape[1], : self.coarse.shape[2]]
            self.slots[i] = self.rows.append(parts)
        for m, x in rows.items():
            self.vectors[m][i] = x
            d = x - self.shift[m]
            self.sum[m] += d
            self.sumsq[m] += d * d
        self.ids[i] = item
        self.pos[item] = i
        self.n += 1
        self._changed()
        return i

    def pop(self, item: int) -> tuple[int, int]:
        """Remove ``item``; ``(its position, the position of the row moved into it)``.

        The two are equal when ``item`` was the last row (nothing moved).
        """
        i = self.pos.pop(item)
        last = self.n - 1
        for m in self.modalities:
            d = self.vectors[m][i] - self.shift[m]
            self.sum[m] -= d
            self.sumsq[m] -= d * d
            self.vectors[m][i] = self.vectors[m][last]
        self.coarse[i] = self.coarse[last]
        self.slots[i] = self.slots[last]
        if i != last:
            moved = int(self.ids[last])
            self.ids[i] = moved
            self.pos[moved] = i
        self.n -= 1
        self._changed()
        return i, last

    def ensure_capacity(self, n: int) -> None:
        if n <= self.capacity:
            return
        capacity = max(n, 2 * self.capacity)
        ids = np.empty(capacity, dtype=np.int64)
        ids[: self.n] = self.ids[: self.n]
        self.ids = ids
        for m in self.modalities:
            grown = np.empty((capacity, self.dims[m]), dtype=np.float64)
            grown[: self.n] = self.vectors[m][: self.n]
            self.vectors[m] = grown
        coarse = np.empty((capacity, *self.coarse.shape[1:]), dtype=np.float16)
        coarse[: self.n] = self.coarse[: self.n]
        self.coarse = coarse
        slots = np.full(capacity, -1, dtype=np.int64)
        slots[: self.n] = self.slots[: self.n]
        self.slots = slots

    def parts_at(self, positions: np.ndarray) -> np.ndarray:
        """(len(positions), m, K) float16: every sample's profiles of the shapes there."""
        assert self.rows is not None, "no parts"
        return self.rows.read(self.slots[np.asarray(positions, dtype=np.int64)])

    def _changed(self) -> None:
        self._sigma = None
        self._pos_table = None

    def sigma(self) -> dict[str, np.ndarray]:
        """sigma_i of eq. (9) over the current gallery, per modality (as ``gallery_sigma``)."""
        if self._sigma is None:
            n = max(self.n, 1)
            out = {}
            for m in self.modalities:
                mean = self.sum[m] / n
                var = np.maximum(self.sumsq[m] / n - mean * mean, 0.0)
                sigma = np.sqrt(var)
                # Exact zeros are constant elements (gallery_sigma gives them 1);
                # rounding residue of the running sums is treated the same way.
                scale = np.sqrt(self.sumsq[m] / n) + np.abs(self.shift[m])
                out[m] = np.where(sigma > 1e-7 * np.maximum(scale, 1e-300), sigma, 1.0)
            self._sigma = out
        return self._sigma

    def recentre(self) -> None:
        """Shift the running sums to the current mean (keeps them accurate)."""
        for m in self.modalities:
            x = self.vectors[m][: self.n]
            mean = x.mean(axis=0) if self.n else np.zeros(self.dims[m])
            dev = x - mean
            self.shift[m] = mean
            self.sum[m] = dev.sum(axis=0)
            self.sumsq[m] = (dev * dev).sum(axis=0)
        self._sigma = None

    def positions(self, ids: np.ndarray) -> np.ndarray:
        """Positions of enrolled ``ids`` (a dense id -> position table, rebuilt after changes)."""
        positions: np.ndarray = self._position_table()[ids]
        return positions

    def contains(self, ids: np.ndarray) -> np.ndarray:
        """(len(ids),) bool: which of ``ids`` (any non-negative ints) are enrolled."""
        table = self._position_table()
        ids = np.asarray(ids, dtype=np.int64)
        inside = ids < len(table)
        found = np.zeros(len(ids), dtype=bool)
        found[inside] = table[ids[inside]] >= 0
        return found

    def _position_table(self) -> np.ndarray:
        """The dense id -> position table (-1: not enrolled), up to the largest id."""
        if self._pos_table is None:
            table = np.full(int(self.ids[: self.n].max(initial=-1)) + 1, -1, dtype=np.int64)
            table[self.ids[: self.n]] = np.arange(self.n)
            self._pos_table = table
        return self._pos_table
