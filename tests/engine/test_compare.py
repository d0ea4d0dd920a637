"""Eqs. (8) and (9) on hand-computed cases, and the fusion rules."""

from __future__ import annotations

import numpy as np
import pytest

from worker.engine.compare import (
    dissimilarity,
    fuse,
    gallery_sigma,
    mean_normalized_manhattan,
    normalized_euclidean,
    paired_dissimilarity,
    product_fusion,
    sum_fusion,
)


def test_d1_hand_computed():
    a = np.array([[1.0, 2.0, 0.0]])
    b = np.array([[3.0, 2.0, 0.0], [1.0, 2.0, 0.0]])
    # vs b0: 2|1-3|/(1+3) = 1, 0, 0 (both zero) -> mean 1/3; vs b1: 0.
    np.testing.assert_allclose(mean_normalized_manhattan(a, b), [[1 / 3, 0.0]])


def test_d1_is_symmetric_and_scale_free():
    rng = np.random.default_rng(0)
    x = rng.random((5, 8))
    d = mean_normalized_manhattan(x, x)
    np.testing.assert_allclose(d, d.T)
    np.testing.assert_allclose(np.diag(d), 0.0)
    np.testing.assert_allclose(mean_normalized_manhattan(3 * x, 3 * x), d)


def test_d2_hand_computed():
    gallery = np.array([[0.0, 0.0], [2.0, 4.0]])
    sigma = gallery_sigma(gallery)
    np.testing.assert_allclose(sigma, [1.0, 2.0])
    # ((2-0)/1)^2 + ((4-0)/2)^2 = 8
    np.testing.assert_allclose(normalized_euclidean(gallery, gallery, sigma)[0, 1], np.sqrt(8))


def test_constant_element_gets_unit_sigma():
    sigma = gallery_sigma(np.array([[1.0, 5.0], [3.0, 5.0]]))
    np.testing.assert_allclose(sigma, [1.0, 1.0])


def test_fusion_rules():
    d = {"gdm": np.array([[1.0, 2.0]]), "ddt": np.array([[3.0, 0.5]])}
    np.testing.assert_allclose(sum_fusion(d), [[4.0, 2.5]])
    np.testing.assert_allclose(product_fusion(d), [[3.0, 1.0]])
    np.testing.assert_allclose(fuse(d, "sum", {"ddt": 2.0}), [[7.0, 3.0]])
    np.testing.assert_allclose(fuse(d, "product", {"gdm": 2.0}), [[3.0, 2.0]])
    with pytest.raises(ValueError, match="fusion rule"):
        fuse(d, "max")


@pytest.mark.parametrize("kind", ["D1", "D2"])
def test_paired_dissimilarity_is_the_diagonal_of_the_matrix(kind):
    rng = np.random.default_rng(3)
    a, b = rng.random((7, 12)), rng.random((7, 12))
    sigma = gallery_sigma(b)
    np.testing.assert_allclose(
        paired_dissimilarity(a, b, kind, sigma), np.diag(dissimilarity(a, b, kind, sigma))
    )
