"""Index-array helpers: unique rows, used vertices, edge keys, Euler characteristic and
boundary edges."""

from __future__ import annotations

import numpy as np
import trimesh

from worker.engine.topology import (
    edge_keys,
    euler_and_boundary,
    keys_seen_once,
    unique_rows,
    used_vertices,
)


def open_tube(sections: int = 24, rings: int = 5) -> np.ndarray:
    """Faces of a cylinder without caps: ``rings`` circles of ``sections`` vertices."""
    faces = []
    for r in range(rings - 1):
        for s in range(sections):
            a, b = r * sections + s, r * sections + (s + 1) % sections
            c, d = a + sections, b + sections
            faces += [(a, b, d), (a, d, c)]
    return np.array(faces)


def test_unique_rows_agrees_with_numpy_unique():
    rows = np.random.default_rng(0).integers(0, 4, size=(500, 3))  # many repeats
    first, inverse = unique_rows(rows)
    expected, expected_first, expected_inverse = np.unique(
        rows, axis=0, return_index=True, return_inverse=True
    )
    np.testing.assert_array_equal(rows[first], expected)
    np.testing.assert_array_equal(first, expected_first)  # first occurrence of each
    np.testing.assert_array_equal(inverse, expected_inverse.ravel())
    np.testing.assert_array_equal(rows[first][inverse], rows)


def test_used_vertices_agrees_with_numpy_unique():
    faces = np.random.default_rng(1).integers(0, 1000, size=(400, 3))  # some vertices unused
    used = used_vertices(faces, 1000)
    np.testing.assert_array_equal(used, np.unique(faces))
    assert len(used) < 1000


def test_edge_keys_name_the_edge_opposite_each_corner():
    faces = np.array([[0, 1, 2], [2, 1, 3]])
    n = 4
    # corner 0 of face 0 faces edge 1-2, corner 1 faces 2-0, corner 2 faces 0-1
    np.testing.assert_array_equal(
        edge_keys(faces, n),
        [[1 * n + 2, 0 * n + 2, 0 * n + 1], [1 * n + 3, 2 * n + 3, 1 * n + 2]],
    )
    # the shared edge 1-2 has one key, whichever face and direction it comes from
    assert edge_keys(faces, n)[0, 0] == edge_keys(faces, n)[1, 2]


def test_euler_characteristic_and_boundary_of_a_sphere_a_torus_and_a_tube():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    torus = trimesh.creation.torus(major_radius=2.0, minor_radius=0.5)
    assert euler_and_boundary(sphere.faces, len(sphere.vertices)) == (2, 0)
    assert euler_and_boundary(torus.faces, len(torus.vertices)) == (0, 0)
    tube = open_tube(sections=24)
    assert euler_and_boundary(tube, tube.max() + 1) == (0, 2 * 24)  # an annulus: two rims


def test_keys_seen_once_and_the_edge_counts_agree_with_numpy_unique():
    # Random faces over few vertices: edges used once, twice and three or more times.
    faces = np.random.default_rng(2).integers(0, 40, size=(300, 3))
    keys = edge_keys(faces, 40)
    unique, counts = np.unique(keys, return_counts=True)
    np.testing.assert_array_equal(keys_seen_once(keys), unique[counts == 1])
    assert (counts > 2).any() and (counts == 1).any()
    assert euler_and_boundary(faces, 40) == (40 - len(unique) + 300, np.sum(counts == 1))
    assert len(keys_seen_once(np.array([3, 3]))) == 0
