"""The inverted file of the samples' profiles against a plain count of shared words."""

import numpy as np
import pytest

from app.gallery import words as words_module
from app.gallery.words import (
    SampleWords,
    build_words,
    largest,
    nearest_words,
    needs_vocabulary,
    unique_words,
    vocabulary_size,
)

WORDS, FILED = 32, 12  # a small vocabulary; samples filed per shape


def _words_of(rng: np.random.Generator, n: int) -> list[set[int]]:
    return [set(rng.integers(0, WORDS, size=FILED).tolist()) for _ in range(n)]


def _matrix(sets: list[set[int]]) -> np.ndarray:
    out = np.full((len(sets), FILED), -1, dtype=np.int32)
    for row, words in enumerate(sets):
        out[row, : len(words)] = sorted(words)
    return out


def _plain_votes(sets: list[set[int]], assigned: np.ndarray) -> np.ndarray:
    """tf-idf's cosine, shape by shape: the idf of each assigned word the shape has, over
    the root of the sum of its own words' squared idf."""
    n = len(sets)
    idf = {w: np.log((n + 1.0) / (sum(w in s for s in sets) + 1.0)) for w in range(WORDS)}
    out = np.zeros(n)
    for row, words in enumerate(sets):
        norm = np.sqrt(sum(idf[w] ** 2 for w in words))
        out[row] = sum(idf[int(a)] for a in assigned if int(a) in words) / norm
    return out


def test_votes_are_the_plain_tf_idf_cosine():
    rng = np.random.default_rng(0)
    sets = _words_of(rng, 50)
    centroids = rng.normal(size=(WORDS, 4))
    words = SampleWords.of_words(centroids, np.arange(100, 150), _matrix(sets))
    assigned = rng.integers(0, WORDS, size=(20, 2))
    ids, votes = words.votes(assigned)
    np.testing.assert_array_equal(ids, np.arange(100, 150))
    np.testing.assert_allclose(votes, _plain_votes(sets, assigned.ravel()), rtol=1e-12)


def test_shapes_filed_after_and_refiled_vote_as_if_filed_at_once():
    """Added shapes are weighed by the build's weights; refiling (the removed left out,
    the added in) equals filing the present shapes from scratch."""
    rng = np.random.default_rng(1)
    centroids = rng.normal(size=(WORDS, 4))
    first = _words_of(rng, 40)
    words = SampleWords.of_words(centroids, np.arange(40), _matrix(first))
    samples = rng.normal(size=(10, FILED, 4))
    for item, s in enumerate(samples, start=40):
        words.file(item, s)
    added = [set(nearest_words(centroids, s).tolist()) for s in samples]
    assigned = rng.integers(0, WORDS, size=30)
    ids, votes = words.votes(assigned)
    np.testing.assert_array_equal(ids, np.arange(50))
    # The added shapes' votes use the idf of the 40 filed at the build.
    build_idf = {w: np.log(41.0 / (sum(w in s for s in first) + 1.0)) for w in range(WORDS)}
    for row, filed in enumerate(added, start=40):
        norm = np.sqrt(sum(build_idf[w] ** 2 for w in filed))
        want = sum(build_idf[int(a)] for a in assigned if int(a) in filed) / norm
        assert votes[row] == pytest.approx(want, rel=1e-12)

    removed = {3, 17, 44}
    for item in removed:
        words.forget(item)
    present = [i for i in range(50) if i not in removed]
    refiled = words.refiled(lambda ids: ~np.isin(ids, list(removed)))
    scratch = SampleWords.of_words(
        centroids, np.array(present), _matrix([(first + added)[i] for i in present])
    )
    assert refiled.fitted == 40  # the vocabulary's, not the filing's
    ids, votes = refiled.votes(assigned)
    want_ids, want = scratch.votes(assigned)
    np.testing.assert_array_equal(ids, want_ids)
    np.testing.assert_allclose(votes, want, rtol=1e-12)


def test_samples_vote_by_their_valid_radii_only_and_the_removed_are_left_out(monkeypatch):
    monkeypatch.setattr(words_module, "ASSIGN", 1)  # the nearest word only
    centroids = np.eye(4) * 3.0
    ids = np.array([7, 8, 9, 10])
    words = SampleWords.of_words(centroids, ids, np.array([[0, -1], [1, -1], [2, -1], [3, -1]]))
    # Near word 1 on the first two radii; the last two (beyond its reach) near word 3.
    query = np.array([[0.0, 3.0, 0.0, 9.0]])
    valid = np.array([[True, True, False, False]])

    def best(valid: np.ndarray, present, count: int) -> list[int]:
        return words.best(*words.voted(query, valid), present, count).tolist()

    assert best(valid, lambda i: np.ones(len(i), bool), 1) == [8]
    assert best(np.ones_like(valid), lambda i: np.ones(len(i), bool), 1) == [10]
    # Shape 8 alone has the query's word; removed, no shape is a candidate.
    assert best(valid, lambda i: i != 8, 4) == []


def test_each_sample_is_assigned_its_nearest_words_over_its_valid_radii():
    """Samples with every count of valid radii (none: not assigned) in one call: the words
    are those of the masked distance computed sample by sample in double precision."""
    rng = np.random.default_rng(4)
    centroids = rng.normal(size=(WORDS, 6))
    words = SampleWords.of_words(centroids, np.arange(50), _matrix(_words_of(rng, 50)))
    queries = rng.normal(size=(40, 6))
    lengths = np.arange(40) % 7
    valid = np.arange(6)[None, :] < lengths[:, None]
    nearest = [
        np.argsort(((queries[i, :n] - centroids[:, :n]) ** 2).sum(axis=1))[:2]
        for i, n in enumerate(lengths)
        if n > 0
    ]
    np.testing.assert_array_equal(words._assign(queries, valid), np.stack(nearest))


def test_the_vocabulary_is_fitted_again_when_the_gallery_doubles():
    rng = np.random.default_rng(2)
    samples = rng.normal(size=(300, 8, 4)).astype(np.float32)

    words = build_words(np.arange(300), samples)
    assert words.size == vocabulary_size(300 * 8) and words.fitted == 300
    filed = unique_words(nearest_words(words.centroids, samples.reshape(-1, 4)).reshape(300, 8))
    np.testing.assert_array_equal(
        words.votes(np.arange(words.size))[1],
        SampleWords.of_words(words.centroids, np.arange(300), filed).votes(np.arange(words.size))[
            1
        ],
    )
    assert needs_vocabulary(None, 300)
    assert not needs_vocabulary(words, 599) and needs_vocabulary(words, 601)
    assert needs_vocabulary(words, 149)


@pytest.mark.parametrize("count", [1, 8, 64, 512])
def test_the_largest_votes_are_those_a_full_partition_finds(count):
    """The threshold read off a strided sample keeps exactly the largest votes, and a
    threshold that too few pass falls back to every positive vote."""
    rng = np.random.default_rng(count)
    for votes in (
        np.where(rng.random(200_000) < 0.6, rng.gamma(2.0, 1.0, 200_000), 0.0),
        np.concatenate([np.zeros(199_000), rng.random(1_000)]),  # most shapes unvoted
        np.where(np.arange(200_000) % 997 == 0, 1.0, 0.0),  # a few voted, all tied
    ):
        found = largest(votes, count)
        positive = np.flatnonzero(votes > 0)
        plain = positive[np.argsort(-votes[positive], kind="stable")][:count]
        assert len(found) == len(plain)
        np.testing.assert_array_equal(np.sort(votes[found]), np.sort(votes[plain]))
