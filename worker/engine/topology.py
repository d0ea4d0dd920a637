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


def used_vertices(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Sorted indices of the vertices ``faces`` refers to (``np.unique(faces)``, by a
    mask instead of a sort: tens of milliseconds less on a 100k-face upload)."""
    used = np.zeros(n_vertices, dtype=bool)
    used[np.asarray(faces).ravel()] = True
    return np.flatnonzero(used)


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


def euler_and_boundary(faces: np.ndarray, n_vertices: int) -> tuple[int, int]:
    """``V - E + F`` of the complex spanned by ``faces``, and its number of boundary
    edges (used by exactly one face), from one pass over the edges."""
    _, counts = np.unique(edge_keys(faces, n_vertices), return_counts=True)
    return n_vertices - len(counts) + len(faces), int(np.count_nonzero(counts == 1))
