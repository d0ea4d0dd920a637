"""Small combinatorial helpers on triangle index arrays (vectorized, 1-D keys)."""

from __future__ import annotations

import numpy as np


def unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique rows of an integer array, much faster than ``np.unique(axis=0)``.

    Parameters
    ----------
    rows : (n, d) int

    Returns
    -------
    first : (u,) int, index of the first occurrence of each unique row, in the
        order of the rows' lexicographic sort.
    inverse : (n,) int, ``rows == rows[first][inverse]``.
    """
    rows = np.asarray(rows)
    order = np.lexsort(rows.T[::-1])
    sorted_rows = rows[order]
    new = np.ones(len(rows), dtype=bool)
    new[1:] = np.any(sorted_rows[1:] != sorted_rows[:-1], axis=1)
    group = np.cumsum(new) - 1
    inverse = np.empty(len(rows), dtype=np.int64)
    inverse[order] = group
    first = order[new]
    return first, inverse


def edge_keys(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Undirected edge of every face corner as one int64 key ``min * n + max``.

    Parameters
    ----------
    faces : (m, 3) int
    n_vertices : number of vertices

    Returns
    -------
    (m, 3) int64; entry ``[f, c]`` is the edge opposite corner ``c`` of face ``f``.
    """
    a = faces[:, [1, 2, 0]].astype(np.int64)
    b = faces[:, [2, 0, 1]].astype(np.int64)
    return np.minimum(a, b) * n_vertices + np.maximum(a, b)


def euler_characteristic(faces: np.ndarray, n_vertices: int) -> int:
    """V - E + F of the complex spanned by ``faces``."""
    n_edges = len(np.unique(edge_keys(faces, n_vertices)))
    return n_vertices - n_edges + len(faces)


def boundary_edge_count(faces: np.ndarray, n_vertices: int) -> int:
    """Number of edges used by exactly one face."""
    _, counts = np.unique(edge_keys(faces, n_vertices), return_counts=True)
    return int(np.count_nonzero(counts == 1))
