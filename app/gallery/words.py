"""An inverted file of the gallery's sample profiles: the partial search's first pass.

A partial query is a handful of local features (its samples' geodesic-ball area
profiles, :mod:`worker.engine.parts`), and a gallery shape contains it when it has
samples like them. Comparing every query sample with every shape's samples costs the
gallery's size; image retrieval answers the same question at scale with a vocabulary
of local features and an inverted file (Sivic and Zisserman 2003, "Video Google"; for
shapes, Bronstein et al. 2011, "Shape Google"). Here:

* the vocabulary is ``k``-means of the gallery's sample profiles (``WORD_SAMPLES`` of
  each shape: its first ones, spread over its surface by the farthest-point order,
  the samples the coarse pass compares too);
* each shape is filed under the words of those samples (each word once);
* a query sample, at a scale the parts search tries, is assigned its ``ASSIGN``
  nearest words by the radii within its reach (a masked distance: the profile's other
  radii cross the query's boundary), and every shape filed under them gets the word's
  weight, its inverse document frequency (a rare profile says more);
* the shapes with the most weight are the candidates the exact passes score. The
  search votes at each scale apart and takes its candidates at the query's scale
  (:meth:`app.gallery.index.GalleryIndex.partial_search`): at the wrong scales a
  query's samples look like other shapes' samples, and their votes would drown the
  right scale's.

Shapes are filed by id. The inverted file is kept as arrays, made at once for the shapes
there are (:func:`build_words`, at the index's whole refit); a shape added after is held
apart (its words, weighed with the build's weights), one removed is left out of the
answers. The index's next whole refit files them all again with the same vocabulary
(:meth:`SampleWords.refiled`, no profile read), and fits a new vocabulary when the gallery
has doubled since the last (:func:`needs_vocabulary`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import faiss
import numpy as np

from worker.engine.parts import COARSE_SAMPLES

#: Samples of each gallery shape filed: its first ones, those the coarse pass compares.
WORD_SAMPLES = COARSE_SAMPLES
#: Nearest words a query sample is assigned at each scale.
ASSIGN = 2
#: Words in the vocabulary: about one per ``SAMPLES_PER_WORD`` filed samples, a power of
#: two from ``MIN_WORDS`` to ``MAX_WORDS`` (a shape's 64 samples take about 1% of the
#: words of a large gallery: fewer words and every shape has most of them).
SAMPLES_PER_WORD = 16
MIN_WORDS = 16
MAX_WORDS = 8192
#: Profiles the vocabulary is fitted on, at most (a seeded sample above), and the
#: ``k``-means iterations.
FIT_PROFILES = 100_000
FIT_ITERATIONS = 12
#: Shapes filed per block of the nearest-word search.
FILE_BLOCK = 256
#: :func:`largest`'s threshold: this deep in a strided sample of the values.
THRESHOLD_DEPTH = 16


class SampleWords:
    """The vocabulary and the inverted file (see the module docstring).

    Parameters
    ----------
    centroids : (V, K) the words.
    ids : (n,) int64, the shapes filed at the build.
    slots : (E,) int32, the inverted file: the filed shapes' slots (in ``ids``), word by
        word, each shape once under each of its words.
    bounds : (V + 1,) word ``w``'s entries are ``slots[bounds[w]:bounds[w + 1]]``.
    added : id -> words of the shapes filed since.
    fitted : shapes the vocabulary was fitted on (default ``len(ids)``).

    A word's weight is its inverse document frequency at the build,
    ``log((n + 1) / (n_w + 1))`` for ``n_w`` of the ``n`` shapes filed under it, and a
    shape's norm the root of the sum of its words' squared weights: tf-idf's cosine, so
    that a shape filed under many words does not win for that alone. Both stay fixed
    until the next build (a shape added since is weighed by them too).
    """

    def __init__(
        self,
        centroids: np.ndarray,
        ids: np.ndarray,
        slots: np.ndarray,
        bounds: np.ndarray,
        added: dict[int, np.ndarray] | None = None,
        fitted: int | None = None,
    ) -> None:
        self.fitted = len(ids) if fitted is None else fitted
        self.centroids = np.ascontiguousarray(centroids, dtype=np.float32)
        self._cumulative: np.ndarray | None = None  # (K, V) the words' cumulative squares
        self.ids = np.asarray(ids, dtype=np.int64)
        self.slots = np.asarray(slots, dtype=np.int32)
        self.bounds = np.asarray(bounds, dtype=np.int64)
        counts = np.diff(self.bounds)
        self.idf = np.log((len(self.ids) + 1.0) / (counts + 1.0))
        entry_words = np.repeat(np.arange(self.size, dtype=np.int32), counts)
        squares = np.bincount(self.slots, (self.idf**2)[entry_words], minlength=len(self.ids))
        self.norms = np.sqrt(np.maximum(squares, 1e-12))
        self.added: dict[int, np.ndarray] = dict(added or {})
        self._added: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @classmethod
    def of_words(cls, centroids: np.ndarray, ids: np.ndarray, words: np.ndarray) -> SampleWords:
        """File shapes by their (n, s) words (each once, -1 after the last)."""
        filed = words.ravel()
        keep = filed >= 0
        slots = np.repeat(np.arange(len(ids), dtype=np.int32), words.shape[1])[keep]
        order = np.argsort(filed[keep], kind="stable")
        bounds = np.searchsorted(filed[keep][order], np.arange(len(centroids) + 1))
        return cls(centroids, ids, slots[order], bounds)

    @property
    def size(self) -> int:
        return len(self.centroids)

    @property
    def nbytes(self) -> int:
        """Memory of the inverted file (the words' and the added shapes' are small)."""
        return int(self.slots.nbytes + self.ids.nbytes + self.bounds.nbytes + self.norms.nbytes)

    def arrays(self) -> dict[str, np.ndarray]:
        """What :meth:`from_arrays` restores (the saved index keeps it)."""
        ids, words, lengths = self._added_arrays()
        return {
            "centroids": self.centroids,
            "ids": self.ids,
            "slots": self.slots,
            "bounds": self.bounds,
            "added_ids": ids,
            "added_lengths": lengths,
            "added_words": words,
            "fitted": np.array([self.fitted], dtype=np.int64),
        }

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> SampleWords:
        ends = np.cumsum(arrays["added_lengths"])
        added = {
            int(item): arrays["added_words"][end - length : end].astype(np.int32)
            for item, length, end in zip(
                arrays["added_ids"], arrays["added_lengths"], ends, strict=True
            )
        }
        return cls(
            arrays["centroids"],
            arrays["ids"],
            arrays["slots"],
            arrays["bounds"],
            added,
            int(arrays["fitted"][0]),
        )

    def file(self, item: int, samples: np.ndarray) -> None:
        """File a shape added after the build ((s, K) its samples)."""
        words = unique_words(nearest_words(self.centroids, samples[:WORD_SAMPLES]))
        self.added[item] = words[words >= 0]
        self._added = None

    def forget(self, item: int) -> None:
        """A removed shape (one filed at the build is left out of answers instead)."""
        if self.added.pop(item, None) is not None:
            self._added = None

    def refiled(self, present: Callable[[np.ndarray], np.ndarray]) -> SampleWords:
        """The same vocabulary with every present shape filed at once: those filed at the
        build that are still there (``present``) and those added since, the weights
        counted again. No profile is read: a shape's words are where it was filed."""
        counts = np.diff(self.bounds)
        entry_words = np.repeat(np.arange(self.size, dtype=np.int32), counts)
        kept = present(self.ids)
        new_slot = np.cumsum(kept) - 1
        keep = kept[self.slots]
        added_ids, added_words, lengths = self._added_arrays()
        words = np.concatenate([entry_words[keep], added_words])
        slots = np.concatenate(
            [
                new_slot[self.slots[keep]],
                int(kept.sum()) + np.repeat(np.arange(len(added_ids)), lengths),
            ]
        ).astype(np.int32)
        order = np.argsort(words, kind="stable")
        bounds = np.searchsorted(words[order], np.arange(self.size + 1))
        ids = np.concatenate([self.ids[kept], added_ids])
        return SampleWords(self.centroids, ids, slots[order], bounds, fitted=self.fitted)

    def voted(self, queries: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every filed shape's ids and weight (:meth:`votes`) for query vectors.

        Parameters
        ----------
        queries : (q, K) query vectors: a sample at a scale, the profile's columns that
            scale compares with the gallery's radii.
        valid : (q, K) bool, the radii within the sample's reach.
        """
        if not len(queries):
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        return self.votes(self._assign(np.asarray(queries, dtype=np.float64), valid))

    @staticmethod
    def best(
        ids: np.ndarray,
        votes: np.ndarray,
        present: Callable[[np.ndarray], np.ndarray],
        count: int,
    ) -> np.ndarray:
        """Of :meth:`voted`'s shapes, the ids of the ``count`` with the most weight, most
        first (fewer if fewer are filed), those not ``present`` left out (looked up for
        the best few only)."""
        voted = largest(votes, 2 * count)
        best: np.ndarray = ids[voted[np.argsort(-votes[voted], kind="stable")]]
        kept: np.ndarray = best[present(best)][:count]
        return kept

    def votes(self, assigned: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every filed shape's ids and weight for query vectors assigned to words
        ``assigned`` (any shape of ints): the sum over them of the word's weight if the
        shape is filed under it, over the shape's norm."""
        assigned = np.asarray(assigned, dtype=np.int64).ravel()
        # Each word's weight times the query vectors assigned to it, given to every shape
        # filed under it: the entries of the words assigned, one slice of the inverted
        # file each (a query's 128 words, but about 400,000 entries at a million shapes).
        per_word = np.bincount(assigned, minlength=self.size) * self.idf
        used = np.flatnonzero(per_word)
        starts, ends = self.bounds[used], self.bounds[used + 1]
        slots = np.concatenate(
            [self.slots[a:b] for a, b in zip(starts.tolist(), ends.tolist(), strict=True)]
            + [np.zeros(0, dtype=np.int32)]
        )
        weights = np.repeat(per_word[used], ends - starts)
        votes = np.bincount(slots, weights, minlength=len(self.ids)).astype(float, copy=False)
        np.divide(votes, self.norms, out=votes)
        ids = self.ids
        if self.added:
            added_ids, added_words, lengths = self._added_arrays()
            slots = np.repeat(np.arange(len(added_ids)), lengths)
            weight = np.bincount(slots, per_word[added_words], minlength=len(added_ids))
            norms = np.bincount(slots, self.idf[added_words] ** 2, minlength=len(added_ids))
            ids = np.concatenate([ids, added_ids])
            votes = np.concatenate([votes, weight / np.sqrt(np.maximum(norms, 1e-12))])
        return ids, votes

    def _added_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The added shapes as arrays (kept until one is added or forgotten): ids, their
        words one after another, how many each."""
        if self._added is None:
            lengths = np.array([len(w) for w in self.added.values()], dtype=np.int64)
            self._added = (
                np.fromiter(self.added, dtype=np.int64, count=len(self.added)),
                np.concatenate([*self.added.values(), np.zeros(0, np.int32)]).astype(np.int32),
                lengths,
            )
        return self._added

    def _assign(self, queries: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """(q, ASSIGN) each query vector's nearest words over its valid radii only.

        A sample's valid radii are its first ones (those within its reach), ``L`` of them:
        the squared distance over them is ``|q|^2 - 2 q.c + sum_{k<L} c_k^2``. With the
        radii past ``L`` set to 0, ``q.c`` is one matrix product for every vector, and each
        adds the words' sums of squares for its ``L`` (single precision: a near tie between
        two words goes either way, and both are assigned)."""
        if self._cumulative is None:
            self._cumulative = np.cumsum(self.centroids**2, axis=1).T.copy()  # (K, V)
        lengths = valid.sum(axis=1)
        rows = np.flatnonzero(lengths > 0)
        k = min(ASSIGN, self.size)
        heads = np.where(valid[rows], queries[rows], 0.0).astype(np.float32)
        distances = heads @ self.centroids.T
        distances *= -2.0
        distances += self._cumulative[lengths[rows] - 1]
        nearest = np.empty((len(rows), k), dtype=np.int64)
        within = np.arange(len(rows))
        for column in range(k):  # the k smallest, one argmin at a time
            found = distances.argmin(axis=1)
            nearest[:, column] = found
            distances[within, found] = np.inf
        return nearest


def largest(values: np.ndarray, count: int) -> np.ndarray:
    """The positions of the ``count`` largest positive ``values`` (every positive one if
    fewer), in no order.

    In a large array, the ``THRESHOLD_DEPTH``-th largest of every ``count / 4``-th value is
    a threshold that about ``4 count`` values pass, and only those are partitioned: the
    same positions as partitioning every value (a tenth of its time for a million votes),
    which is done when fewer than ``count`` pass.
    """
    stride = count // 4
    if stride > 1 and len(values) > 64 * count:
        sample = values[::stride]
        threshold = np.partition(sample, len(sample) - THRESHOLD_DEPTH)[-THRESHOLD_DEPTH]
        if threshold > 0:
            above = np.flatnonzero(values >= threshold)
            if len(above) >= count:
                top: np.ndarray = above[np.argpartition(-values[above], count - 1)[:count]]
                return top
    positive = np.flatnonzero(values > 0)
    if len(positive) > count:
        positive = positive[np.argpartition(-values[positive], count - 1)[:count]]
    return positive


def build_words(ids: np.ndarray, samples: np.ndarray, seed: int = 0) -> SampleWords:
    """Fit the vocabulary on the shapes' samples (a seeded sample of at most
    ``FIT_PROFILES``, faiss's ``k``-means) and file them all.

    Parameters
    ----------
    ids : (n,) the shapes' ids.
    samples : (n, s, K) their profiles (only the first ``WORD_SAMPLES`` are read, in
        blocks of ``FILE_BLOCK`` shapes).
    """
    n = len(ids)
    per_shape = min(WORD_SAMPLES, samples.shape[1])
    rng = np.random.default_rng(seed)
    take = min(n * per_shape, FIT_PROFILES)
    chosen = np.sort(rng.choice(n * per_shape, size=take, replace=False))
    fit = np.ascontiguousarray(samples[chosen // per_shape, chosen % per_shape], np.float32)
    size = min(vocabulary_size(n * per_shape), max(1, len(fit)))
    kmeans = faiss.Kmeans(fit.shape[1], size, niter=FIT_ITERATIONS, seed=seed, verbose=False)
    kmeans.train(fit)
    assert kmeans.centroids is not None  # trained
    centroids = np.asarray(kmeans.centroids)
    words = np.full((n, WORD_SAMPLES), -1, dtype=np.int32)
    for start in range(0, n, FILE_BLOCK):
        block = np.asarray(samples[start : start + FILE_BLOCK, :per_shape], dtype=np.float32)
        filed = nearest_words(centroids, block.reshape(-1, block.shape[-1]))
        words[start : start + len(block), :per_shape] = unique_words(
            filed.reshape(len(block), per_shape)
        )
    return SampleWords.of_words(centroids, ids, words)


def vocabulary_size(n_samples: int) -> int:
    """Words for ``n_samples`` filed samples (see ``SAMPLES_PER_WORD``)."""
    target = max(MIN_WORDS, n_samples // SAMPLES_PER_WORD)
    return int(min(MAX_WORDS, 2 ** int(np.ceil(np.log2(target)))))


def nearest_words(centroids: np.ndarray, profiles: np.ndarray) -> np.ndarray:
    """The nearest word of each of (s, K) full profiles (faiss's exact search: by one
    matrix product for a block of profiles, about 9 us a profile for 8,192 words)."""
    flat = faiss.IndexFlatL2(centroids.shape[1])
    flat.add(np.ascontiguousarray(centroids, dtype=np.float32))
    _, found = flat.search(np.ascontiguousarray(profiles, dtype=np.float32), 1)
    nearest: np.ndarray = found[:, 0].astype(np.int32)
    return nearest


def unique_words(words: np.ndarray) -> np.ndarray:
    """Each row's words once, ascending, -1 after them ((..., s) int)."""
    ordered = np.sort(np.asarray(words, dtype=np.int32), axis=-1)
    repeated = np.zeros(ordered.shape, dtype=bool)
    repeated[..., 1:] = ordered[..., 1:] == ordered[..., :-1]
    ordered = np.where(repeated, np.iinfo(np.int32).max, ordered)
    ordered = np.sort(ordered, axis=-1)
    result: np.ndarray = np.where(ordered == np.iinfo(np.int32).max, -1, ordered)
    return result


def needs_vocabulary(words: SampleWords | None, shapes: int) -> bool:
    """Whether a gallery of ``shapes`` wants a vocabulary fitted anew: none yet, or the
    gallery has doubled or halved since it was fitted (and so wants twice or half the
    words, up to ``MAX_WORDS``, and its profiles may have moved)."""
    if words is None:
        return True
    return not words.fitted / 2 <= shapes <= 2 * words.fitted
