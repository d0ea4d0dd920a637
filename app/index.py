"""The gallery index: faiss candidates per modality, exact fused ranking.

How a search works
------------------
Each modality ``m`` of the gallery is kept twice: the exact vectors (float64,
for scoring) and a faiss ``IndexFlatL2`` over a transformed vector ``t_m(x)``
that gives candidates. The final ranking is always the exact fused score of
the preset: eq. (8) D1 or eq. (9) D2 per modality, then the sum or product
rule (``worker.engine.compare``).

* D2 (the default preset): ``t_m(x) = P_m^T (x / sigma_fit_m - mu_m)`` with
  ``P_m`` orthonormal (PCA of the whitened gallery, at most ``MAX_DIMS``
  columns; the identity for the GDM's 19 and the spectrum's 50 elements).
  faiss returns ``CANDIDATES`` shapes per modality; their union is ranked by a
  fused *estimate* (exact D2 for the short modalities, the projected distance
  for the DDT's 2,000 elements), and the DDT is scored exactly in that order
  for at most ``MAX_SCORED`` shapes. An orthonormal projection never
  lengthens a vector, so the projected distance times
  ``rho_m = min_i sigma_fit_i / sigma_now_i`` is a *lower bound* of D2 under
  the current sigma. Two certificates follow: (1) inside the union, scoring
  stops once the k-th exact score is below every remaining lower bound;
  (2) a shape outside the union scores at least ``fuse({m: rho_m * t_m})``
  with ``t_m`` the last candidate distance of modality m (Fagin's threshold
  algorithm). When both hold the top-k *is* the exhaustive one
  (``SearchStats.certified``); when the union certificate holds but not the
  outside one, the candidate count grows x4 up to ``MAX_CANDIDATES``.
  Otherwise the answer is best effort: on descriptors shaped like TOSCA's the
  whitened DDT has too much independent per-element variation for the 64-D
  bound to be tight, so certification is rare there, and recall@10 is
  *measured* instead (``bench/index_bench.py``, ``docs/benchmarks.md``).
* D1 has no cheap bound. Its candidates come from the L2 distance of
  log-descriptors (eq. 8's terms are ``2 tanh(|log a - log b| / 2)``, close
  to ``|log a - log b|`` for similar shapes) projected the same way, with
  ``CANDIDATES`` per modality, all scored exactly.

D2's sigma
----------
``sigma`` of eq. (9) is the per-element standard deviation over the *current*
gallery, kept exactly up to date from running sums (shifted by the fitted mean
to avoid cancellation) on every add and delete, so scores always use the
current gallery's sigma. The transforms (``mu``, ``sigma_fit``, ``P``) are
refitted, and the faiss indexes rebuilt, when the gallery has changed by more
than ``refit_fraction`` of its size since the last fit; in between, ``rho_m``
keeps the certificate valid.

Thread safety: all public methods take one lock (searches take milliseconds).
"""

from __future__ import annotations

import hashlib
import json
import shutil
import threading
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import faiss
import numpy as np

from worker.engine.compare import fuse, mean_normalized_manhattan, normalized_euclidean
from worker.engine.presets import MODALITIES, Preset

MAX_DIMS = 64  # columns of the candidate projection per modality
CANDIDATES = 2048  # faiss candidates per modality (D2), first round
MAX_CANDIDATES = 16_384  # per modality, when more rounds can still certify the top-k
MAX_SCORED = 256  # long-modality exact scores per round, in fused-estimate order
FIT_SAMPLE = 5_000  # rows used to fit a projection (any orthonormal P keeps the bound)
BOUND_SAFETY = 1.0 - 1e-5  # float32 candidate distances: keep the bound a true lower bound
FORMAT_VERSION = 1


def _single_threaded_faiss() -> None:
    """One query at a time: faiss's OpenMP team costs more than it saves (2-15 ms
    per search on a busy 2-core machine, even for 83 shapes), and the API's
    threads and the workers already use the cores. OpenMP's setting is per
    calling thread, so this runs in every thread that searches."""
    faiss.omp_set_num_threads(1)


@dataclass
class Match:
    """One ranked gallery shape: its id, fused score and per-modality dissimilarities."""

    id: int
    score: float
    scores: dict[str, float]


@dataclass
class SearchStats:
    candidates: int = 0  # shapes returned by faiss (union over modalities)
    scored: int = 0  # shapes whose exact long-modality score was computed
    rounds: int = 0
    certified: bool = False
    seconds: float = 0.0


@dataclass
class _Fit:
    """Candidate transform of one modality, fixed between refits."""

    mu: np.ndarray  # (M,) shift (mean of t, or of log x for D1)
    scale: np.ndarray  # (M,) divisor before projecting (sigma_fit for D2, 1 for D1)
    floor: np.ndarray  # (M,) D1 only: values clipped here before the log
    projection: np.ndarray  # (M, r) orthonormal columns
    index: faiss.Index = field(repr=False)


def _growable(m: int, capacity: int = 64) -> np.ndarray:
    return np.empty((capacity, m), dtype=np.float64)


class GalleryIndex:
    """Descriptors of enrolled shapes under one preset; see the module docstring."""

    def __init__(
        self,
        preset: Preset,
        dims: Mapping[str, int],
        *,
        refit_fraction: float = 0.05,
        max_dims: int = MAX_DIMS,
        candidates: int = CANDIDATES,
        max_candidates: int = MAX_CANDIDATES,
        max_scored: int = MAX_SCORED,
    ) -> None:
        self.preset = preset
        self.dims = dict(dims)
        self.modalities = tuple(m for m in MODALITIES if m in self.dims)
        self.refit_fraction = refit_fraction
        self.max_dims = max_dims
        self.candidates = candidates
        self.max_candidates = max_candidates
        self.max_scored = max_scored
        self._lock = threading.RLock()
        self._ids = np.empty(64, dtype=np.int64)
        self._pos: dict[int, int] = {}
        self._n = 0
        self._vectors = {m: _growable(d) for m, d in self.dims.items()}
        # Transformed vectors t_m(x) by position (what faiss holds), for cheap bounds.
        self._reduced: dict[str, np.ndarray] = {}
        # Running sums of (x - shift) and (x - shift)^2 for the current sigma.
        self._shift = {m: np.zeros(d) for m, d in self.dims.items()}
        self._sum = {m: np.zeros(d) for m, d in self.dims.items()}
        self._sumsq = {m: np.zeros(d) for m, d in self.dims.items()}
        self._sigma_cache: dict[str, np.ndarray] | None = None
        self._pos_cache: np.ndarray | None = None
        self._fits: dict[str, _Fit] | None = None
        self._n_at_fit = 0
        self._changes_since_fit = 0
        self.dirty = False
        self.refits = 0

    # ------------------------------------------------------------------ size
    def __len__(self) -> int:
        return self._n

    def __contains__(self, item: int) -> bool:
        return item in self._pos

    def ids(self) -> np.ndarray:
        with self._lock:
            return self._ids[: self._n].copy()

    def fingerprint(self) -> str:
        """A digest of the set of ids (to compare with the database)."""
        return ids_fingerprint(self.ids())

    # --------------------------------------------------------------- updates
    def add(self, item: int, vectors: Mapping[str, np.ndarray]) -> None:
        """Add (or replace) shape ``item``; searchable on return."""
        if item < 0:
            raise ValueError("ids must be non-negative")
        with self._lock:
            if item in self._pos:
                self._remove(item)
            self._ensure_capacity(self._n + 1)
            i = self._n
            self._ids[i] = item
            self._pos[item] = i
            for m in self.modalities:
                x = np.asarray(vectors[m], dtype=np.float64).ravel()
                if x.shape != (self.dims[m],):
                    raise ValueError(f"{m}: expected {self.dims[m]} values, got {x.size}")
                self._vectors[m][i] = x
                d = x - self._shift[m]
                self._sum[m] += d
                self._sumsq[m] += d * d
                if self._fits is not None:
                    fit = self._fits[m]
                    t = self._transform(m, fit, x[None, :])
                    self._reduced[m][i] = t[0]
                    fit.index.add_with_ids(t, np.array([item], dtype=np.int64))
            self._n += 1
            self._changed()

    def add_many(self, items: Iterable[tuple[int, Mapping[str, np.ndarray]]]) -> None:
        """Add many shapes, then refit once (building from a database)."""
        with self._lock:
            fits, self._fits = self._fits, None
            for item, vectors in items:
                self.add(item, vectors)
            self._fits = fits
            self.refit()

    def remove(self, item: int) -> bool:
        """Remove shape ``item``; gone from results on return. False if absent."""
        with self._lock:
            if item not in self._pos:
                return False
            self._remove(item)
            self._changed()
            return True

    def _remove(self, item: int) -> None:
        i = self._pos.pop(item)
        last = self._n - 1
        for m in self.modalities:
            d = self._vectors[m][i] - self._shift[m]
            self._sum[m] -= d
            self._sumsq[m] -= d * d
            self._vectors[m][i] = self._vectors[m][last]
            if self._fits is not None:
                self._reduced[m][i] = self._reduced[m][last]
                # faiss's Python wrapper accepts an id array in place of an IDSelector.
                self._fits[m].index.remove_ids(np.array([item], dtype=np.int64))  # type: ignore[arg-type]
        if i != last:
            moved = int(self._ids[last])
            self._ids[i] = moved
            self._pos[moved] = i
        self._n -= 1

    def _ensure_capacity(self, n: int) -> None:
        if n <= len(self._ids):
            return
        capacity = max(n, 2 * len(self._ids))
        ids = np.empty(capacity, dtype=np.int64)
        ids[: self._n] = self._ids[: self._n]
        self._ids = ids
        for m in self.modalities:
            grown = np.empty((capacity, self.dims[m]), dtype=np.float64)
            grown[: self._n] = self._vectors[m][: self._n]
            self._vectors[m] = grown
            if m in self._reduced:
                reduced = np.empty((capacity, self._reduced[m].shape[1]), dtype=np.float32)
                reduced[: self._n] = self._reduced[m][: self._n]
                self._reduced[m] = reduced

    def _changed(self) -> None:
        self._sigma_cache = None
        self._pos_cache = None
        self._changes_since_fit += 1
        self.dirty = True
        if self._fits is not None and self._changes_since_fit > self.refit_fraction * max(
            self._n_at_fit, 1
        ):
            self.refit()

    # ----------------------------------------------------------------- sigma
    def sigma(self) -> dict[str, np.ndarray]:
        """sigma_i of eq. (9) over the current gallery, per modality (as ``gallery_sigma``)."""
        with self._lock:
            if self._sigma_cache is None:
                n = max(self._n, 1)
                out = {}
                for m in self.modalities:
                    mean = self._sum[m] / n
                    var = np.maximum(self._sumsq[m] / n - mean * mean, 0.0)
                    sigma = np.sqrt(var)
                    # Exact zeros are constant elements (gallery_sigma gives them 1);
                    # rounding residue of the running sums is treated the same way.
                    scale = np.sqrt(self._sumsq[m] / n) + np.abs(self._shift[m])
                    out[m] = np.where(sigma > 1e-7 * np.maximum(scale, 1e-300), sigma, 1.0)
                self._sigma_cache = out
            return self._sigma_cache

    # ----------------------------------------------------------------- fit
    def refit(self) -> None:
        """Refit the candidate transforms on the current gallery and rebuild faiss."""
        with self._lock:
            n = self._n
            fits: dict[str, _Fit] = {}
            rng = np.random.default_rng(0)
            sample = np.sort(rng.choice(n, FIT_SAMPLE, replace=False)) if n > FIT_SAMPLE else None
            for m in self.modalities:
                x = self._vectors[m][:n]
                # Recentre the running sums on the current mean (keeps them accurate).
                mean = x.mean(axis=0) if n else np.zeros(self.dims[m])
                dev = x - mean
                self._shift[m] = mean
                self._sum[m] = dev.sum(axis=0)
                self._sumsq[m] = (dev * dev).sum(axis=0)
                fits[m] = self._fit(m, x if sample is None else x[sample], x)
            self._fits = fits
            self._sigma_cache = None
            self._n_at_fit = n
            self._changes_since_fit = 0
            self.refits += 1
            self.dirty = True

    def _fit(self, m: str, fit_rows: np.ndarray, all_rows: np.ndarray) -> _Fit:
        dim = self.dims[m]
        if self.preset.dissimilarity == "D2":
            floor = np.zeros(dim)
            std = fit_rows.std(axis=0) if len(fit_rows) else np.ones(dim)
            scale = np.where(std > 0, std, 1.0)
            t = fit_rows / scale
        else:
            positive = np.where(fit_rows > 0, fit_rows, np.nan)
            with np.errstate(all="ignore"):
                typical = np.nanmedian(positive, axis=0) if len(fit_rows) else np.ones(dim)
            typical = np.where(np.isfinite(typical), typical, 1.0)
            floor = 1e-6 * typical
            scale = np.ones(dim)
            t = np.log(np.maximum(fit_rows, floor))
        mu = t.mean(axis=0) if len(t) else np.zeros(dim)
        r = min(dim, self.max_dims)
        if r == dim:
            projection = np.eye(dim)
        else:
            centred = t - mu
            basis = _principal_directions(centred, r) if len(centred) >= 2 else np.zeros((dim, 0))
            if basis.shape[1] < r:  # tiny galleries: complete with an orthonormal basis
                q, _ = np.linalg.qr(
                    np.concatenate([basis, np.random.default_rng(1).normal(size=(dim, r))], 1)
                )
                basis = q[:, :r]
            projection = basis
        index = faiss.IndexIDMap2(faiss.IndexFlatL2(projection.shape[1]))
        fit = _Fit(mu=mu, scale=scale, floor=floor, projection=projection, index=index)
        reduced = np.empty((len(self._ids), projection.shape[1]), dtype=np.float32)
        if len(all_rows):
            for start in range(0, len(all_rows), 8192):  # bounded temporary memory
                stop = min(start + 8192, len(all_rows))
                reduced[start:stop] = self._transform(m, fit, all_rows[start:stop])
            index.add_with_ids(reduced[: len(all_rows)], self._ids[: len(all_rows)])
        self._reduced[m] = reduced
        return fit

    def _transform(self, m: str, fit: _Fit, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        if self.preset.dissimilarity == "D2":
            t = x / fit.scale
        else:
            t = np.log(np.maximum(x, fit.floor))
        return np.ascontiguousarray((t - fit.mu) @ fit.projection, dtype=np.float32)

    # ---------------------------------------------------------------- search
    def exact_scores(
        self,
        query: Mapping[str, np.ndarray],
        positions: np.ndarray,
        modalities: tuple[str, ...],
        rule: str,
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Fused and per-modality dissimilarities of ``query`` to gallery rows ``positions``."""
        sigma = self.sigma() if self.preset.dissimilarity == "D2" else None
        per: dict[str, np.ndarray] = {}
        for m in modalities:
            g = self._vectors[m][positions]
            q = np.asarray(query[m], dtype=np.float64).ravel()[None, :]
            if sigma is None:
                per[m] = mean_normalized_manhattan(q, g)[0]
            else:
                per[m] = normalized_euclidean(q, g, sigma[m])[0]
        weights = {m: self.preset.weight(m) for m in modalities}
        return np.asarray(fuse(per, rule, weights), dtype=np.float64), per

    def search(
        self,
        query: Mapping[str, np.ndarray],
        k: int,
        *,
        fusion: str | None = None,
        modalities: tuple[str, ...] | None = None,
        exclude: Iterable[int] = (),
        exhaustive: bool = False,
        stats: SearchStats | None = None,
    ) -> list[Match]:
        """The ``k`` gallery shapes with the lowest fused dissimilarity to ``query``.

        Parameters
        ----------
        query : modality -> (M_m,) float, the query's descriptor vectors.
        k : number of matches.
        fusion : "sum" or "product"; default the preset's rule.
        modalities : fused modalities; default the preset's.
        exclude : ids left out (e.g. the query shape itself).
        exhaustive : score every gallery shape (the reference ranking).

        Returns
        -------
        Matches sorted by score (ties by id).
        """
        start = time.perf_counter()
        _single_threaded_faiss()
        rule = fusion or self.preset.fusion
        mods = tuple(modalities or self.preset.fused_modalities)
        excluded = set(int(e) for e in exclude)
        stats = stats if stats is not None else SearchStats()
        with self._lock:
            n = self._n
            if n == 0 or k <= 0:
                return []
            if self._fits is None and not exhaustive:
                self.refit()
            want = min(n, k + len(excluded & self._pos.keys()))
            if exhaustive:
                positions = np.arange(n)
                fused, per = self.exact_scores(query, positions, mods, rule)
                stats.candidates, stats.certified = n, True
            else:
                positions, fused, per = self._candidate_search(query, want, mods, rule, stats)
            ids = self._ids[positions]
            keep = np.array([int(i) not in excluded for i in ids], dtype=bool)
            ids, fused = ids[keep], fused[keep]
            per = {m: v[keep] for m, v in per.items()}
            order = np.lexsort((ids, fused))[:k]
            matches = [
                Match(
                    id=int(ids[j]),
                    score=float(fused[j]),
                    scores={m: float(per[m][j]) for m in mods},
                )
                for j in order
            ]
        stats.seconds = time.perf_counter() - start
        return matches

    def _candidate_search(
        self,
        query: Mapping[str, np.ndarray],
        want: int,
        mods: tuple[str, ...],
        rule: str,
        stats: SearchStats,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Candidates from faiss, exact scores for as few of them as certifies the top-k.

        Returns the positions whose exact scores were computed, their fused and
        per-modality scores; every shape not among them scores above the k-th.
        """
        assert self._fits is not None
        n = self._n
        d2 = self.preset.dissimilarity == "D2"
        weights = {m: self.preset.weight(m) for m in mods}
        q = {m: np.asarray(query[m], dtype=np.float64).ravel() for m in mods}
        transformed = {m: self._transform(m, self._fits[m], q[m][None, :]) for m in mods}
        if not d2:
            count = min(n, max(self.candidates, 4 * want))
            labels = [self._fits[m].index.search(transformed[m], count)[1][0] for m in mods]
            union = np.unique(np.concatenate(labels))
            positions = self._positions(union[union >= 0])
            fused, exact = self.exact_scores(query, positions, mods, rule)
            stats.rounds, stats.candidates, stats.certified = 1, len(positions), count >= n
            return positions, fused, exact

        sigma = self.sigma()
        rho = {m: float(np.min(self._fits[m].scale / sigma[m])) * BOUND_SAFETY for m in mods}
        # Short modalities (GDM, spectrum) are scored exactly for every candidate; the
        # long one (DDT, 2,000 elements) is estimated by its projected distance, and
        # scored exactly in the order of the fused estimate.
        cheap = tuple(m for m in mods if self.dims[m] <= self.max_dims)
        costly = tuple(m for m in mods if m not in cheap)
        count = max(self.candidates, 4 * want)
        batch = max(2 * want, 32)
        while True:
            stats.rounds += 1
            count = min(count, n)
            found, threshold = [], {}
            for m in mods:
                dist, labels = self._fits[m].index.search(transformed[m], count)
                found.append(labels[0][labels[0] >= 0])
                threshold[m] = rho[m] * float(np.sqrt(max(dist[0][-1], 0.0)))
            positions = self._positions(np.unique(np.concatenate(found)))
            per: dict[str, np.ndarray] = {}
            for m in cheap:
                g = self._vectors[m][positions]
                per[m] = normalized_euclidean(q[m][None, :], g, sigma[m])[0]
            estimate, bound = dict(per), dict(per)
            for m in costly:
                diff = self._reduced[m][positions].astype(np.float64) - transformed[m][0]
                estimate[m] = np.sqrt((diff * diff).sum(axis=1))
                bound[m] = rho[m] * estimate[m]
            order = np.argsort(np.asarray(fuse(estimate, rule, weights)), kind="stable")
            lower = np.asarray(fuse(bound, rule, weights), dtype=np.float64)[order]
            # Smallest lower bound among the not yet scored: when the k-th exact score
            # is below it, no remaining candidate can enter the top-k.
            rest_min = np.append(np.minimum.accumulate(lower[::-1])[::-1], np.inf)
            fused = np.full(len(positions), np.inf)
            for m in costly:
                per[m] = np.full(len(positions), np.inf)
            done, kth, exact_in_union = 0, np.inf, False
            while done < len(order):
                chunk = order[done : done + batch]
                for m in costly:
                    g = self._vectors[m][positions[chunk]]
                    per[m][chunk] = normalized_euclidean(q[m][None, :], g, sigma[m])[0]
                fused[chunk] = fuse({m: per[m][chunk] for m in mods}, rule, weights)
                done += len(chunk)
                if done >= want:
                    kth = np.partition(fused[order[:done]], want - 1)[want - 1]
                    if kth <= rest_min[done]:
                        exact_in_union = True
                        break
                    if done >= self.max_scored:
                        break
            exact_in_union = exact_in_union or done == len(order)
            refined = order[:done]
            stats.candidates, stats.scored = len(positions), done
            out = positions[refined], fused[refined], {m: v[refined] for m, v in per.items()}
            outside = float(fuse({m: np.asarray(t) for m, t in threshold.items()}, rule, weights))
            if exact_in_union and (count >= n or kth <= outside):
                stats.certified = True
                return out
            if not exact_in_union or count >= self.max_candidates or count >= n:
                return out  # best effort: recall measured in bench/index_bench.py
            count *= 4

    def _positions(self, ids: np.ndarray) -> np.ndarray:
        if self._pos_cache is None:  # id -> position, dense (ids are database ids)
            table = np.full(int(self._ids[: self._n].max(initial=-1)) + 1, -1, dtype=np.int64)
            table[self._ids[: self._n]] = np.arange(self._n)
            self._pos_cache = table
        return self._pos_cache[ids]

    # ---------------------------------------------------------- persistence
    def save(self, directory: Path) -> None:
        """Write the index atomically to ``directory`` (replacing it)."""
        with self._lock:
            if self._fits is None:
                self.refit()
            tmp = directory.with_name(directory.name + ".tmp")
            shutil.rmtree(tmp, ignore_errors=True)
            tmp.mkdir(parents=True)
            n = self._n
            fits = self._fits
            assert fits is not None
            arrays: dict[str, np.ndarray] = {"ids": self._ids[:n]}
            for m in self.modalities:
                fit = fits[m]
                arrays.update(
                    {
                        f"{m}.vectors": self._vectors[m][:n],
                        f"{m}.shift": self._shift[m],
                        f"{m}.sum": self._sum[m],
                        f"{m}.sumsq": self._sumsq[m],
                        f"{m}.mu": fit.mu,
                        f"{m}.scale": fit.scale,
                        f"{m}.floor": fit.floor,
                        f"{m}.projection": fit.projection,
                        f"{m}.reduced": self._reduced[m][:n],
                    }
                )
                faiss.write_index(fit.index, str(tmp / f"{m}.faiss"))
            np.savez(tmp / "arrays.npz", **arrays)  # type: ignore[arg-type]  # numpy stubs
            manifest = {
                "format": FORMAT_VERSION,
                "preset": self.preset.name,
                "preset_version": self.preset.version,
                "dims": self.dims,
                "size": n,
                "n_at_fit": self._n_at_fit,
                "changes_since_fit": self._changes_since_fit,
                "fingerprint": ids_fingerprint(self._ids[:n]),
                "saved_at": time.time(),
            }
            (tmp / "manifest.json").write_text(json.dumps(manifest, indent=1))
            old = directory.with_name(directory.name + ".old")
            shutil.rmtree(old, ignore_errors=True)
            if directory.exists():
                directory.rename(old)
            tmp.rename(directory)
            shutil.rmtree(old, ignore_errors=True)
            self.dirty = False

    @classmethod
    def load(cls, directory: Path, preset: Preset, **options) -> GalleryIndex:
        """Read an index written by :meth:`save`.

        Raises
        ------
        ValueError
            Missing, corrupt or made for another preset version; rebuild it then.
        """
        try:
            manifest = json.loads((directory / "manifest.json").read_text())
            if manifest.get("format") != FORMAT_VERSION or (
                manifest["preset"],
                manifest["preset_version"],
            ) != (preset.name, preset.version):
                raise ValueError("index made by another format or preset version")
            index = cls(preset, manifest["dims"], **options)
            with np.load(directory / "arrays.npz") as npz:
                arrays = {k: np.array(npz[k]) for k in npz.files}
            n = int(manifest["size"])
            ids = arrays["ids"].astype(np.int64)
            if len(ids) != n or ids_fingerprint(ids) != manifest["fingerprint"]:
                raise ValueError("index ids do not match its manifest")
            index._ensure_capacity(n)
            index._ids[:n] = ids
            index._pos = {int(i): p for p, i in enumerate(ids)}
            index._n = n
            fits = {}
            for m in index.modalities:
                index._vectors[m][:n] = arrays[f"{m}.vectors"]
                index._shift[m] = arrays[f"{m}.shift"]
                index._sum[m] = arrays[f"{m}.sum"]
                index._sumsq[m] = arrays[f"{m}.sumsq"]
                reduced = arrays[f"{m}.reduced"].astype(np.float32)
                index._reduced[m] = np.empty((len(index._ids), reduced.shape[1]), np.float32)
                index._reduced[m][:n] = reduced
                faiss_index = faiss.read_index(str(directory / f"{m}.faiss"))
                if faiss_index.ntotal != n:
                    raise ValueError(f"faiss index of {m} has {faiss_index.ntotal} rows, not {n}")
                fits[m] = _Fit(
                    mu=arrays[f"{m}.mu"],
                    scale=arrays[f"{m}.scale"],
                    floor=arrays[f"{m}.floor"],
                    projection=arrays[f"{m}.projection"],
                    index=faiss_index,
                )
            index._fits = fits
            index._n_at_fit = int(manifest["n_at_fit"])
            index._changes_since_fit = int(manifest["changes_since_fit"])
            index.dirty = False
            return index
        except ValueError:
            raise
        except Exception as exc:  # corrupt files surface as many types
            raise ValueError(f"unreadable index: {exc}") from exc


def _principal_directions(centred: np.ndarray, r: int, oversample: int = 16) -> np.ndarray:
    """(M, <=r) orthonormal top principal directions of centred rows (randomized SVD,
    Halko et al. 2011, two power iterations): a full SVD of 5,000 x 2,000 took
    tens of seconds on a busy 2-core machine, this takes well under one."""
    n, dim = centred.shape
    width = min(r + oversample, n, dim)
    rng = np.random.default_rng(0)
    sample = centred @ rng.normal(size=(dim, width))
    for _ in range(2):
        sample, _ = np.linalg.qr(sample)
        sample, _ = np.linalg.qr(centred @ (centred.T @ sample))
    basis_rows = sample.T @ centred  # (width, M): the rows' content in that subspace
    _, _, vt = np.linalg.svd(basis_rows, full_matrices=False)
    return vt[: min(r, len(vt))].T


def ids_fingerprint(ids: np.ndarray) -> str:
    return hashlib.sha256(np.sort(np.asarray(ids, dtype=np.int64)).tobytes()).hexdigest()


def descriptor_dims(preset: Preset) -> dict[str, int]:
    """Length of each modality's flat vector under ``preset``."""
    return {
        "gdm": preset.gdm_singular_values,
        "ddt": int(np.prod(preset.ddt_core_shape)),
        "spectrum": preset.spectrum_size,
    }
