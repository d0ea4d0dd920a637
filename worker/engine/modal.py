"""Modal representations of the GDM and the DDT (sec. 3), made sampling-order invariant.

A simultaneous permutation of the first two modes (eq. 5) leaves the singular
values of the GDM and the HOSVD core of the DDT unchanged (eqs. 6-7), so these are
the descriptors; so are the singular values of each slice of the DDT, which the
default preset takes instead of the core (:func:`slice_singular_values`). Both tensors
are first normalized per slice (sec. 4.2), but in sec. 4.1's TOSCA protocol
(``normalize=False``), where the objects share one scale and keep it.

Two discretizations of the same idea:

* as in the paper (``mass=None``): the matrices over the vertex set, each slice
  divided by its sum. Their singular values are those of the vertex sampling, so
  they change with the triangulation (a mesh decimated where the surface bends
  gets more weight there), more than between two different bodies (measured on
  TOSCA, ``docs/evaluation.md``);
* on the surface (``mass`` = lumped vertex areas ``m``): the matrices weighted
  ``M^1/2 D M^1/2``, whose eigenvalues approximate those of the integral operator
  ``f -> integral d(x, y) f(y) dA(y)`` of the surface itself, whatever the
  sampling, normalized by area so scale cancels. The same operator's singular
  values also come from distances to a few hundred samples ``y_c`` spread over the
  surface, each standing for its geodesic Voronoi cell of area ``w_c``: the
  quadrature ``integral d(x, y) f(y) dA(y) ~ sum_c d(x, y_c) f(y_c) w_c`` makes
  it the ``n x m`` matrix ``M^1/2 D W^1/2`` (:func:`modal_gdm` with
  ``sample_areas``).
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


def modal_gdm(
    gdm: np.ndarray,
    k: int,
    mass: np.ndarray | None = None,
    sample_areas: np.ndarray | None = None,
    normalize: bool = True,
) -> np.ndarray:
    """The ``k`` largest singular values of the normalized GDM, descending.

    The GDM is symmetric, so its singular values are the absolute values of its
    eigenvalues and the largest ones come from Lanczos (``eigsh``) without a full
    SVD; with samples, from the largest eigenvalues of the small ``m x m`` Gram
    matrix, by Lanczos too.
    :func:`modal_gdm_reference` is the plain SVD.

    Parameters
    ----------
    gdm : (n, n) float, symmetric; or (n, m), the distances from ``m`` samples
        (columns) to every vertex, with ``sample_areas``.
    k : number of singular values.
    mass : (n,) float, lumped vertex areas; when given, the singular values are
        those of ``M^1/2 G M^1/2 / A^(3/2)`` (``A`` the total area): the geodesic
        distance operator of the surface, in units that make it scale-free
        (distances scale like ``s``, areas like ``s^2``). Without it, the paper's
        :func:`normalize_slices`.
    sample_areas : (m,) float, the samples' Voronoi areas (:func:`voronoi_areas`):
        the singular values of ``M^1/2 G W^1/2 / A^(3/2)``, the same operator
        integrated over the samples instead of every vertex.
    normalize : False, no scale normalization (sec. 4.1): the singular values of the
        GDM itself (weighted without the ``A^(3/2)``), in the distances' unit.

    Returns
    -------
    (k,) float
    """
    weighted = _normalized_gdm(gdm, mass, sample_areas, normalize)
    if sample_areas is not None:
        # sigma^2 are the Gram matrix's eigenvalues; the k kept ones span about
        # three decades, far from float64's rounding of the largest. For a few of
        # many samples Lanczos finds them in a third of the time of a full
        # tridiagonalization (500 samples); LAPACK takes the rest.
        gram = weighted.T @ weighted
        m = len(gram)
        squares: np.ndarray
        if m > 2 * k:
            squares = sla.eigsh(
                gram, k=k, which="LA", return_eigenvectors=False, v0=seeded_start(m)
            )
        else:
            squares = la.eigvalsh(gram, subset_by_index=[m - k, m - 1])
        return np.sqrt(np.maximum(np.sort(squares)[::-1], 0.0))
    values = sla.eigsh(
        weighted, k=k, which="LM", return_eigenvectors=False, v0=seeded_start(len(gdm))
    )
    singular_values: np.ndarray = np.sort(np.abs(values))[::-1]
    return singular_values


def voronoi_areas(distances: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Area of each sample's geodesic Voronoi cell: the vertex areas nearest to it.

    Parameters
    ----------
    distances : (n, m) float, from the ``m`` samples (columns) to every vertex.
    mass : (n,) float, lumped vertex areas.

    Returns
    -------
    (m,) float, summing to the total area.
    """
    nearest = np.argmin(distances, axis=1)
    areas: np.ndarray = np.bincount(nearest, weights=mass, minlength=distances.shape[1])
    return areas


def _normalized_gdm(
    gdm: np.ndarray,
    mass: np.ndarray | None,
    sample_areas: np.ndarray | None = None,
    normalize: bool = True,
) -> np.ndarray:
    if mass is None:
        return normalize_slices(gdm) if normalize else gdm
    scale = float(mass.sum()) ** 0.75 if normalize else 1.0
    rows = np.sqrt(mass) / scale
    columns = rows if sample_areas is None else np.sqrt(sample_areas) / scale
    if sample_areas is not None:  # the small Gram matrix wants double precision
        gdm = gdm.astype(np.float64)
    weighted: np.ndarray = gdm * rows[:, None].astype(gdm.dtype)
    weighted *= columns[None, :].astype(gdm.dtype)
    return weighted


def modal_gdm_reference(
    gdm: np.ndarray,
    k: int,
    mass: np.ndarray | None = None,
    sample_areas: np.ndarray | None = None,
    normalize: bool = True,
) -> np.ndarray:
    """The same descriptor by a full SVD."""
    singular_values: np.ndarray = np.linalg.svd(
        _normalized_gdm(gdm, mass, sample_areas, normalize), compute_uv=False
    )
    return singular_values[:k]


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


def vertex_modes_core(tensor: np.ndarray, rank: tuple[int, int]) -> np.ndarray:
    """Core of a truncated HOSVD in the first two modes only (a partial Tucker).

    Eqs. (5)-(7) permute the first two modes, the vertices; the third, the
    diffusion times, has its own order and needs no factor. Decomposing only the
    vertex modes keeps it: slice ``k`` of the core is ``U1^T T_k U2`` for the leading
    singular vectors ``U1``, ``U2`` of the two vertex unfoldings (tensorly's
    ``partial_tucker`` with no iterations), i.e. time ``t_k``'s own slice. The full
    HOSVD (:func:`hosvd_core`) also rotates that mode by the time unfolding's singular
    vectors, a shape-dependent mixture of the times whose later slices are
    differences of nearly equal slices, elements that cross zero. Absolute values,
    as :func:`hosvd_core`, for the same invariance to signs.

    Every slice of a DDT is symmetric, so the two vertex unfoldings are the same
    matrix and one SVD gives both factors (``partial_tucker`` takes two, 4 ms each at
    the default's size; tested against it).

    Parameters
    ----------
    tensor : (p, p, s) float, every slice symmetric.
    rank : (r1, r2)

    Returns
    -------
    (r1, r2, s) float, non-negative.
    """
    # A plain SVD of the unfolding, not the Gram matrix, as in hosvd_core.
    factor = np.linalg.svd(tensor.reshape(len(tensor), -1), full_matrices=False)[0]
    core = np.einsum(
        "ai,abt,bj->ijt", factor[:, : rank[0]], tensor, factor[:, : rank[1]], optimize=True
    )
    magnitudes: np.ndarray = np.abs(core)
    return magnitudes


def core_diagonal(core: np.ndarray) -> np.ndarray:
    """The elements ``S[i, i, k]`` of a core whose first two modes are symmetric.

    Parameters
    ----------
    core : (r1, r2, r3) float

    Returns
    -------
    (min(r1, r2), r3) float
    """
    diagonal: np.ndarray = np.diagonal(core, axis1=0, axis2=1).T
    return diagonal


def orthonormal_basis(columns: np.ndarray, scale: float | None = None) -> np.ndarray:
    """Orthonormal basis of the span of ``columns`` (n, m), n >> m, rank-revealing.

    Householder QR with column pivoting; directions whose pivot is below
    ``TOL.basis_rank`` of ``scale`` (by default the largest pivot, i.e. the longest
    column) are numerically absent and dropped (the constant vector is also the first
    eigenvector, so the columns are dependent).
    """
    q, r, _ = la.qr(columns, mode="economic", pivoting=True)
    pivots = np.abs(np.diag(r))
    reference = pivots[0] if scale is None else scale
    basis: np.ndarray = q[:, pivots > TOL.basis_rank * reference]
    return basis


def extended_basis(orthonormal: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the span of ``[orthonormal, columns]``, given the first
    block's orthonormal columns (n, k) and a few more columns (n, m), m small.

    The same span as :func:`orthonormal_basis` of both blocks, without the pivoted QR
    of all ``k + m`` columns: ``columns`` are orthogonalized against the first block
    (two passes of classical Gram-Schmidt, which keeps them orthogonal to working
    precision), and what is left of them gets its own rank-revealing basis, measured
    against the longest column of either block, as :func:`orthonormal_basis` does.
    """
    rest = columns - orthonormal @ (orthonormal.T @ columns)
    rest -= orthonormal @ (orthonormal.T @ rest)
    scale = max(1.0, float(np.linalg.norm(columns, axis=0).max()))
    return np.column_stack([orthonormal, orthonormal_basis(rest, scale)])


def _is_orthonormal(columns: np.ndarray) -> bool:
    """Whether the columns are orthonormal to ``TOL.orthonormal``."""
    gram = columns.T @ columns
    return bool(np.abs(gram - np.eye(len(gram))).max() <= TOL.orthonormal)


def small_ddt(
    eigenvalues: np.ndarray,
    eigenvectors: np.ndarray,
    times: tuple[float, ...],
    mass: np.ndarray | None = None,
    coordinates: np.ndarray | None = None,
    normalize: bool = True,
) -> np.ndarray:
    """The normalized DDT in a small orthonormal basis of its slices' span, without
    forming the ``n x n x s`` tensor.

    Every slice of eq. (4) is low rank:
    ``D_t = r_t 1^T + 1 r_t^T - 2 Psi_t Psi_t^T`` with ``Psi_t = Phi exp(-Lambda t)``
    and ``r_t`` the row norms of ``Psi_t``. With weights ``w`` (the vertex areas,
    or ones for the paper's vertex matrices) every weighted slice
    ``W^1/2 D_t W^1/2`` lives in the span of ``W^1/2 [1, r_1 .. r_s, Phi]``; with
    ``Q`` an orthonormal basis of it, the small tensor ``Q^T W^1/2 D_t W^1/2 Q`` has
    exactly the same HOSVD core (its factors are ``Q^T`` times the big ones) and
    every slice the same non-zero eigenvalues.
    Each slice is divided by its weighted mean ``sum_ij w_i w_j d_ij / (sum w)^2``
    times ``sum w``: for ``w = 1`` that is the paper's division by the sum, times
    ``n`` (:func:`normalize_slices`).

    With ``mass``, ``W^1/2`` times the eigenvectors is already orthonormal (eq. (3)'s
    are, in the weights' inner product) and contains ``W^1/2 1`` (the constant is an
    eigenvector), so ``Q`` is those columns extended by the ``r_t``
    (:func:`extended_basis`), and ``Q^T W^1/2 Phi`` is the coordinates over zeros;
    columns that are not orthonormal to ``TOL.orthonormal`` get the pivoted QR of all
    of them instead (:func:`orthonormal_basis`). Eigenfunctions given by
    ``coordinates`` in that basis (the averaged mass's Ritz vectors,
    :func:`worker.engine.diffusion.averaged_mass_eigenpairs`) share it, so they cost
    no second orthonormalization.

    Parameters
    ----------
    eigenvalues : (k,) float, in the unit of ``times``.
    eigenvectors : (n, k) float, orthonormal in the inner product of ``mass``
        (without ``mass``: the paper's ``A``).
    times : diffusion times.
    mass : (n,) float, lumped vertex areas, or None for the paper's vertex matrices.
    coordinates : (k, k) float, optional: eq. (4)'s eigenfunctions are
        ``eigenvectors @ coordinates`` (with ``eigenvalues`` theirs); by default the
        eigenvectors themselves.
    normalize : False, every slice as eq. (4) gives it (sec. 4.1: no scale
        normalization).

    Returns
    -------
    (p, p, len(times)) float, ``p`` at most ``k + len(times) + 1``; every slice
    symmetric.
    """
    n, k = eigenvectors.shape
    weights = np.ones(n) if mass is None else np.asarray(mass, dtype=np.float64)
    root = np.sqrt(weights)
    total = float(weights.sum())
    functions = eigenvectors if coordinates is None else eigenvectors @ coordinates
    decays = np.exp(-np.outer(eigenvalues, times))  # (k, s): column t is exp(-Lambda t)
    rows = (functions**2) @ decays**2  # (n, s): column t is r_t
    spanning = root[:, None] * eigenvectors
    others = root[:, None] * np.column_stack([np.ones(n), rows])
    if mass is not None and _is_orthonormal(spanning):
        q = extended_basis(spanning, others[:, 1:])
        # Q^T W^1/2 Phi: the basis leads with W^1/2 times the eigenvectors, and the rest
        # of it is orthogonal to them (to working precision).
        q_phi = np.zeros((q.shape[1], k))
        q_phi[:k] = np.eye(k) if coordinates is None else coordinates
    else:
        q = orthonormal_basis(np.column_stack([others, spanning]))
        q_phi = q.T @ (root[:, None] * functions)
    q_others = q.T @ others
    q_one, q_rows = q_others[:, 0], q_others[:, 1:]
    mass_phi = weights @ functions
    slices = []
    for j in range(len(times)):
        q_r, q_psi = q_rows[:, j], q_phi * decays[:, j]  # Q^T W^1/2 Psi_t
        # sum_ij w_i w_j d_ij of eq. (4), from the same low-rank form.
        integral = 2.0 * total * (weights @ rows[:, j]) - 2.0 * np.sum(
            (mass_phi * decays[:, j]) ** 2
        )
        small = np.outer(q_r, q_one) + np.outer(q_one, q_r) - 2.0 * q_psi @ q_psi.T
        slices.append(small * (total / integral) if normalize else small)
    return np.stack(slices, axis=2)


def ddt_core(
    eigenvalues: np.ndarray,
    eigenvectors: np.ndarray,
    times: tuple[float, ...],
    core_shape: tuple[int, int, int],
    mass: np.ndarray | None = None,
    mix_times: bool = True,
    coordinates: np.ndarray | None = None,
    normalize: bool = True,
) -> np.ndarray:
    """HOSVD core of the normalized DDT: that of its small form (:func:`small_ddt`).

    Parameters
    ----------
    eigenvalues, eigenvectors, times, mass, coordinates, normalize : as :func:`small_ddt`.
    core_shape : (r1, r2, r3)
    mix_times : True, the whole HOSVD (the paper); False, the vertex modes only
        (:func:`vertex_modes_core`), so the core's third size is ``len(times)``.

    Returns
    -------
    core_shape float, as :func:`hosvd_core` (or :func:`vertex_modes_core`) of the
    normalized dense (weighted) DDT.
    """
    tensor = small_ddt(eigenvalues, eigenvectors, times, mass, coordinates, normalize)
    if mix_times:
        return hosvd_core(tensor, core_shape)
    return vertex_modes_core(tensor, core_shape[:2])


def slice_singular_values(tensor: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` largest singular values of every slice of a tensor whose slices are
    symmetric (a DDT, or its :func:`small_ddt`), descending.

    Eq. (5) permutes the vertices of every slice alike, so each slice's singular
    values are invariant to it, as the GDM's are (eq. 6). :func:`core_diagonal` would
    hold the same numbers if the slices shared their eigenvectors exactly; weighted by
    area they do only roughly (on three TOSCA meshes the two are 2-4% apart at the
    early times and 29-33% at the latest, docs/evaluation.md). The core's element
    ``S[i, i, t]`` belongs to the ``i``-th singular vector of the unfolding of all
    times together, and where two of those are nearly equal (the two sides of a
    figure) any mixture of the pair is as good a factor, so the diagonal elements
    trade places and values with the triangulation. A slice's singular values are
    continuous in the slice (Weyl), whatever its eigenvectors do.

    Parameters
    ----------
    tensor : (p, p, s) float, every slice symmetric.
    k : values kept per slice, ``k <= p``.

    Returns
    -------
    (k, s) float, column ``t`` the ``k`` largest ``|eigenvalues|`` of slice ``t``, none
    below ``TOL.slice_value_floor`` of the largest (below it they are rounding).
    """
    columns = []
    for t in range(tensor.shape[2]):
        values = np.sort(np.abs(la.eigvalsh(tensor[:, :, t])))[::-1][:k]
        columns.append(np.maximum(values, TOL.slice_value_floor * values[0]))
    return np.column_stack(columns)
