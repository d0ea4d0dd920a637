"""How far apart a gallery's different objects are: the yardstick of a match's closeness.

A dissimilarity means little by itself (each modality and each collection has its own
scale), so an answer also says, per modality, what share of the gallery's pairs of
*different* objects lie farther apart than the match: 1.0 is closer than every one of
them, 0.5 as close as a typical pair of different objects. The same number means the
same in every collection and for every query, with or without labels.

The pairs are drawn at random among the gallery's shapes, leaving out those that share
a label (with labels, every pair left is an impostor pair; without, nearly every random
pair is of different objects). The parts modality compares a query's samples with a
whole, so its pairs take a few whole shapes' own samples as queries (the gallery keeps a
small reservoir of them, :data:`PARTS_QUERIES`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from worker.engine.presets import PARTS

from .index import GalleryIndex

#: Pairs of different objects drawn per flat modality.
FLAT_PAIRS = 4000
#: Whole shapes kept as parts queries, and the shapes each is compared with.
PARTS_QUERIES = 16
PARTS_TARGETS = 48


@dataclass(frozen=True)
class PartsQuery:
    """A whole shape's own samples, kept to score the parts modality's pairs."""

    mesh_id: int
    profiles: np.ndarray
    reach: np.ndarray


@dataclass(frozen=True)
class Reference:
    """Sorted dissimilarities of pairs of different objects, per modality."""

    scores: dict[str, np.ndarray] = field(repr=False)
    version: int
    fitted_at: float

    def closeness(self, modality: str, value: float) -> float | None:
        """The share of the reference pairs farther apart than ``value`` (None: no pairs
        of this modality, e.g. a gallery of one shape)."""
        pairs = self.scores.get(modality)
        if pairs is None or not len(pairs):
            return None
        farther = len(pairs) - int(np.searchsorted(pairs, value, side="right"))
        return farther / len(pairs)


def fit_reference(
    index: GalleryIndex,
    labels: Mapping[int, str],
    parts_queries: Sequence[PartsQuery],
    *,
    version: int,
    seed: int = 0,
) -> Reference:
    """Score random pairs of different objects of the gallery (see the module)."""
    rng = np.random.default_rng(seed)
    ids = np.sort(index.ids())
    scores: dict[str, np.ndarray] = {}
    if len(ids) >= 2:
        first = ids[rng.integers(0, len(ids), FLAT_PAIRS)]
        second = ids[rng.integers(0, len(ids), FLAT_PAIRS)]
        keep = _different(first, second, labels)
        per = index.pair_scores(first[keep], second[keep])
        scores = {m: np.sort(v) for m, v in per.items()}
        present = [q for q in parts_queries if q.mesh_id in index]
        if present and index.store.parts_shape is not None:
            found = []
            for query in present:
                targets = ids[rng.integers(0, len(ids), PARTS_TARGETS)]
                targets = targets[_different(np.full(len(targets), query.mesh_id), targets, labels)]
                if len(targets):
                    found.append(index.parts_scores(query.profiles, query.reach, targets))
            if found:
                scores[PARTS] = np.sort(np.concatenate(found))
    return Reference(scores=scores, version=version, fitted_at=time.time())


def _different(first: np.ndarray, second: np.ndarray, labels: Mapping[int, str]) -> np.ndarray:
    """Which pairs are of two different shapes not known to be the same object."""
    same_label = np.array(
        [
            int(a) in labels and labels[int(a)] == labels.get(int(b))
            for a, b in zip(first, second, strict=True)
        ],
        dtype=bool,
    )
    result: np.ndarray = (first != second) & ~same_label
    return result
