"""The gallery index: faiss candidates per modality, exact fused ranking.

How a search works
------------------
Each modality ``m`` of the gallery is kept twice: the exact vectors (float64,
for scoring) and a faiss ``IndexFlatL2`` over a transformed vector ``t_m(x)``
that gives candidates. The final ranking is always the exact fused score of
the preset: each modality by its comparison (eq. 8 D1, eq. 9 D2, or ShapeDNA's for
the spectrum; :meth:`~worker.engine.presets.Preset.comparison`), then the sum or
product rule (``worker.engine.compare``).

* D2 (the paper's SHREC preset): ``t_m(x) = P_m^T (x / sigma_fit_m - mu_m)`` with
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
  *measured* instead (``benchmarks/index.py``, ``docs/benchmarks.md``).
* D1 (the default preset) has no cheap bound. Its candidates come from the L2
  distance of log-descriptors (eq. 8's terms are ``2 tanh(|log a - log b| / 2)``,
  close to ``|log a - log b|`` for similar shapes) projected the same way, with
  ``CANDIDATES`` per modality, all scored exactly. So does any mix of comparisons
  (a learned fusion's): ShapeDNA's comparison is an exact L2 of reweighted spectra,
  a D2 modality's candidates its whitened L2; the certified search above is taken
  only when every modality is compared by D2.

D2's sigma
----------
``sigma`` of eq. (9) is the per-element standard deviation over the *current*
gallery, kept exactly up to date from running sums (shifted by the fitted mean
to avoid cancellation) on every add and delete, so scores always use the
current gallery's sigma. The transforms (``mu``, ``sigma_fit``, ``P``) are
refitted, and the faiss indexes rebuilt, when the gallery has changed by more
than ``refit_fraction`` of its size since the last fit; in between, ``rho_m``
keeps the certificate valid.

A query that looks partial (:func:`worker.engine.compare.partiality`) is ranked by
:meth:`GalleryIndex.partial_search` instead: the parts modality
(:mod:`worker.engine.parts`) has no vector to index, so every enrolled shape's profiles
(kept beside the vectors, float16) are compared coarsely with the query (a few
samples of each): every shape, or in a large gallery the candidates an inverted file
of the samples' profiles gives (:mod:`.words`), fused with the flat modalities' exact
scores at the query's weights, and a shortlist is compared with every sample
(``benchmarks/partial_search.py`` measures it); a whole query never takes this path.

Thread safety: all public methods take one lock (searches take milliseconds).

The vectors and running sigma are :mod:`.vectors`, the candidate transforms and
faiss :mod:`.candidates`, files :mod:`.persistence`; :class:`~.service.Gallery`
is what the rest of the service uses.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import faiss
import numpy as np

from worker.engine.compare import (
    fuse,
    normalized_euclidean,
    paired_preset_dissimilarity,
    preset_dissimilarity,
)
from worker.engine.parts import (
    COARSE_SAMPLES,
    PartsMatch,
    area_profiles,
    best_scale,
    can_hold,
    clearest,
    coarse,
    led_part_dissimilarity,
    samples_at_scale,
    scale_count,
    scale_scores,
    sized_dissimilarity,
    sized_scales,
)
from worker.engine.presets import PARTS, SIZE, Preset

from .candidates import FIT_SAMPLE, MAX_DIMS, CandidateTransform
from .vectors import GalleryVectors, ids_fingerprint
from .words import SampleWords, build_words, needs_vocabulary

CANDIDATES = 2048  # faiss candidates per modality (D2), first round
MAX_CANDIDATES = 16_384  # per modality, when more rounds can still certify the top-k
MAX_SCORED = 256  # long-modality exact scores per round, in fused-estimate order
PARTS_BLOCK_SAMPLES = 1 << 16  # gallery samples a partial search compares at once
PARTS_SHORTLIST = 32  # shapes a partial search compares with every sample
#: From this many shapes a partial search takes its candidates from the inverted file of
#: the samples' profiles (.words) instead of comparing every shape coarsely: one in
#: WORD_SHARE of the shapes, at least WORD_CANDIDATES and at most WORD_MAX_CANDIDATES
#: (docs/decisions.md, "Partial queries: one candidate in 50": against the exhaustive
#: ranking, twice as many agree no more often at 10,000 or 100,000 shapes; at a million
#: half as many agree less often).
WORDS_FROM = 4096
WORD_CANDIDATES = 256
WORD_SHARE = 50
WORD_MAX_CANDIDATES = 8192
#: Shapes each scale's votes put first that are compared coarsely to choose the scale:
#: an eighth of the candidates, from WORD_MIN_PROBE to WORD_MAX_PROBE (docs/decisions.md,
#: "A partial query's scale is chosen on an eighth of its candidates": the more shapes a
#: gallery holds, the more of them crowd the top votes at a wrong scale).
WORD_MIN_PROBE = 64
WORD_MAX_PROBE = 256
#: Each scale's best shapes of its probe that are then compared at every scale: a step's
#: best shape scores near the best at the steps beside it, where a million shapes' votes
#: can rank it too low to be probed (docs/decisions.md, "A step's leaders compared at
#: every step").
PROBE_LEADERS = 4
#: The query's samples that vote, those farthest from its boundary: while its candidates
#: are fewer than WORD_MAX_CANDIDATES, twice the coarse pass's (docs/decisions.md, "A
#: partial query votes with 128 samples while its candidates are few": they then miss the
#: exhaustive ranking's first less often; at the cap the candidates hold it already, and
#: the votes, which cost in proportion to the gallery, keep the coarse pass's samples).
VOTE_SAMPLES = 128
#: Beside the inverted file's candidates once they reach WORD_MAX_CANDIDATES, the best of
#: the query searched as a whole (the preset's fusion), one in WHOLE_SHARE of as many
#: (docs/decisions.md, "A million's partial candidates from its whole search too": below
#: the cap the votes' candidates already hold them).
WHOLE_SHARE = 16
#: Query scales on either side of the coarse pass's that the shortlist tries (with the
#: preset's four scales to a step of the grid, three quarters of a step: at 100,000 shapes
#: the whole step agrees with the exhaustive ranking no more often, half of it less
#: often; docs/decisions.md).
SHORTLIST_SCALES = 3
BOUND_SAFETY = 1.0 - 1e-5  # float32 candidate distances: keep the bound a true lower bound


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
    partiality: float = 0.0  # how partial the query looks (0: ranked as a whole)
    kept_share: float | None = None  # share of its whole the query seems to have
    parts_scale: float | None = None  # the parts' scale s of a partial query (kept 1/s^2)
    # The share's bounds: the parts' scale is measured on a grid (worker.engine.parts).
    kept_range: tuple[float, float] | None = None
    # The weight each modality's score carried in the fused score of this search.
    weights: dict[str, float] = field(default_factory=dict)


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
        parts_shape: tuple[int, int] | None = None,
        parts_path: Path | None = None,
    ) -> None:
        self.preset = preset
        self.store = GalleryVectors(dims, parts_shape, parts_path, preset.parts_radii)
        self.dims = self.store.dims
        self.modalities = self.store.modalities
        self.refit_fraction = refit_fraction
        self.max_dims = max_dims
        self.candidates = candidates
        self.max_candidates = max_candidates
        self.max_scored = max_scored
        # Taken by every public method, and by persistence while it reads or writes.
        self.lock = threading.RLock()
        # Transformed vectors t_m(x) by position (what faiss holds), for cheap bounds.
        self.reduced: dict[str, np.ndarray] = {}
        self.fits: dict[str, CandidateTransform] | None = None
        self.n_at_fit = 0
        self.changes_since_fit = 0
        self.dirty = False
        self.refits = 0
        # The inverted file of the samples' profiles, from WORDS_FROM shapes (.words).
        self.words: SampleWords | None = None

    # ------------------------------------------------------------------ size
    def __len__(self) -> int:
        return self.store.n

    def __contains__(self, item: int) -> bool:
        return item in self.store.pos

    def ids(self) -> np.ndarray:
        with self.lock:
            return self.store.current_ids()

    def labelled_vectors(
        self,
        labels: Mapping[int, str],
        choose: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
        """A copy, taken under the lock, of what a fit on the labelled shapes reads:
        their labels, their vectors (in the order of their ids, so that a fit's folds
        depend on the gallery, not on the order its shapes were described in) and eq.
        (9)'s sigma over the whole gallery. ``choose`` picks among the labelled shapes
        (indices, from their labels), so only those are copied."""
        with self.lock:
            ids = np.sort(self.ids())
            ids = ids[np.array([int(i) in labels for i in ids], dtype=bool)]
            names = np.array([labels[int(i)] for i in ids])
            if choose is not None:
                picked = choose(names)
                ids, names = ids[picked], names[picked]
            positions = self.store.positions(ids)
            vectors = {m: self.store.vectors[m][positions].copy() for m in self.modalities}
            sigma = {m: v.copy() for m, v in self.sigma().items()}
        return names, vectors, sigma

    def fingerprint(self) -> str:
        """A digest of the set of ids (to compare with the database)."""
        return ids_fingerprint(self.ids())

    # --------------------------------------------------------------- updates
    def add(self, item: int, vectors: Mapping[str, np.ndarray]) -> None:
        """Add (or replace) shape ``item``; searchable on return."""
        if item < 0:
            raise ValueError("ids must be non-negative")
        with self.lock:
            if item in self.store.pos:
                self._remove(item)
            i = self.store.append(item, vectors)
            if self.words is not None:
                self.words.file(item, self.store.coarse[i])
            if self.fits is not None:
                self._grow_reduced()
                for m in self.modalities:
                    fit = self.fits[m]
                    t = fit.transform(self.store.vectors[m][i][None, :])
                    self.reduced[m][i] = t[0]
                    fit.index.add_with_ids(t, np.array([item], dtype=np.int64))
            self._changed()

    def add_many(self, items: Iterable[tuple[int, Mapping[str, np.ndarray]]]) -> None:
        """Add many shapes, then refit once (building from a database)."""
        with self.lock:
            fits, self.fits = self.fits, None
            for item, vectors in items:
                self.add(item, vectors)
            self.fits = fits
            self.refit()

    def remove(self, item: int) -> bool:
        """Remove shape ``item``; gone from results on return. False if absent."""
        with self.lock:
            if item not in self.store.pos:
                return False
            self._remove(item)
            self._changed()
            return True

    def _remove(self, item: int) -> None:
        i, last = self.store.pop(item)
        if self.words is not None:
            self.words.forget(item)
        if self.fits is not None:
            for m in self.modalities:
                self.reduced[m][i] = self.reduced[m][last]
                ids = np.array([item], dtype=np.int64)
                # arg-type: faiss's stubs want an IDSelector; its Python wrapper takes ids too.
                self.fits[m].index.remove_ids(ids)  # type: ignore[arg-type]

    def _grow_reduced(self) -> None:
        """Keep the transformed rows' capacity that of the vectors."""
        capacity, n = self.store.capacity, self.store.n
        for m, reduced in self.reduced.items():
            if len(reduced) < capacity:
                grown = np.empty((capacity, reduced.shape[1]), dtype=np.float32)
                grown[: n - 1] = reduced[: n - 1]
                self.reduced[m] = grown

    def _changed(self) -> None:
        self.changes_since_fit += 1
        self.dirty = True
        if self.fits is not None and self.changes_since_fit > self.refit_fraction * max(
            self.n_at_fit, 1
        ):
            self.refit()

    def sigma(self) -> dict[str, np.ndarray]:
        """sigma_i of eq. (9) over the current gallery, per modality (as ``gallery_sigma``)."""
        with self.lock:
            return self.store.sigma()

    # ----------------------------------------------------------------- fit
    def refit(self, modalities: Iterable[str] | None = None) -> None:
        """Refit the candidate transforms on the current gallery and rebuild faiss (of
        ``modalities`` only, e.g. those whose comparison changed; default all)."""
        with self.lock:
            n = self.store.n
            rng = np.random.default_rng(0)
            sample = np.sort(rng.choice(n, FIT_SAMPLE, replace=False)) if n > FIT_SAMPLE else None
            whole = modalities is None or self.fits is None
            if whole:
                self.store.recentre()
            fits: dict[str, CandidateTransform] = dict(self.fits or {})
            for m in self.modalities if whole else tuple(modalities or ()):
                x = self.store.vectors[m][:n]
                fit = CandidateTransform.fit(
                    x if sample is None else x[sample],
                    comparison=self.preset.comparison(m),
                    max_dims=self.max_dims,
                    gallery_size=n,
                )
                reduced = np.empty((self.store.capacity, fit.projection.shape[1]), np.float32)
                fit.transform_into(reduced, x, self.store.ids)
                self.reduced[m] = reduced
                fits[m] = fit
            self.fits = fits
            if whole:
                self.n_at_fit = n
                self.changes_since_fit = 0
                self._refile_words(n)
            self.refits += 1
            self.dirty = True

    def _refile_words(self, n: int) -> None:
        """The inverted file of the samples' profiles at a whole refit: from
        ``WORDS_FROM`` shapes, a new vocabulary when the gallery has grown enough since
        the last (:func:`.words.needs_vocabulary`), otherwise every shape filed at once
        with the same words."""
        if self.store.parts_shape is None or n < WORDS_FROM:
            self.words = None
        elif needs_vocabulary(self.words, n):
            self.words = build_words(self.store.ids[:n], self.store.coarse[:n])
        else:
            assert self.words is not None
            self.words = self.words.refiled(self.store.contains)

    def compare_with(self, preset: Preset) -> None:
        """Rank with ``preset`` (the same descriptors; other fusion weights or
        comparisons) from now on, refitting the candidates of every modality whose
        comparison changed."""
        with self.lock:
            changed = [
                m for m in self.modalities if preset.comparison(m) != self.preset.comparison(m)
            ]
            self.preset = preset
            if changed and self.fits is not None:
                self.refit(changed)

    # ---------------------------------------------------------------- search
    def exact_scores(
        self,
        query: Mapping[str, np.ndarray],
        positions: np.ndarray,
        modalities: tuple[str, ...],
        rule: str,
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Fused and per-modality dissimilarities of ``query`` to gallery rows ``positions``."""
        preset = self.preset
        # The current gallery's sigma: the rows scored here may be a few candidates.
        sigma = self.sigma() if preset.uses_sigma(modalities) else None
        per: dict[str, np.ndarray] = {}
        for m in modalities:
            g = self.store.vectors[m][positions]
            q = np.asarray(query[m], dtype=np.float64).ravel()[None, :]
            scale = None if sigma is None else sigma[m]
            per[m] = preset_dissimilarity(m, q, g, preset, scale)[0]
        weights = {m: self.preset.weight(m) for m in modalities}
        return np.asarray(fuse(per, rule, weights), dtype=np.float64), per

    def pair_scores(self, first: np.ndarray, second: np.ndarray) -> dict[str, np.ndarray]:
        """Each flat modality's dissimilarity of the pairs of shapes ``first[i]``,
        ``second[i]`` (ids), as a search scores them (the parts are a query's, not a
        whole's: :meth:`parts_scores`)."""
        preset = self.preset
        with self.lock:
            a, b = self.store.positions(first), self.store.positions(second)
            sigma = self.sigma()
            return {
                m: paired_preset_dissimilarity(
                    m, self.store.vectors[m][a], self.store.vectors[m][b], preset, sigma[m]
                )
                for m in self.modalities
            }

    def parts_scores(self, profiles: np.ndarray, reach: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """The parts dissimilarity of a query (its profiles and reach) to shapes ``ids``,
        every sample compared at the query's best scale, as a partial search's exact pass."""
        with self.lock:
            gallery = self.store.parts_at(self.store.positions(ids))
            return self._parts_scores(profiles, reach, gallery).dissimilarity

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
        modalities : fused modalities; default the preset's scored ones (the size among
            them in a collection of metric units).
        exclude : ids left out (e.g. the query shape itself).
        exhaustive : score every gallery shape (the reference ranking).

        Returns
        -------
        Matches sorted by score (ties by id).
        """
        start = time.perf_counter()
        _single_threaded_faiss()
        rule = fusion or self.preset.fusion
        mods = tuple(modalities or self.preset.scored_modalities)
        excluded = set(int(e) for e in exclude)
        stats = stats if stats is not None else SearchStats()
        with self.lock:
            n = self.store.n
            if n == 0 or k <= 0:
                return []
            if self.fits is None and not exhaustive:
                self.refit()
            want = min(n, k + len(excluded & self.store.pos.keys()))
            if exhaustive:
                positions = np.arange(n)
                fused, per = self.exact_scores(query, positions, mods, rule)
                stats.candidates, stats.certified = n, True
            else:
                positions, fused, per = self._candidate_search(query, want, mods, rule, stats)
            ids = self.store.ids[positions]
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

    def partial_search(
        self,
        query: Mapping[str, np.ndarray],
        profiles: np.ndarray,
        reach: np.ndarray,
        weights: Mapping[str, float],
        k: int,
        *,
        exclude: Iterable[int] = (),
        sized: bool = False,
        stats: SearchStats | None = None,
    ) -> tuple[list[Match], float]:
        """The ``k`` gallery shapes with the lowest product ``prod_m D_m^w_m`` over the
        flat modalities and the parts modality (a query that looks partial,
        :func:`worker.engine.compare.query_weights`).

        Every shape is scored with the flat modalities exactly and the parts coarsely
        (:func:`worker.engine.parts.coarse`) at the scale of each step of the profiles'
        grid, the scale of the best match chosen; from ``WORDS_FROM`` shapes, the
        inverted file of the samples' profiles (:mod:`.words`) chooses the scale and
        ``n / WORD_SHARE`` candidates (from ``WORD_CANDIDATES`` to
        ``WORD_MAX_CANDIDATES``, with the whole query's best ``count / WHOLE_SHARE`` at
        the cap), scored at that scale only (:meth:`_word_candidates`).
        The best ``max(PARTS_SHORTLIST, 2 k)`` by that product are scored with every
        sample, their scale chosen among the chosen one and the ``SHORTLIST_SCALES`` on
        either side of it (the best there compared at each, the rest where those choose:
        :func:`~worker.engine.parts.led_part_dissimilarity`), or with ``sized``, each
        shape's near the scale its size and the query's imply
        (:func:`~worker.engine.parts.sized_dissimilarity`), the shortlist then drawn from
        the shapes large enough to hold the query.

        Parameters
        ----------
        query : modality -> (M_m,) float, the query's flat vectors.
        profiles, reach : the query's parts profiles (m, C) and its samples' reach.
        weights : the product's exponent per modality (``PARTS`` among them).
        sized : the shortlist compared at the scales the sizes imply
            (:func:`~worker.engine.parts.compared_by_size`; the query's and every
            shape's ``SIZE`` vector, a collection of metric units).

        Returns
        -------
        The matches (``scores`` per weighed modality) and the query's parts scale; a shape
        the parts cannot compare (``inf``: no sample of the query clear of its boundary, or
        with ``sized`` a shape too small to hold it) is no match.
        """
        start = time.perf_counter()
        excluded = np.array(sorted(int(e) for e in exclude), dtype=np.int64)
        stats = stats if stats is not None else SearchStats()
        with self.lock:
            n, shape = self.store.n, self.store.parts_shape
            if shape is None:
                raise ValueError("this index keeps no parts profiles")
            if n == 0 or k <= 0:
                return [], 1.0
            flat = tuple(m for m in weights if m != PARTS)
            few = coarse(profiles, reach, self.store.coarse[:n], self.preset)
            # The coarse pass at each step of the grid, the best chosen over the candidates.
            scales = range(0, scale_count(self.preset), self.preset.parts_scale_steps)
            if self.words is not None:
                count = min(max(WORD_CANDIDATES, n // WORD_SHARE), WORD_MAX_CANDIDATES)
                voting = VOTE_SAMPLES if count < WORD_MAX_CANDIDATES else COARSE_SAMPLES
                voters = clearest(reach, voting)
                areas = area_profiles(profiles[voters], self.preset)
                scales, found_ids = self._word_candidates(
                    (areas, reach[voters]), few[:2], count, excluded
                )
                if count == WORD_MAX_CANDIDATES:
                    # Fewer than one shape in WORD_SHARE: the whole query's best join them
                    # (a part's whole-surface vectors still point at its object).
                    whole = self.search(query, count // WHOLE_SHARE, exclude=excluded.tolist())
                    found_ids = np.union1d(found_ids, np.array([m.id for m in whole], np.int64))
                positions = np.sort(self.store.positions(found_ids))
            else:
                positions = np.flatnonzero(~np.isin(self.store.ids[:n], excluded))
            if not len(positions):
                return [], 1.0
            per = self.exact_scores(query, positions, flat, "sum")[1] if flat else {}
            rough_parts = self._parts_scores(*few[:2], few[2][positions], scales, rough=True)
            per[PARTS] = rough_parts.dissimilarity
            rough = np.asarray(fuse(per, "product", dict(weights)), dtype=np.float64)
            if sized:  # the shortlist from the shapes large enough to hold the query
                sizes = self.store.vectors[SIZE][positions, 0]
                centres = sized_scales(float(query[SIZE][0]), sizes, self.preset)
                rough[~can_hold(centres, self.preset)] = np.inf
            short = np.argsort(rough, kind="stable")[: max(PARTS_SHORTLIST, 2 * k)]
            positions = positions[short]
            per = {m: v[short] for m, v in per.items() if m != PARTS}
            shortlisted = self.store.parts_at(positions)
            if sized:
                centres = centres[short]
                found = sized_dissimilarity(profiles, reach, shortlisted, self.preset, centres)
            else:
                tried = range(
                    max(0, rough_parts.j - SHORTLIST_SCALES),
                    min(scale_count(self.preset), rough_parts.j + SHORTLIST_SCALES + 1),
                )
                found = led_part_dissimilarity(
                    profiles, reach, shortlisted, self.preset, tried, rough_parts.j
                )
            per[PARTS] = found.dissimilarity
            fused = np.asarray(fuse(per, "product", dict(weights)), dtype=np.float64)
            ids = self.store.ids[positions]
            order = [j for j in np.lexsort((ids, fused)) if np.isfinite(fused[j])][:k]
            matches = [
                Match(
                    id=int(ids[j]),
                    score=float(fused[j]),
                    scores={m: float(per[m][j]) for m in weights},
                )
                for j in order
            ]
        stats.candidates, stats.scored, stats.rounds = n, len(positions), 2
        stats.seconds = time.perf_counter() - start
        return matches, found.scale

    def _word_candidates(
        self,
        voters: tuple[np.ndarray, np.ndarray],
        few: tuple[np.ndarray, np.ndarray],
        count: int,
        excluded: np.ndarray,
    ) -> tuple[range, np.ndarray]:
        """A partial query's scale and its ``count`` candidates from the inverted file.

        The ``voters`` (profiles, reach: the query's samples that vote) vote at each step
        of the grid apart; each scale's best ``count / 8`` (``WORD_MIN_PROBE`` to
        ``WORD_MAX_PROBE``) are compared coarsely at it (``few``: the coarse pass's
        samples of the query, profiles and reach), the ``PROBE_LEADERS`` best of
        each at every step as well, and the scale of the best match is the query's, as
        the exhaustive pass chooses it over every shape (it can only be missed when no
        shape near that best is among the probes). Its candidates are that scale's
        ``count`` best by votes.
        """
        assert self.words is not None
        words, present = self.words, self.store.contains
        depth = min(max(WORD_MIN_PROBE, count // 8), WORD_MAX_PROBE)
        steps = range(0, scale_count(self.preset), self.preset.parts_scale_steps)
        lowest, leaders = np.full(len(steps), np.inf), []
        kept: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # the probes' best step's votes
        profiles, reach = few
        for row, j in enumerate(steps):
            voted = words.voted(*samples_at_scale(*voters, j, self.preset))
            probe = self._without(words.best(*voted, present, depth + len(excluded)), excluded)
            if len(probe):
                gallery = self.store.coarse[self.store.positions(probe)]
                scores = self._parts_scores(
                    profiles, reach, gallery, range(j, j + 1), rough=True
                ).dissimilarity
                low = scores.min()
                if low < lowest.min():
                    kept = {j: voted}
                lowest[row] = low
                leaders.append(probe[np.argsort(scores, kind="stable")[:PROBE_LEADERS]])
        probed = np.flatnonzero(np.isfinite(lowest))
        if not len(probed):  # no sample has enough radii clear of the boundary
            return range(1), np.zeros(0, dtype=np.int64)
        gallery = self.store.coarse[self.store.positions(np.unique(np.concatenate(leaders)))]
        across = scale_scores(profiles, reach, gallery, self.preset, steps, rough=True)
        j = steps[probed[np.argmin(np.minimum(lowest, across.min(axis=1))[probed])]]
        # Another step's votes are taken again: every step's kept, a million weights each,
        # would take fresh memory for every step (a tenth of the search).
        voted = kept[j] if j in kept else words.voted(*samples_at_scale(*voters, j, self.preset))
        found = words.best(*voted, present, count + len(excluded))
        return range(j, j + 1), self._without(found, excluded)

    @staticmethod
    def _without(ids: np.ndarray, excluded: np.ndarray) -> np.ndarray:
        kept: np.ndarray = ids[~np.isin(ids, excluded)]
        return kept

    def _parts_scores(
        self,
        profiles: np.ndarray,
        reach: np.ndarray,
        gallery: np.ndarray,
        scales: range | None = None,
        rough: bool = False,
    ) -> PartsMatch:
        """The parts dissimilarity of a query to ``gallery`` (float16 profiles) at the best
        of ``scales`` (default all), in blocks of ``PARTS_BLOCK_SAMPLES`` samples; ``rough``
        for a pass that shortlists (:func:`~worker.engine.parts.scale_scores`)."""
        block = max(1, PARTS_BLOCK_SAMPLES // max(gallery.shape[1], 1))
        scores = [
            scale_scores(profiles, reach, gallery[a : a + block], self.preset, scales, rough)
            for a in range(0, len(gallery), block)
        ]
        return best_scale(np.concatenate(scores, axis=1), self.preset, scales)

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
        assert self.fits is not None
        n = self.store.n
        # The certified search bounds eq. (9) by its projections: when every modality is
        # compared by it. Otherwise every candidate is scored exactly.
        d2 = all(self.preset.comparison(m) == "D2" for m in mods)
        weights = {m: self.preset.weight(m) for m in mods}
        q = {m: np.asarray(query[m], dtype=np.float64).ravel() for m in mods}
        transformed = {m: self.fits[m].transform(q[m][None, :]) for m in mods}
        if not d2:
            count = min(n, max(self.candidates, 4 * want))
            labels = [self.fits[m].index.search(transformed[m], count)[1][0] for m in mods]
            union = np.unique(np.concatenate(labels))
            positions = self.store.positions(union[union >= 0])
            fused, exact = self.exact_scores(query, positions, mods, rule)
            stats.rounds, stats.candidates, stats.certified = 1, len(positions), count >= n
            return positions, fused, exact

        sigma = self.sigma()
        rho = {m: float(np.min(self.fits[m].scale / sigma[m])) * BOUND_SAFETY for m in mods}
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
                dist, labels = self.fits[m].index.search(transformed[m], count)
                found.append(labels[0][labels[0] >= 0])
                threshold[m] = rho[m] * float(np.sqrt(max(dist[0][-1], 0.0)))
            positions = self.store.positions(np.unique(np.concatenate(found)))
            per: dict[str, np.ndarray] = {}
            for m in cheap:
                g = self.store.vectors[m][positions]
                per[m] = normalized_euclidean(q[m][None, :], g, sigma[m])[0]
            estimate, bound = dict(per), dict(per)
            for m in costly:
                diff = self.reduced[m][positions].astype(np.float64) - transformed[m][0]
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
                    g = self.store.vectors[m][positions[chunk]]
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
                return out  # best effort: recall measured in benchmarks/index.py
            count *= 4
