"""The gallery index against the exhaustive ranking of ``worker.engine.compare`` (no server)."""

from __future__ import annotations

import faiss
import numpy as np
import pytest

import app.gallery.index as index_module
from app.gallery.index import PARTS_SHORTLIST, GalleryIndex, SearchStats
from app.gallery.persistence import load_index, save_index
from worker.engine.compare import (
    dissimilarity,
    fuse,
    fused_dissimilarity,
    gallery_sigma,
    query_weights,
)
from worker.engine.parts import (
    COARSE_SAMPLES,
    area_profiles,
    coarse,
    compared_profiles,
    grid_radii,
    part_dissimilarity,
    samples_at_scale,
    scale_count,
    scale_scores,
    sized_dissimilarity,
    sized_scales,
    with_centroids,
)
from worker.engine.presets import (
    DEFAULT_PRESET,
    MODALITIES,
    PARTS,
    REWEIGHTED,
    SIZE,
    get_preset,
    with_fusion,
    with_units,
)

SHREC = get_preset("smeets2010-shrec")  # D2, product rule
TOSCA = get_preset("smeets2010-tosca")  # D1, sum rule


def _gallery(n: int, seed: int = 0, preset=SHREC) -> dict[str, np.ndarray]:
    """Positive descriptors with class structure, shaped like the real ones."""
    rng = np.random.default_rng(seed)
    dims = preset.modality_sizes()
    classes = rng.integers(0, max(n // 8, 1), size=n)
    out = {}
    for m, d in dims.items():
        centres = rng.normal(size=(max(n // 8, 1), d)) + np.linspace(3, -3, d)
        out[m] = np.exp(centres[classes] + 0.3 * rng.normal(size=(n, d)))
    return out


def _exhaustive(preset, gallery, query, k, exclude=()):
    per = {}
    for m in preset.fused_modalities:
        per[m] = dissimilarity(query[m][None], gallery[m], preset.dissimilarity)[0]
    fused = fuse(per, preset.fusion, {m: preset.weight(m) for m in preset.fused_modalities})
    order = [int(i) for i in np.lexsort((np.arange(len(fused)), fused)) if i not in exclude]
    return order[:k], fused


def _index(preset, gallery, **options) -> GalleryIndex:
    index = GalleryIndex(preset, preset.modality_sizes(), **options)
    n = len(gallery["gdm"])
    index.add_many((i, {m: gallery[m][i] for m in MODALITIES}) for i in range(n))
    return index


@pytest.mark.parametrize("preset", [SHREC, TOSCA], ids=["D2-product", "D1-sum"])
def test_top_k_equals_the_exhaustive_ranking(preset):
    gallery = _gallery(600)
    # Small candidate counts, so the candidate path (not a full scan) is exercised.
    index = _index(preset, gallery, candidates=64, max_candidates=256, max_scored=64)
    rng = np.random.default_rng(1)
    for i in rng.choice(600, size=20, replace=False):
        query = {
            m: gallery[m][i] * np.exp(0.05 * rng.normal(size=gallery[m].shape[1]))
            for m in MODALITIES
        }
        expected, fused = _exhaustive(preset, gallery, query, 10)
        found = index.search(query, 10)
        assert [m.id for m in found] == expected
        np.testing.assert_allclose([m.score for m in found], fused[expected], rtol=1e-9)


@pytest.mark.slow  # many refits and exhaustive rankings
def test_certified_searches_are_exact_and_sigma_is_the_current_gallerys():
    gallery = _gallery(300)
    index = _index(SHREC, gallery)
    for m in MODALITIES:
        np.testing.assert_allclose(index.sigma()[m], gallery_sigma(gallery[m]), rtol=1e-9)
    stats = SearchStats()
    query = {m: gallery[m][7] for m in MODALITIES}
    found = index.search(query, 5, exclude=(7,), stats=stats)
    expected, _ = _exhaustive(SHREC, gallery, query, 5, exclude=(7,))
    assert stats.certified and [m.id for m in found] == expected


@pytest.mark.slow  # many refits and exhaustive rankings
def test_adds_and_deletes_keep_sigma_and_results_current():
    gallery = _gallery(400)
    index = _index(SHREC, {m: v[:300] for m, v in gallery.items()})
    for i in range(300, 400):  # past the refit fraction: refits happen on the way
        index.add(i, {m: gallery[m][i] for m in MODALITIES})
    removed = list(range(0, 400, 7))
    for i in removed:
        assert index.remove(i)
    assert not index.remove(removed[0])
    keep = [i for i in range(400) if i not in removed]
    current = {m: v[keep] for m, v in gallery.items()}
    for m in MODALITIES:
        np.testing.assert_allclose(index.sigma()[m], gallery_sigma(current[m]), rtol=1e-8)
    assert index.refits > 1
    # Which ids are enrolled, as the partial search asks (past the largest id too).
    asked = np.array([0, 1, 7, 398, 399, 400, 10**6])
    assert index.store.contains(asked).tolist() == [int(i) in keep for i in asked]
    query = {m: gallery[m][0] for m in MODALITIES}  # a deleted shape as the query
    expected, _ = _exhaustive(SHREC, current, query, 10)
    assert [m.id for m in index.search(query, 10)] == [keep[i] for i in expected]


def test_save_load_roundtrip_and_corrupt_files_are_refused(tmp_path):
    gallery = _gallery(200)
    index = _index(SHREC, gallery)
    save_index(index, tmp_path / "idx")
    loaded = load_index(tmp_path / "idx", SHREC)
    assert loaded.fingerprint() == index.fingerprint() and len(loaded) == 200
    query = {m: gallery[m][3] for m in MODALITIES}
    assert [m.id for m in loaded.search(query, 10)] == [m.id for m in index.search(query, 10)]

    (tmp_path / "idx" / "ddt.faiss").write_bytes(b"garbage")
    with pytest.raises(ValueError):
        load_index(tmp_path / "idx", SHREC)
    with pytest.raises(ValueError):
        load_index(tmp_path / "missing", SHREC)
    save_index(index, tmp_path / "idx")
    with pytest.raises(ValueError):  # made for another preset
        load_index(tmp_path / "idx", TOSCA)


def test_empty_and_tiny_galleries():
    index = GalleryIndex(SHREC, SHREC.modality_sizes())
    query = {m: np.ones(d) for m, d in SHREC.modality_sizes().items()}
    assert index.search(query, 5) == []
    index.add(42, query)
    (only,) = index.search(query, 5)
    assert only.id == 42 and only.score == 0.0
    assert index.search(query, 5, exclude=(42,)) == []


def test_large_galleries_use_an_inverted_file_that_finds_deletes_and_reloads(tmp_path, monkeypatch):
    from app.gallery import candidates

    # A "large" gallery of 2,000 shapes: 20 cells, 8 probed per search.
    monkeypatch.setattr(candidates, "IVF_MIN_SHAPES", 1_000)
    monkeypatch.setattr(candidates, "IVF_SHAPES_PER_CELL", 100)
    monkeypatch.setattr(candidates, "IVF_PROBES", 8)
    preset = get_preset("smeets2010-surface")  # the default: D1, product rule
    gallery = _gallery(2_000, preset=preset)
    index = _index(preset, gallery, candidates=200)
    ivf = faiss.try_extract_index_ivf(index.fits["gdm"].index)
    assert ivf is not None and ivf.nlist == 20 and ivf.nprobe == 8

    rng = np.random.default_rng(2)
    queries = []
    for i in rng.choice(2_000, size=20, replace=False):
        noise = {m: np.exp(0.05 * rng.normal(size=gallery[m].shape[1])) for m in MODALITIES}
        queries.append({m: gallery[m][i] * noise[m] for m in MODALITIES})
    hits = 0
    for query in queries:
        expected, fused = _exhaustive(preset, gallery, query, 10)
        found = index.search(query, 10)
        hits += len({m.id for m in found} & set(expected))
        for match in found:  # whatever is returned carries its exact fused score
            assert match.score == pytest.approx(fused[match.id], rel=1e-9)
    assert hits / (10 * len(queries)) >= 0.95

    removed = [m.id for m in index.search(queries[0], 5)]
    for i in removed:
        assert index.remove(i)
    assert not {m.id for m in index.search(queries[0], 10)} & set(removed)

    save_index(index, tmp_path / "idx")
    loaded = load_index(tmp_path / "idx", preset)
    assert faiss.try_extract_index_ivf(loaded.fits["gdm"].index).nprobe == 8
    for query in queries[:5]:
        assert [m.id for m in loaded.search(query, 10)] == [m.id for m in index.search(query, 10)]


DEFAULT = get_preset(DEFAULT_PRESET)  # D1, product rule, with the parts modality


def _parts_gallery(n: int, seed: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Flat vectors and whole-surface parts profiles (n, m, 2C) for the default preset:
    smooth falling area profiles and rising centroid profiles, as a surface's."""
    rng = np.random.default_rng(seed)
    samples, columns = DEFAULT.gdm_samples, len(grid_radii(DEFAULT))
    areas = -np.cumsum(rng.uniform(0.0, 0.3, size=(n, samples, columns)), axis=2)
    centroids = np.cumsum(rng.uniform(0.0, 0.05, size=(n, samples, columns)), axis=2)
    return _gallery(n, seed, DEFAULT), with_centroids(areas, centroids)


def _shifted(profiles: np.ndarray, columns: float) -> np.ndarray:
    """A part's (m, 2C) profiles whose radii grow by ``2^(columns / 8)`` against its
    whole's ``profiles``: column ``c`` of each kind is the whole's ``c - columns``, linear
    between two (the first ones: the whole's first)."""
    width = len(grid_radii(DEFAULT))
    at = np.arange(width) - columns
    return np.concatenate(
        [
            np.stack([np.interp(at, np.arange(width), row) for row in kind])
            for kind in (profiles[:, :width], profiles[:, width:])
        ],
        axis=1,
    )


@pytest.mark.parametrize("n", [6, 90], ids=["all-shortlisted", "coarse-first"])
def test_a_partial_search_ranks_as_the_exhaustive_product(n):
    """With the parts at the query's weights: the exhaustive product of the flat D1 and
    the parts dissimilarity (scale chosen over all shapes) when every shape is
    shortlisted; the query's own source first when a coarse pass shortlists."""
    vectors, profiles = _parts_gallery(n, seed=4)
    index = GalleryIndex(DEFAULT, DEFAULT.modality_sizes(), parts_shape=DEFAULT.parts_shape())
    index.add_many(
        (
            i,
            {
                **{m: vectors[m][i] for m in MODALITIES},
                PARTS: compared_profiles(profiles[i], DEFAULT),
            },
        )
        for i in range(n)
    )
    source = 3
    part = profiles[source, :200].astype(np.float16).astype(np.float64)  # 200 of its samples
    reach = np.full(200, np.inf)
    weights = query_weights(DEFAULT, 0.5)
    query = {m: vectors[m][source] for m in MODALITIES}
    found, scale = index.partial_search(query, part, reach, weights, 3, exclude=[5])
    assert found[0].id == source and scale == 1.0
    assert [set(m.scores) for m in found] == [set(weights)] * 3
    if n <= PARTS_SHORTLIST:
        whole = compared_profiles(profiles, DEFAULT).astype(np.float16).astype(np.float64)
        per = {m: dissimilarity(query[m][None], vectors[m], "D1")[0] for m in weights if m != PARTS}
        per[PARTS] = part_dissimilarity(part, reach, whole, DEFAULT).dissimilarity
        fused = fuse(per, "product", weights)
        expected = [i for i in np.argsort(fused, kind="stable") if i != 5][:3]
        assert [m.id for m in found] == expected
        np.testing.assert_allclose([m.score for m in found], fused[expected], rtol=1e-9)


def test_a_partial_search_of_a_metric_collection_scores_each_shape_at_its_size():
    """``sized``: the shortlist's parts at the scales each shape's size and the query's
    imply, as :func:`~worker.engine.parts.sized_dissimilarity` scores every shape, and
    the size among the flat modalities (the exhaustive product, every shape
    shortlisted); the source, the size a part of 59% of its area implies, comes first
    before an equal copy of it 19% larger; a shape with under half the query's area
    (size 0.5 against 0.77) is none, one a little smaller (0.7) is compared as a whole."""
    preset = with_units(DEFAULT, "metric")
    n = 6
    vectors, profiles = _parts_gallery(n, seed=4)
    profiles[4] = profiles[3]  # shape 4: shape 3 at another size
    vectors[SIZE] = np.array([[1.3], [0.5], [1.1], [1.0], [2.0 ** (2 / 8)], [0.7]])
    index = GalleryIndex(preset, preset.modality_sizes(), parts_shape=preset.parts_shape())
    index.add_many(
        (i, {**{m: vectors[m][i] for m in vectors}, PARTS: compared_profiles(profiles[i], preset)})
        for i in range(n)
    )
    source = 3
    part = _shifted(profiles[source, :200], 3).astype(np.float16).astype(np.float64)
    reach = np.full(200, np.inf)
    weights = query_weights(preset, 1.0)
    query = {m: vectors[m][source] for m in MODALITIES}
    query[SIZE] = np.array([2.0 ** (-3 / 8)])
    found, scale = index.partial_search(query, part, reach, weights, 6, sized=True)
    whole = compared_profiles(profiles, preset).astype(np.float16).astype(np.float64)
    per = {m: dissimilarity(query[m][None], vectors[m], "D1")[0] for m in weights if m != PARTS}
    centres = sized_scales(2.0 ** (-3 / 8), vectors[SIZE][:, 0], preset)
    per[PARTS] = sized_dissimilarity(part, reach, whole, preset, centres).dissimilarity
    fused = fuse(per, "product", weights)
    assert fused[1] == np.inf and np.isfinite(np.delete(fused, 1)).all()
    expected = [int(i) for i in np.argsort(fused, kind="stable")[:5]]
    assert [m.id for m in found] == expected and expected[0] == source
    np.testing.assert_allclose([m.score for m in found], fused[expected], rtol=1e-9)
    assert scale == 2.0 ** (3 / 8)
    unsized, _ = index.partial_search(query, part, reach, weights, 3)
    assert {m.id for m in unsized[:2]} == {3, 4}


def test_a_metric_partial_search_shortlists_only_shapes_that_can_hold_the_query():
    """More shapes than the shortlist holds hold the query's profiles exactly, the source
    (the last) only nearly; but they are too small to hold it, and the shortlist leaves
    them out, so the source is found."""
    preset = with_units(DEFAULT, "metric")
    n = PARTS_SHORTLIST + 8
    vectors, profiles = _parts_gallery(n, seed=5)
    exact = profiles[0].copy()
    profiles[:] = exact
    profiles[n - 1] += np.random.default_rng(0).normal(scale=0.02, size=exact.shape)
    for m in MODALITIES:
        vectors[m][:] = vectors[m][0]
    vectors[SIZE] = np.where(np.arange(n) < n - 1, 0.5, 1.0)[:, None]
    index = GalleryIndex(preset, preset.modality_sizes(), parts_shape=preset.parts_shape())
    index.add_many(
        (i, {**{m: vectors[m][i] for m in vectors}, PARTS: compared_profiles(profiles[i], preset)})
        for i in range(n)
    )
    part = _shifted(exact[:200], 3)
    query = {m: vectors[m][n - 1] for m in MODALITIES}
    query[SIZE] = np.array([2.0 ** (-3 / 8)])
    weights = query_weights(preset, 1.0)
    found, _ = index.partial_search(query, part, np.full(200, np.inf), weights, 5, sized=True)
    assert [m.id for m in found] == [n - 1]


@pytest.mark.parametrize("in_file", [False, True], ids=["in memory", "in a file"])
def test_parts_profiles_are_saved_and_loaded(tmp_path, in_file):
    """Every sample's profiles, kept in memory or in a file beside the saved index (read
    row by row; a removed shape's slot is not reused, so a saved index's rows never
    change), and the coarse rows (the first samples' area profiles) by position."""
    vectors, profiles = _parts_gallery(5, seed=2)
    path = tmp_path / "index.parts" if in_file else None
    index = GalleryIndex(
        DEFAULT, DEFAULT.modality_sizes(), parts_shape=DEFAULT.parts_shape(), parts_path=path
    )
    for i in range(5):
        compared = compared_profiles(profiles[i], DEFAULT)
        index.add(10 + i, {**{m: vectors[m][i] for m in MODALITIES}, PARTS: compared})
    index.remove(11)  # the last row moves into its place, its profiles with it
    save_index(index, tmp_path / "index")
    loaded = load_index(tmp_path / "index", DEFAULT)
    assert loaded.store.parts_shape == DEFAULT.parts_shape()
    assert (loaded.store.rows.path is not None) == in_file
    for item in (10, 12, 13, 14):
        want = compared_profiles(profiles[item - 10], DEFAULT).astype(np.float16)
        position = loaded.store.pos[item]
        np.testing.assert_array_equal(loaded.store.parts_at(np.array([position]))[0], want)
        coarse_rows = want[:COARSE_SAMPLES, : DEFAULT.parts_radii]  # their areas alone
        np.testing.assert_array_equal(loaded.store.coarse[position], coarse_rows)
    if in_file:  # rows added after the save go after the saved ones
        loaded.add(20, {**{m: vectors[m][0] for m in MODALITIES}, PARTS: compared})
        assert loaded.store.slots[loaded.store.pos[20]] == 5


@pytest.mark.parametrize("name", ["smeets2010-shrec", DEFAULT_PRESET], ids=["D2", "D1"])
def test_a_metric_collection_ranks_by_shape_and_size_as_the_engine_does(name):
    """With units "metric" the index scores the size with the shape (the engine's
    ``fused_dissimilarity``, the reference), on its candidate path or, for D2, whole."""
    preset = with_units(get_preset(name), "metric")
    gallery = _gallery(400, preset=preset)
    rng = np.random.default_rng(2)
    gallery[SIZE] = rng.uniform(0.5, 2.0, size=(400, 1))  # sizes of similar shapes
    index = GalleryIndex(preset, preset.modality_sizes(), candidates=64, max_candidates=256)
    index.add_many((i, {m: gallery[m][i] for m in preset.modality_sizes()}) for i in range(400))
    assert index.modalities[-1] == SIZE
    for i in rng.choice(400, size=10, replace=False):
        query = {m: gallery[m][i] * 1.01 for m in preset.modality_sizes()}
        fused = fused_dissimilarity(
            {m: v[None] for m, v in query.items()}, gallery, preset, index.sigma()
        )[0]
        expected = [int(j) for j in np.lexsort((np.arange(400), fused))[:10]]
        found = index.search(query, 10)
        assert [m.id for m in found] == expected
        assert all(set(m.scores) == set(preset.scored_modalities) for m in found)
        np.testing.assert_allclose([m.score for m in found], fused[expected], rtol=1e-9)


#: The default preset as a fusion learned on a collection might leave it: the DDT by eq.
#: (9), the spectrum by ShapeDNA's comparison, the GDM by the preset's eq. (8).
LEARNED = with_fusion(
    get_preset(DEFAULT_PRESET),
    {"gdm": 0.25, "ddt": 0.5, "spectrum": 1.0},
    {"ddt": "D2", "spectrum": REWEIGHTED},
)


def _ranking(preset, gallery, query, k=10):
    """The engine's fused score of the whole gallery (the reference) and its top k."""
    fused = fused_dissimilarity(
        {m: v[None] for m, v in query.items()},
        gallery,
        preset,
        {m: gallery_sigma(v) for m, v in gallery.items()},
    )[0]
    return [int(j) for j in np.lexsort((np.arange(len(fused)), fused))[:k]], fused


def test_each_modality_is_ranked_by_its_own_comparison():
    """A preset whose modalities compare by D1, D2 and ShapeDNA's comparison ranks as the
    engine's fused score, on the candidate path; switching the comparisons (a learned
    fusion adopted, then dropped) refits only the modalities whose comparison changed."""
    base = get_preset(DEFAULT_PRESET)
    gallery = _gallery(500, preset=base)
    index = _index(base, gallery, candidates=64, max_candidates=256)
    rng = np.random.default_rng(4)
    queries = [
        {m: gallery[m][i] * np.exp(0.05 * rng.normal(size=gallery[m].shape[1])) for m in MODALITIES}
        for i in rng.choice(500, size=10, replace=False)
    ]
    before = {m: index.fits[m] for m in MODALITIES}
    for preset in (LEARNED, base):
        index.compare_with(preset)
        assert index.preset is preset
        for m in MODALITIES:  # the GDM's comparison is the same in both
            assert (index.fits[m] is before[m]) == (m == "gdm"), m
        for query in queries:
            expected, fused = _ranking(preset, gallery, query)
            found = index.search(query, 10)
            assert [m.id for m in found] == expected
            np.testing.assert_allclose([m.score for m in found], fused[expected], rtol=1e-9)
        before = {m: index.fits[m] for m in MODALITIES}


def test_an_index_saved_under_other_comparisons_is_refitted_where_they_differ(tmp_path):
    base = get_preset(DEFAULT_PRESET)
    gallery = _gallery(300, preset=base)
    save_index(_index(base, gallery), tmp_path / "idx")
    loaded = load_index(tmp_path / "idx", LEARNED)
    assert {m: loaded.fits[m].comparison for m in MODALITIES} == {
        m: LEARNED.comparison(m) for m in MODALITIES
    }
    query = {m: gallery[m][7] * 1.02 for m in MODALITIES}
    assert [m.id for m in loaded.search(query, 10)] == _ranking(LEARNED, gallery, query)[0]


def _posed_index(monkeypatch, rng: np.random.Generator, objects: int = 40, poses: int = 10):
    """An index of ``objects`` in ``poses`` noisy poses each (shape ``i`` is object ``i mod
    objects``), with the inverted file of the samples' profiles from 100 shapes; and the
    function that makes a new pose of an object."""
    monkeypatch.setattr(index_module, "WORDS_FROM", 100)
    _, bases = _parts_gallery(objects, seed=6)
    vectors = _gallery(objects * poses, seed=6, preset=DEFAULT)
    index = GalleryIndex(DEFAULT, DEFAULT.modality_sizes(), parts_shape=DEFAULT.parts_shape())

    def pose(o: int) -> np.ndarray:
        return bases[o] + 0.02 * rng.normal(size=bases[o].shape)

    index.add_many(
        (
            i,
            {
                **{m: vectors[m][i] for m in MODALITIES},
                PARTS: compared_profiles(pose(i % objects), DEFAULT),
            },
        )
        for i in range(objects * poses)
    )
    return index, pose, vectors


def _every_shape_compared(index: GalleryIndex, *query) -> tuple[list[int], float]:
    """A partial search's answer with every shape compared coarsely (no inverted file)."""
    words, index.words = index.words, None
    try:
        every, scale = index.partial_search(*query)
    finally:
        index.words = words
    return [m.id for m in every], scale


def test_from_thousands_of_shapes_the_inverted_file_finds_what_every_shape_compared_finds(
    monkeypatch,
):
    """A gallery of objects in several poses, each query a part of an unseen pose: the
    partial search's candidates from the inverted file of the samples' profiles give the
    ranking that comparing every shape coarsely gives."""
    rng = np.random.default_rng(8)
    objects, poses = 40, 10
    index, pose, vectors = _posed_index(monkeypatch, rng, objects, poses)
    assert index.words is not None and len(index.words.ids) == objects * poses
    weights = {PARTS: 1.0}
    same = 0
    for q in range(12):
        part = pose(q % objects)[:150]
        reach = np.full(150, np.inf)
        found, _ = index.partial_search({}, part, reach, weights, 10)
        every, _ = _every_shape_compared(index, {}, part, reach, weights, 10)
        assert found[0].id % objects == q % objects  # its own object first
        same += [m.id for m in found] == every
    assert same == 12

    # Churn: a shape removed is no longer found, one added after the build is; a whole
    # refit files them at once with the same vocabulary and answers the same.
    part, reach = pose(0)[:150], np.full(150, np.inf)
    first = index.partial_search({}, part, reach, weights, 10)[0][0].id
    assert index.remove(first)
    index.add(
        10_000,
        {**{m: vectors[m][first] for m in MODALITIES}, PARTS: compared_profiles(pose(0), DEFAULT)},
    )
    assert index.words.added and 10_000 in index.words.added
    before = [m.id for m in index.partial_search({}, part, reach, weights, 10)[0]]
    assert first not in before and 10_000 in before
    vocabulary = index.words.centroids
    index.refit()
    assert index.words.centroids is vocabulary and not index.words.added
    assert [m.id for m in index.partial_search({}, part, reach, weights, 10)[0]] == before


@pytest.mark.parametrize("j", [0, 2, 5])
def test_the_inverted_file_chooses_the_scale_every_shape_compared_chooses(monkeypatch, j):
    """A part that keeps ``2^(-j/4)`` of its whole's area, its profiles' radii grown by
    ``2^(j/8)`` against the whole's: the samples vote at each scale, and the scale whose
    most voted shapes hold the best match is the one comparing every shape finds, with
    the same ranking (candidates compared at that scale only)."""
    rng = np.random.default_rng(9)
    index, pose, _ = _posed_index(monkeypatch, rng)
    part = _shifted(pose(7)[:150], j)
    query = ({}, part, np.full(150, np.inf), {PARTS: 1.0}, 10)
    found, scale = index.partial_search(*query)
    assert scale == 2.0 ** (j / 8) and found[0].id % 40 == 7
    assert ([m.id for m in found], scale) == _every_shape_compared(index, *query)


def test_a_scale_whose_votes_miss_its_best_shapes_is_found_by_another_scale_s_leaders(
    monkeypatch,
):
    """At the part's own scale the votes rank its object's poses below that scale's probe
    (within its candidates); at the next step of the grid they rank first. The probes
    alone would choose the next step; its best shapes compared at every step find the
    part's own scale, and the ranking every shape compared gives."""
    rng = np.random.default_rng(9)
    index, pose, _ = _posed_index(monkeypatch, rng)
    shift = 2  # columns: the part's own scale is step 2 of the grid
    part = _shifted(pose(7)[:150], shift)
    own = np.arange(7, 400, 40)
    others = np.setdiff1d(np.arange(400), own)
    gallery = index.store.coarse[index.store.positions(others)]
    few = coarse(part, np.full(150, np.inf), gallery, DEFAULT)
    j = DEFAULT.parts_scale_steps * shift
    at_own_scale = scale_scores(*few[:3], DEFAULT, range(j, j + 1), rough=True)
    others = others[np.argsort(-at_own_scale[0])]  # the probe there: the farthest others
    asked: list[int] = []

    def at_scale(profiles, reach, j, preset):
        asked.append(j)
        return samples_at_scale(profiles, reach, j, preset)

    def voted(queries, valid):  # a scale's votes stand for its step of the grid
        return np.array([asked[-1] // DEFAULT.parts_scale_steps]), np.zeros(0)

    def best(step, _, present, count):
        ranked = {shift: [others[:100], own, others[100:]], shift + 1: [own, others]}
        return np.concatenate(ranked.get(int(step[0]), [others, own]))[:count]

    monkeypatch.setattr(index_module, "samples_at_scale", at_scale)
    monkeypatch.setattr(index.words, "voted", voted)
    monkeypatch.setattr(index.words, "best", best)
    query = ({}, part, np.full(150, np.inf), {PARTS: 1.0}, 10)
    found, scale = index.partial_search(*query)
    assert scale == 2.0 ** (shift / 8) and found[0].id % 40 == 7
    assert ([m.id for m in found], scale) == _every_shape_compared(index, *query)


@pytest.mark.parametrize(("candidates", "probed"), [(256, 64), (1600, 200), (4000, 256)])
def test_each_scale_s_probe_is_an_eighth_of_the_candidates_within_its_bounds(
    monkeypatch, candidates, probed
):
    """The scale is chosen on each scale's ``count / 8`` most voted shapes, at least
    ``WORD_MIN_PROBE`` and at most ``WORD_MAX_PROBE``: every step of the grid compares that
    many coarsely, and the answer stays the one every shape compared gives."""
    rng = np.random.default_rng(11)
    index, pose, _ = _posed_index(monkeypatch, rng)
    monkeypatch.setattr(index_module, "WORD_CANDIDATES", candidates)
    probes: list[int] = []
    scored = index._parts_scores

    def spy(profiles, reach, gallery, scales=None, rough=False):
        if rough and scales is not None and len(scales) == 1:
            probes.append(len(gallery))
        return scored(profiles, reach, gallery, scales, rough)

    monkeypatch.setattr(index, "_parts_scores", spy)
    query = ({}, pose(3)[:150], np.full(150, np.inf), {PARTS: 1.0}, 10)
    found, _ = index.partial_search(*query)
    steps = range(0, scale_count(DEFAULT), DEFAULT.parts_scale_steps)
    assert probes[: len(steps)] == [probed] * len(steps)  # then the candidates' pass
    assert found[0].id % 40 == 3
    assert [m.id for m in found] == _every_shape_compared(index, *query)[0]


@pytest.mark.parametrize(("cap", "voting"), [(8192, 128), (256, 64)])
def test_twice_the_coarse_pass_s_samples_vote_while_the_candidates_are_under_their_cap(
    monkeypatch, cap, voting
):
    """The query's ``VOTE_SAMPLES`` samples farthest from its boundary vote at each step
    while its candidates are fewer than ``WORD_MAX_CANDIDATES``; at the cap, the coarse
    pass's ``COARSE_SAMPLES``. Either way the answer is the one every shape compared
    gives."""
    rng = np.random.default_rng(12)
    index, pose, vectors = _posed_index(monkeypatch, rng)
    monkeypatch.setattr(index_module, "WORD_MAX_CANDIDATES", cap)
    assert index.words is not None
    rows: list[np.ndarray] = []
    voted = index.words.voted

    def spy(queries, valid):
        rows.append(np.asarray(queries))
        return voted(queries, valid)

    monkeypatch.setattr(index.words, "voted", spy)
    part = pose(9)[:300]
    reach = 10.0 + rng.permutation(300)  # every radius clear, each sample its own reach
    query = ({m: vectors[m][9] for m in MODALITIES}, part, reach, {PARTS: 1.0}, 10)
    found, _ = index.partial_search(*query)
    clear = np.sort(np.argsort(-reach)[:voting])
    areas = area_profiles(part[clear], DEFAULT)  # the votes read the areas alone
    assert np.array_equal(rows[0], samples_at_scale(areas, reach[clear], 0, DEFAULT)[0])
    assert found[0].id % 40 == 9
    assert [m.id for m in found] == _every_shape_compared(index, *query)[0]


@pytest.mark.parametrize(("share", "joined"), [(16, True), (10**9, False)])
def test_at_the_cap_the_whole_query_s_best_join_the_voted_candidates(monkeypatch, share, joined):
    """Once the inverted file's candidates reach ``WORD_MAX_CANDIDATES``, the best
    ``count / WHOLE_SHARE`` of the query searched as a whole are candidates as well: a
    shape whose flat vectors are the query's, though its parts are another object's and
    the votes leave it out, is found first when the product weighs the flat modalities."""
    rng = np.random.default_rng(13)
    index, pose, vectors = _posed_index(monkeypatch, rng)
    monkeypatch.setattr(index_module, "WORD_MAX_CANDIDATES", 32)
    monkeypatch.setattr(index_module, "WHOLE_SHARE", share)
    flat = {m: vectors[m][17] for m in MODALITIES}  # shape 17: object 17, pose 0
    weights = {"ddt": 0.25, PARTS: 0.5, "spectrum": 0.5}
    found, _ = index.partial_search(flat, pose(3)[:150], np.full(150, np.inf), weights, 10)
    assert (found[0].id == 17) is joined
    if not joined:
        assert found[0].id % 40 == 3  # the votes' object


@pytest.mark.parametrize("quarters", [3, 10, 18])
def test_between_the_grid_s_steps_the_shortlist_finds_the_scale_every_shape_compared_finds(
    monkeypatch, quarters
):
    """A part whose radii grow by ``2^(q/32)`` against its whole's, ``q`` quarter steps,
    between two steps of the grid at which the samples vote: the shortlist's scales
    around the voted one reach it, and the answer is the one every scale of every shape
    gives."""
    rng = np.random.default_rng(10)
    index, pose, _ = _posed_index(monkeypatch, rng)
    part = _shifted(pose(11)[:150], quarters / 4)
    query = ({}, part, np.full(150, np.inf), {PARTS: 1.0}, 10)
    found, scale = index.partial_search(*query)
    assert scale == 2.0 ** (quarters / 32) and found[0].id % 40 == 11
    assert ([m.id for m in found], scale) == _every_shape_compared(index, *query)
