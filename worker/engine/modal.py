"""Modal representations of the GDM and the DDT (sec. 3), made sampling-order invariant.

A simultaneous permutation of the first two modes (eq. 5) leaves the singular
values of the GDM and the HOSVD core of the DDT unchanged (eqs. 6-7), so these are
the descriptors. Both tensors are first normalized per slice (sec. 4.2).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as la
import scipy.sparse.linalg as sla
import tensorly as tl
from tensorly.decomposition import tucker

from .diffusion import seeded_start
from .tol import TOL


def normalize_slices(tensor: np.ndarray) -> np.ndarray:
    """Divide every slice by the sum of its distances (sec. 4.2), times ``n``.

    The paper divides by the sum, which removes scale. The extra constant factor
    ``n`` (the number of vertices) changes nothing for meshes of equal size (D1 and
    D2 are scale-free), but keeps descriptors comparable when resampling leaves
    two meshes a few vertices apart: a slice's sum grows like ``n^2`` while its
    singular values grow like ``n``.

    Parameters
    ----------
    tensor : (n, n) or (n, n, s) float

    Returns
    -------
    Same shape, float.
    """
    n = tensor.shape[0]
    sums = tensor.sum(axis=(0, 1))
    normalized: np.ndarray = tensor * (n / sums)
    return normalized


def modal_gdm(gdm: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` largest singular values of the normalized GDM, descending.

    The GDM is symmetric, so its singular values are the absolute values of its
    eigenvalues and the largest ones come from Lanczos (``eigsh``) without a full
    SVD; :func:`modal_gdm_reference` is the plain SVD.

    Parameters
    ----------
    gdm : (n, n) float, symmetric.
    k : number of singular values.

    Returns
    -------
    (k,) float
    """
    normalized = normalize_slices(gdm)
    values = sla.eigsh(
        normalized, k=k, which="LM", return_eigenvectors=False, v0=seeded_start(len(gdm))
    )
    return np.sort(np.abs(values))[::-1]


def modal_gdm_reference(gdm: np.ndarray, k: int) -> np.ndarray:
    """The same descriptor by a full SVD."""
    return np.linalg.svd(normalize_slices(gdm), compute_uv=False)[:k]


def hosvd_core(tensor: np.ndarray, core_shape: tuple[int, int, int]) -> np.ndarray:
    """Truncated HOSVD (Tucker) core of a tensor whose first two modes are symmetric.

    Factors come from the SVDs of the unfoldings (tensorly's ``tucker`` with no
    HOOI iterations, i.e. the HOSVD of [14]), ordered by decreasing mode singular
    values, so the core is ordered by decreasing Frobenius norm of its slices.

    Each singular vector is defined only up to its sign, and flipping one flips a
    whole slice of the core. The descriptor is therefore the element-wise absolute
    value of the core, which is invariant to every sign choice (and, like the core,
    to vertex order).

    Parameters
    ----------
    tensor : (p, p, s) float
    core_shape : (r1, r2, r3)

    Returns
    -------
    core_shape float, non-negative.
    """
    # A plain SVD of each unfolding, not the Gram matrix: small core elements weigh
    # as much as large ones in D1, and squaring the unfolding would drown them.
    core, _ = tucker(tl.tensor(tensor), rank=list(core_shape), n_iter_max=0, init="svd")
    magnitudes: np.ndarray = np.abs(tl.to_numpy(core))
    return magnitudes


def orthonormal_basis(columns: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the span of ``columns`` (n, m), n >> m, rank-revealing.

    Householder QR with column pivoting; directions whose pivot is below
    ``TOL.basis_rank`` of the largest are numerically absent and dropped (the
    constant vector is also the first eigenvector, so the columns are dependent).
    """
    q, r, _ = la.qr(columns, mode="economic", pivoting=True)
    pivots = np.abs(np.diag(r))
    basis: np.ndarray = q[:, pivots > TOL.basis_rank * pivots[0]]
    return basis


def ddt_core(
    eigenvalues: np.ndarray,
    eigenvectors: np.ndarray,
    times: tuple[float, ...],
    core_shape: tuple[int, int, int],
) -> np.ndarray:
    """HOSVD core of the normalized DDT without forming the ``n x n x s`` tensor.

    Every slice of eq. (4) is low rank:
    ``D_t = r_t 1^T + 1 r_t^T - 2 Psi_t Psi_t^T`` with ``Psi_t = Phi exp(-Lambda t)``
    and ``r_t`` the row norms of ``Psi_t``. All slices therefore live in the span of
    ``[1, r_1 .. r_s, Phi]``; with ``Q`` an orthonormal basis of it, the small
    tensor ``S_t = Q^T D_t Q`` has exactly the same HOSVD core (its factors are
    ``Q^T`` times the big ones).

    Parameters
    ----------
    eigenvalues : (k,) float
    eigenvectors : (n, k) float, A-orthonormal.
    times : diffusion times.
    core_shape : (r1, r2, r3)

    Returns
    -------
    core_shape float, as :func:`hosvd_core` of the normalized dense DDT.
    """
    n = eigenvectors.shape[0]
    ones = np.ones(n)
    psis = [eigenvectors * np.exp(-eigenvalues * t) for t in times]
    rows = [np.einsum("ik,ik->i", psi, psi) for psi in psis]
    q = orthonormal_basis(np.column_stack([ones, *rows, eigenvectors]))
    q_one = q.T @ ones
    slices = []
    for psi, r in zip(psis, rows, strict=True):
        q_r = q.T @ r
        q_psi = q.T @ psi
        total = 2.0 * n * r.sum() - 2.0 * np.sum(psi.sum(axis=0) ** 2)
        small = np.outer(q_r, q_one) + np.outer(q_one, q_r) - 2.0 * q_psi @ q_psi.T
        slices.append(small * (n / total))
    return hosvd_core(np.stack(slices, axis=2), core_shape)
