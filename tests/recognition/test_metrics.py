"""Unit tests for worker.recognition.metrics against small hand-computed cases.

Every expected number below is derived by hand in the accompanying comment.
"""

import math

import numpy as np
import pytest

from worker.recognition import metrics as m


def symmetric(n: int, pairs: dict[tuple[int, int], float]) -> np.ndarray:
    """(n, n) symmetric matrix from ``{(i, j): d_ij}``; diagonal set to NaN (never read)."""
    d = np.full((n, n), np.nan)
    for (i, j), value in pairs.items():
        d[i, j] = d[j, i] = value
    assert not np.isnan(d[~np.eye(n, dtype=bool)]).any(), "all off-diagonal pairs needed"
    return d


# Case A: 4 objects, labels a a b b.
#   genuine pairs:  (0,1)=1  (2,3)=3
#   impostor pairs: (0,2)=2  (0,3)=4  (1,2)=5  (1,3)=6
LABELS_A = ["a", "a", "b", "b"]
D_A = symmetric(4, {(0, 1): 1, (2, 3): 3, (0, 2): 2, (0, 3): 4, (1, 2): 5, (1, 3): 6})

# Case B: 5 objects, labels a a a b b (class a: C-1 = 2 relevant, class b: C-1 = 1).
#        0   1   2   3   4
#   0  [ -,  1,  6,  2,  7]
#   1  [ 1,  -,  3,  8,  4]
#   2  [ 6,  3,  -,  5,  9]
#   3  [ 2,  8,  5,  -, 10]
#   4  [ 7,  4,  9, 10,  -]
LABELS_B = ["a", "a", "a", "b", "b"]
D_B = symmetric(
    5,
    {
        (0, 1): 1, (0, 2): 6, (0, 3): 2, (0, 4): 7,
        (1, 2): 3, (1, 3): 8, (1, 4): 4,
        (2, 3): 5, (2, 4): 9,
        (3, 4): 10,
    },
)  # fmt: skip

# Perfect case: 3 classes of 2; same-class pairs at 1, cross-class pairs at 5.
LABELS_PERFECT = [0, 0, 1, 1, 2, 2]
D_PERFECT = np.where(np.equal.outer(LABELS_PERFECT, LABELS_PERFECT), 1.0, 5.0)

# Worst case: labels a a b b; same-class pairs at 10, cross-class pairs at 1.
LABELS_WORST = ["a", "a", "b", "b"]
D_WORST = np.where(np.equal.outer(LABELS_WORST, LABELS_WORST), 10.0, 1.0)


# --------------------------------------------------------------------------- ROC / EER


def test_roc_curve_case_a():
    # 2 genuine {1, 3}, 4 impostors {2, 4, 5, 6}; accept when d <= t.
    #   t     -inf  1    2    3    4    5    6
    #   FAR   0     0    1/4  1/4  2/4  3/4  1
    #   FRR   1     1/2  1/2  0    0    0    0
    far, frr, thresholds = m.roc_curve(D_A, LABELS_A)
    np.testing.assert_array_equal(thresholds, [-np.inf, 1, 2, 3, 4, 5, 6])
    np.testing.assert_allclose(far, [0, 0, 0.25, 0.25, 0.5, 0.75, 1])
    np.testing.assert_allclose(frr, [1, 0.5, 0.5, 0, 0, 0, 0])


def test_roc_curve_case_b():
    # genuine {1, 3, 6, 10} (4 pairs), impostors {2, 4, 5, 7, 8, 9} (6 pairs).
    #   t    -inf 1   2   3   4   5   6   7   8   9   10
    #   FAR  0    0   1/6 1/6 2/6 3/6 3/6 4/6 5/6 1   1
    #   FRR  1    3/4 3/4 2/4 2/4 2/4 1/4 1/4 1/4 1/4 0
    far, frr, thresholds = m.roc_curve(D_B, LABELS_B)
    np.testing.assert_array_equal(thresholds, [-np.inf, *range(1, 11)])
    np.testing.assert_allclose(far, np.array([0, 0, 1, 1, 2, 3, 3, 4, 5, 6, 6]) / 6)
    np.testing.assert_allclose(frr, np.array([4, 3, 3, 2, 2, 2, 1, 1, 1, 1, 0]) / 4)


def test_roc_curve_ties_accepted_together():
    # labels a a b b; genuine {1, 2}, impostors {2, 3, 3, 3}: distinct thresholds 1, 2, 3.
    #   t    -inf 1    2    3
    #   FAR  0    0    1/4  1       (the impostor at 2 enters with the genuine at 2;
    #   FRR  1    1/2  0    0        all three impostors at 3 enter together)
    d = symmetric(4, {(0, 1): 1, (2, 3): 2, (0, 2): 2, (0, 3): 3, (1, 2): 3, (1, 3): 3})
    far, frr, thresholds = m.roc_curve(d, ["a", "a", "b", "b"])
    np.testing.assert_array_equal(thresholds, [-np.inf, 1, 2, 3])
    np.testing.assert_allclose(far, [0, 0, 0.25, 1])
    np.testing.assert_allclose(frr, [1, 0.5, 0, 0])


def test_roc_curve_reads_upper_triangle_only():
    # Garbage in the lower triangle must not change anything.
    d = D_A.copy()
    d[np.tril_indices(4, k=-1)] = 100.0
    for got, want in zip(m.roc_curve(d, LABELS_A), m.roc_curve(D_A, LABELS_A), strict=True):
        np.testing.assert_array_equal(got, want)


def test_eer_interpolated_on_vertical_segment():
    # Case A: FRR - FAR = 1, .5, .25, -.25 ... crosses between t=2 (FAR .25, FRR .5)
    # and t=3 (FAR .25, FRR 0). alpha = .25 / (.25 + .25) = 1/2
    # -> FAR = .25, FRR = .5 - .5 * .5 = .25. EER = 0.25.
    assert m.equal_error_rate(D_A, LABELS_A) == pytest.approx(0.25)


def test_eer_exactly_on_roc_point():
    # Case B: at t=5, FAR = 3/6 = FRR = 2/4, so EER = 0.5 with no interpolation.
    assert m.equal_error_rate(D_B, LABELS_B) == pytest.approx(0.5)


def test_eer_interpolated_on_diagonal_segment():
    # Tie case above: crossing between t=1 (FAR 0, FRR 1/2) and t=2 (FAR 1/4, FRR 0).
    # gap = FRR - FAR = 1/2 then -1/4; alpha = (1/2) / (1/2 + 1/4) = 2/3.
    # FAR = 0 + 2/3 * 1/4 = 1/6;  FRR = 1/2 - 2/3 * 1/2 = 1/6.  EER = 1/6.
    d = symmetric(4, {(0, 1): 1, (2, 3): 2, (0, 2): 2, (0, 3): 3, (1, 2): 3, (1, 3): 3})
    assert m.equal_error_rate(d, ["a", "a", "b", "b"]) == pytest.approx(1 / 6)


def test_eer_perfect_and_worst():
    # Perfect: at t=1 all genuines accepted, no impostor: FAR = FRR = 0 -> EER 0.
    assert m.equal_error_rate(D_PERFECT, LABELS_PERFECT) == 0.0
    # Worst: at t=1 all 4 impostors accepted, no genuine: FAR = 1 = FRR -> EER 1.
    assert m.equal_error_rate(D_WORST, LABELS_WORST) == 1.0


def test_roc_needs_genuine_pairs():
    with pytest.raises(ValueError, match="no genuine pairs"):
        m.roc_curve(np.ones((3, 3)), ["a", "b", "c"])


# --------------------------------------------------------------------------- identification


def test_natural_sort_key():
    names = ["cat10", "Cat3", "cat2", "cat02", "dog1", "cat"]
    # digits compare as numbers, text case-insensitively; "cat02" vs "cat2" tie on the
    # number and fall back to the raw string ("cat02" < "cat2").
    assert sorted(names, key=m.natural_sort_key) == [
        "cat",
        "cat02",
        "cat2",
        "Cat3",
        "cat10",
        "dog1",
    ]


def test_first_instance_split_uses_natural_order():
    # natural order: cat2(1) < cat3(4) < cat10(0) < dog1(3) < dog07(2)
    # -> gallery: cat -> 1, dog -> 3; probes 0, 2, 4.
    # (plain string order would have picked "cat10" and "dog07" instead.)
    names = ["cat10", "cat2", "dog07", "dog1", "cat3"]
    labels = ["cat", "cat", "dog", "dog", "cat"]
    gallery, probes = m.first_instance_split(names, labels)
    np.testing.assert_array_equal(gallery, [1, 3])
    np.testing.assert_array_equal(probes, [0, 2, 4])


def test_first_instance_split_validation():
    with pytest.raises(ValueError, match="must match"):
        m.first_instance_split(["a1", "a2"], ["a"])
    with pytest.raises(ValueError, match="empty"):
        m.first_instance_split([], [])


# Identification case: labels a b c a b c; gallery 0, 1, 2 (a, b, c); probes 3, 4, 5.
# Probe rows against gallery columns 0 1 2:
#   probe 3 (a): [1, 2, 3] -> correct g0 first                  -> rank 1
#   probe 4 (b): [2, 2, 5] -> correct g1 tied with wrong g0      -> rank 2 (pessimistic)
#   probe 5 (c): [1, 2, 3] -> correct g2 after g0, g1            -> rank 3
# CMC = [1/3, 2/3, 3/3]. Probe-probe entries are irrelevant (set to 9).
LABELS_ID = ["a", "b", "c", "a", "b", "c"]
D_ID = np.full((6, 6), 9.0)
D_ID[3, :3] = [1, 2, 3]
D_ID[4, :3] = [2, 2, 5]
D_ID[5, :3] = [1, 2, 3]
D_ID[:3, 3:] = D_ID[3:, :3].T
GALLERY_ID = [0, 1, 2]
PROBES_ID = [3, 4, 5]


def test_cmc_curve_hand_case_with_pessimistic_tie():
    cmc = m.cmc_curve(D_ID, LABELS_ID, GALLERY_ID, PROBES_ID)
    np.testing.assert_allclose(cmc, [1 / 3, 2 / 3, 1])
    assert m.rank1_rate(D_ID, LABELS_ID, GALLERY_ID, PROBES_ID) == pytest.approx(1 / 3)


def test_cmc_curve_all_tied_is_last_rank():
    # One probe equidistant to all three gallery items: both wrong ones rank before
    # the correct one -> rank 3 -> CMC = [0, 0, 1].
    d = np.ones((4, 4))
    cmc = m.cmc_curve(d, ["a", "b", "c", "b"], [0, 1, 2], [3])
    np.testing.assert_allclose(cmc, [0, 0, 1])


def test_cmc_curve_best_of_several_correct_gallery_items():
    # Gallery 0 (a), 1 (a), 2 (b); probe 3 (a) at distances [5, 1, 3]:
    # best correct item 1 at d=1, no wrong item <= 1 -> rank 1 -> CMC = [1, 1, 1].
    d = np.full((4, 4), 9.0)
    d[3, :3] = d[:3, 3] = [5, 1, 3]
    np.testing.assert_allclose(m.cmc_curve(d, ["a", "a", "b", "a"], [0, 1, 2], [3]), [1, 1, 1])


def test_cmc_perfect_and_worst():
    # Perfect: gallery 0, 2, 4 (one per class); every probe's own class is at 1 < 5.
    cmc = m.cmc_curve(D_PERFECT, LABELS_PERFECT, [0, 2, 4], [1, 3, 5])
    np.testing.assert_allclose(cmc, [1, 1, 1])
    # Worst: gallery 0 (a), 2 (b); each probe is closer to the wrong class -> rank 2.
    cmc = m.cmc_curve(D_WORST, LABELS_WORST, [0, 2], [1, 3])
    np.testing.assert_allclose(cmc, [0, 1])


def test_cmc_validation():
    with pytest.raises(ValueError, match="no gallery item"):
        m.cmc_curve(D_ID, LABELS_ID, [0, 1], [5])  # probe 5 is class c
    with pytest.raises(ValueError, match="overlap"):
        m.cmc_curve(D_ID, LABELS_ID, [0, 1, 2], [2, 3])
    with pytest.raises(ValueError, match="outside"):
        m.cmc_curve(D_ID, LABELS_ID, [0, 1, 6], [3])
    with pytest.raises(ValueError, match="repeated"):
        m.cmc_curve(D_ID, LABELS_ID, [0, 0, 1, 2], [3])
    with pytest.raises(ValueError, match="non-empty"):
        m.cmc_curve(D_ID, LABELS_ID, [0, 1, 2], [])
    with pytest.raises(ValueError, match="integers"):
        m.cmc_curve(D_ID, LABELS_ID, [0.0, 1.0, 2.0], [3])


# --------------------------------------------------------------------------- retrieval

# Case B rankings (query excluded, ascending dissimilarity), R = relevant:
#   q0 (a): 1(1) 3(2) 2(6) 4(7)   -> R . R .
#   q1 (a): 0(1) 2(3) 4(4) 3(8)   -> R R . .
#   q2 (a): 1(3) 3(5) 0(6) 4(9)   -> R . R .
#   q3 (b): 0(2) 2(5) 1(8) 4(10)  -> . . . R
#   q4 (b): 1(4) 0(7) 2(9) 3(10)  -> . . . R


def test_nearest_neighbor_rate_case_b():
    # first item relevant for q0, q1, q2 -> 3/5
    assert m.nearest_neighbor_rate(D_B, LABELS_B) == pytest.approx(0.6)


def test_nearest_neighbor_misses_case_b():
    # q3 and q4 (b) retrieve 0 and 1 (a) first; int labels come back as strings
    assert m.nearest_neighbor_misses(D_B, LABELS_B) == {"b": {"a": 2}}
    assert m.nearest_neighbor_misses(D_B, [7, 7, 7, 3, 3]) == {"3": {"7": 2}}


def test_first_tier_case_b():
    # top C-1: q0 1/2, q1 2/2, q2 1/2, q3 0/1, q4 0/1 -> 2/5
    assert m.first_tier(D_B, LABELS_B) == pytest.approx(0.4)


def test_second_tier_case_b():
    # top 2(C-1): q0..q2 top 4 -> 1 each; q3, q4 top 2 -> 0 each -> 3/5
    assert m.second_tier(D_B, LABELS_B) == pytest.approx(0.6)


def test_e_measure_case_b():
    # k = min(32, n-1) = 4. q0..q2: 2 hits, P = 2/4, R = 2/2 -> E = 2/(2 + 1) = 2/3.
    # q3, q4: 1 hit, P = 1/4, R = 1 -> E = 2/(4 + 1) = 2/5.
    # mean = (3 * 2/3 + 2 * 2/5) / 5 = 2.8 / 5 = 0.56
    assert m.e_measure(D_B, LABELS_B) == pytest.approx(0.56)


def test_e_measure_custom_cutoff_case_b():
    # cutoff 2: q0 P=1/2 R=1/2 -> 1/2; q1 P=1 R=1 -> 1; q2 -> 1/2; q3, q4 no hit -> 0.
    # mean = 2 / 5 = 0.4
    assert m.e_measure(D_B, LABELS_B, cutoff=2) == pytest.approx(0.4)
    with pytest.raises(ValueError, match="cutoff"):
        m.e_measure(D_B, LABELS_B, cutoff=0)


def test_dcg_case_b():
    # ideal DCG: class a (2 relevant) = 1 + 1/log2(2) = 2; class b (1 relevant) = 1.
    # q0, q2: hits at ranks 1, 3 -> (1 + 1/log2 3) / 2
    # q1: ranks 1, 2 -> 2/2 = 1
    # q3, q4: rank 4 -> (1/log2 4) / 1 = 1/2
    # mean = (2 * (1 + 1/log2 3)/2 + 1 + 2 * 1/2) / 5 = (3 + 1/log2 3) / 5 ~= 0.726186
    expected = (3 + 1 / math.log2(3)) / 5
    assert m.discounted_cumulative_gain(D_B, LABELS_B) == pytest.approx(expected)


def test_mean_average_precision_case_b():
    # q0, q2: hits at ranks 1, 3 -> (1/1 + 2/3) / 2 = 5/6; q1: (1 + 1)/2 = 1;
    # q3, q4: hit at rank 4 -> 1/4. mean = (5/6 + 1 + 5/6 + 1/4 + 1/4) / 5 = 19/30
    assert m.mean_average_precision(D_B, LABELS_B) == pytest.approx(19 / 30)


def test_retrieval_scores_case_b():
    scores = m.retrieval_scores(D_B, LABELS_B)
    assert set(scores) == {"nn", "first_tier", "second_tier", "e_measure", "dcg", "map"}
    assert scores == pytest.approx(
        {
            "nn": 0.6,
            "first_tier": 0.4,
            "second_tier": 0.6,
            "e_measure": 0.56,
            "dcg": (3 + 1 / math.log2(3)) / 5,
            "map": 19 / 30,
        }
    )
    assert all(isinstance(v, float) for v in scores.values())


def test_retrieval_case_a_dcg_rank_one_equals_rank_two():
    # Case A rankings: q0: 1 . . ; q1: 0 . . ; q2: 0(2) 3(3) 1(5) -> . R . ; q3: 2 . .
    # C-1 = 1 everywhere. nn = ft = 3/4; st (top 2) = 1; E (k=3): P=1/3, R=1 -> 1/2;
    # DCG: rank 2 weighs 1/log2(2) = 1, same as rank 1 -> all 1; MAP = (1+1+1/2+1)/4.
    scores = m.retrieval_scores(D_A, LABELS_A)
    assert scores == pytest.approx(
        {"nn": 0.75, "first_tier": 0.75, "second_tier": 1.0, "e_measure": 0.5, "dcg": 1.0,
         "map": 0.875}
    )  # fmt: skip


def test_retrieval_perfect():
    # Each query's single relevant object comes first.
    # E (k = 5): P = 1/5, R = 1 -> 2/(5 + 1) = 1/3 (E-measure is < 1 by definition here).
    scores = m.retrieval_scores(D_PERFECT, LABELS_PERFECT)
    assert scores == pytest.approx(
        {"nn": 1.0, "first_tier": 1.0, "second_tier": 1.0, "e_measure": 1 / 3, "dcg": 1.0,
         "map": 1.0}
    )  # fmt: skip


def test_retrieval_worst():
    # q0: 2(1) 3(1) 1(10) -> . . R, same pattern for every query (C-1 = 1).
    # nn = ft = 0; st (top 2) = 0; E (k=3): P=1/3, R=1 -> 1/2; cutoff 2 -> 0;
    # DCG = 1/log2(3); MAP = 1/3.
    scores = m.retrieval_scores(D_WORST, LABELS_WORST)
    assert scores == pytest.approx(
        {"nn": 0.0, "first_tier": 0.0, "second_tier": 0.0, "e_measure": 0.5,
         "dcg": 1 / math.log2(3), "map": 1 / 3}
    )  # fmt: skip
    assert m.e_measure(D_WORST, LABELS_WORST, cutoff=2) == 0.0


def test_retrieval_ties_broken_by_index():
    # All dissimilarities equal; labels a b a b, so each ranking is index order:
    #   q0: 1 2 3 -> . R .  AP 1/2   q1: 0 2 3 -> . . R  AP 1/3
    #   q2: 0 1 3 -> R . .  AP 1     q3: 0 1 2 -> . R .  AP 1/2
    # nn = 1/4 (only q2); MAP = (1/2 + 1/3 + 1 + 1/2) / 4 = 7/12
    d = np.ones((4, 4))
    labels = ["a", "b", "a", "b"]
    assert m.nearest_neighbor_rate(d, labels) == pytest.approx(0.25)
    assert m.mean_average_precision(d, labels) == pytest.approx(7 / 12)
    # the misses break ties as the rate does: q0 -> 1, q1 -> 0, q3 -> 0
    assert m.nearest_neighbor_misses(d, labels) == {"a": {"b": 1}, "b": {"a": 2}}


def test_integer_and_string_labels_agree():
    int_labels = [7, 7, 7, 3, 3]
    assert m.retrieval_scores(D_B, int_labels) == m.retrieval_scores(D_B, LABELS_B)
    assert m.equal_error_rate(D_B, int_labels) == m.equal_error_rate(D_B, LABELS_B)


def test_retrieval_rejects_singleton_class():
    with pytest.raises(ValueError, match=r"singleton classes: \['c'\]"):
        m.retrieval_scores(np.ones((3, 3)), ["a", "a", "c"])


# --------------------------------------------------------------------------- validation

ALL_PAIRWISE = [
    m.roc_curve,
    m.equal_error_rate,
    m.nearest_neighbor_rate,
    m.nearest_neighbor_misses,
    m.first_tier,
    m.second_tier,
    m.e_measure,
    m.discounted_cumulative_gain,
    m.mean_average_precision,
    m.retrieval_scores,
]


@pytest.mark.parametrize("func", ALL_PAIRWISE)
def test_rejects_non_square(func):
    with pytest.raises(ValueError, match="square"):
        func(np.ones((4, 3)), ["a", "a", "b", "b"])


@pytest.mark.parametrize("func", ALL_PAIRWISE)
def test_rejects_label_count_mismatch(func):
    with pytest.raises(ValueError, match="must match"):
        func(np.ones((4, 4)), ["a", "a", "b"])


@pytest.mark.parametrize("func", ALL_PAIRWISE)
def test_rejects_single_class(func):
    with pytest.raises(ValueError, match="two classes"):
        func(np.ones((4, 4)), ["a"] * 4)


@pytest.mark.parametrize("func", ALL_PAIRWISE)
def test_rejects_non_finite_off_diagonal(func):
    d = np.ones((4, 4))
    d[0, 2] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        func(d, ["a", "a", "b", "b"])


def test_identification_validates_matrix_too():
    with pytest.raises(ValueError, match="square"):
        m.cmc_curve(np.ones((4, 3)), ["a", "b", "a", "b"], [0, 1], [2, 3])
    with pytest.raises(ValueError, match="two classes"):
        m.rank1_rate(np.ones((4, 4)), ["a"] * 4, [0], [1, 2, 3])


def test_rejects_2d_labels():
    with pytest.raises(ValueError, match="1-D"):
        m.roc_curve(np.ones((4, 4)), [["a", "a"], ["b", "b"]])


def test_diagonal_is_ignored():
    d = D_B.copy()
    np.fill_diagonal(d, -1e9)  # would win every ranking if it were read
    assert m.retrieval_scores(d, LABELS_B) == m.retrieval_scores(D_B, LABELS_B)
    assert m.equal_error_rate(d, LABELS_B) == m.equal_error_rate(D_B, LABELS_B)


def test_query_mean_average_precision_against_a_separate_gallery():
    d = np.array([[0.1, 0.3, 0.2], [0.9, 0.1, 0.5]])
    gallery = np.array(["a", "b", "a"])
    # query a: relevant at ranks 1 and 2 -> AP 1; query b: relevant at rank 1 -> AP 1
    assert m.query_mean_average_precision(d, ["a", "b"], gallery) == pytest.approx(1.0)
    # query b ranked last: its one relevant object at rank 3 -> AP 1/3
    d[1] = [0.1, 0.9, 0.2]
    assert m.query_mean_average_precision(d, ["a", "b"], gallery) == pytest.approx(2 / 3)
    with pytest.raises(ValueError, match="no object of its class"):
        m.query_mean_average_precision(d, ["a", "c"], gallery)


@pytest.mark.parametrize("seed", range(6))
def test_a_labelled_set_scores_each_matrix_as_the_functions_do(seed):
    """:class:`LabelledSet`'s figures equal the functions' bit for bit, on random
    asymmetric matrices whose values tie often (a few levels) or never, and whose
    diagonal holds anything."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 40))
    labels = rng.permutation(np.arange(n) % int(rng.integers(2, n // 2 + 1)))
    labelled = m.LabelledSet(labels)
    for levels in (3, 10, None):
        d = rng.random((n, n)) if levels is None else rng.integers(0, levels, (n, n)) / levels
        np.fill_diagonal(d, rng.choice([np.nan, -1.0, 0.0]))
        retrieval = m.retrieval_scores(d, labels)
        expected = (m.equal_error_rate(d, labels), retrieval["nn"], retrieval["map"])
        assert labelled.figures(d) == expected


def test_a_labelled_set_refuses_what_the_functions_refuse():
    with pytest.raises(ValueError, match="singleton classes"):
        m.LabelledSet(["a", "a", "b"])
    with pytest.raises(ValueError, match="at least two classes"):
        m.LabelledSet(["a", "a"])
    labelled = m.LabelledSet(["a", "a", "b", "b"])
    with pytest.raises(ValueError, match="infinite"):
        labelled.figures(symmetric(4, {(i, j): np.inf for i in range(4) for j in range(i + 1, 4)}))
    with pytest.raises(ValueError, match=r"\(4, 4\)"):
        labelled.figures(np.zeros((3, 3)))
