"""Laplace-Beltrami eigenpairs and the diffusion distance tensor (DDT, sec. 2.2).

Discretization as in the paper: the cotangent Laplacian
``L = diag(sum_l w_il) - w_ij`` with ``w_ij = cot(alpha_ij) + cot(beta_ij)``, and a
diagonal ``A`` with ``a_i = (5 / mean triangle area) * (sum of the areas of the
triangles at vertex i)``. Both are built on the intrinsic Delaunay triangulation
(:mod:`worker.engine.intrinsic`). The eigenpairs solve ``L phi = lambda A phi`` (eq. 3)
with ``phi^T A phi = 1``, and the average diffusion distance is eq. (4):

    d_t(i, j) = sum_l exp(-2 lambda_l t) (phi_l(i) - phi_l(j))^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from .intrinsic import FEMOperators, IntrinsicMesh, averaged_mass
from .tol import TOL

#: ARPACK tries (each with another start vector and a larger subspace) before the
#: dense solver.
EIGEN_ATTEMPTS = 2
#: Lanczos vectors beyond ``k`` on the first try: of k + 20 .. 2k + 1 the fastest at
#: k = 100 and 1,000-5,000 vertices (2,500: 0.14 s against 0.19 s at 2k + 1; the
#: restarts cost less than orthogonalizing against a basis twice as large). A retry
#: takes 2k + 21.
KRYLOV_MARGIN = 40


@dataclass(frozen=True)
class LaplaceBeltrami:
    """The paper's discrete operator pair of eq. (3).

    Attributes
    ----------
    laplacian : (n, n) sparse, ``L`` with weights ``cot alpha + cot beta``.
    mass : (n,) float, the diagonal of ``A``.
    total_area : float, surface area in the mesh's squared length unit.
    """

    laplacian: sp.csr_matrix
    mass: np.ndarray
    total_area: float

    @classmethod
    def from_fem(cls, ops: FEMOperators) -> LaplaceBeltrami:
        # The FEM stiffness has weights (cot alpha + cot beta) / 2; the paper drops the 1/2.
        laplacian = (2.0 * ops.stiffness).tocsr()
        # vertex_areas is one third of the adjacent triangle areas.
        mass = (5.0 / ops.face_areas.mean()) * 3.0 * ops.vertex_areas
        return cls(laplacian, mass, float(ops.face_areas.sum()))

    @property
    def n(self) -> int:
        return len(self.mass)

    @property
    def fem_scale(self) -> float:
        """``c`` of ``A = c M``, ``M`` the lumped FEM mass (``15 / mean triangle area``):
        eq. (3)'s ``lambda`` is ``2 lambda_FEM / c`` and ``sqrt(c) phi`` is
        M-orthonormal."""
        return float(self.mass.sum()) / self.total_area

    def shift(self) -> float:
        """A small negative shift that makes ``L - shift * A`` positive definite.

        It is a fraction of Weyl's estimate of the first non-zero eigenvalue,
        ``lambda_1 ~ 4 pi / area`` for the FEM pair, i.e. ``8 pi / sum(a_i)`` for
        the paper's ``(L, A)``. (A shift scaled by ``mean(diag(L) / diag(A))``
        followed the largest cotangent weights: on a thin tube with a few needle
        triangles it landed far below the whole low spectrum, which then looked
        like one cluster to ARPACK, and the factorization failed.)
        """
        return -TOL.eigen_shift * 8.0 * np.pi / float(self.mass.sum())


def laplace_beltrami_eigenpairs(op: LaplaceBeltrami, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of eq. (3), by sparse shift-invert Lanczos (ARPACK).

    ``A`` is diagonal, so eq. (3) is the standard problem ``S y = lambda y`` with
    ``S = A^-1/2 L A^-1/2`` and ``phi = A^-1/2 y``: the same eigenvalues, and
    eigenvectors that are A-orthonormal because the ``y`` are orthonormal. Lanczos on
    ``S`` needs no products with ``A`` (ARPACK's generalized mode does three per
    step); with a symmetric fill-reducing order for the shifted factor, this takes
    0.13 s instead of 0.22 s at 2,500 vertices and k = 100. The tests check it
    against the dense generalized solver.

    (A block-Krylov solver on the banded factorization was tried and was no faster
    at k = 150, n = 2,500 once it was accurate enough; see docs/benchmarks.md.)

    Returns
    -------
    eigenvalues : (k,) float, ascending; the first is 0 (constant eigenvector).
    eigenvectors : (n, k) float, A-orthonormal.
    """
    inverse_root = sp.diags(1.0 / np.sqrt(op.mass))
    symmetric = (inverse_root @ op.laplacian @ inverse_root).tocsc()
    shifted = (symmetric - op.shift() * sp.identity(op.n)).tocsc()
    # Minimum degree on the symmetric pattern fills the factor about 30% less than
    # SuperLU's default (COLAMD), so each of the few hundred solves is faster.
    factor = sla.splu(shifted, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
    shift_invert = sla.LinearOperator(shifted.shape, matvec=factor.solve, dtype=np.float64)
    values: np.ndarray | None = None
    for attempt in range(EIGEN_ATTEMPTS):
        try:
            values, vectors = sla.eigsh(
                symmetric,
                k=k,
                sigma=op.shift(),
                OPinv=shift_invert,
                which="LM",
                tol=TOL.eigen_residual,
                v0=seeded_start(op.n, attempt),
                ncv=min(op.n, 2 * k + 21 if attempt else k + KRYLOV_MARGIN),
            )
            vectors = inverse_root @ vectors
            break
        except (sla.ArpackError, sla.ArpackNoConvergence):
            continue
    if values is None or not np.all(np.isfinite(values)):
        # ARPACK gave up twice (seen on nearly degenerate spectra): the dense
        # generalized solver always answers, in seconds at a few thousand vertices.
        values, vectors = la.eigh(
            op.laplacian.toarray(), np.diag(op.mass), subset_by_index=[0, k - 1]
        )
    order = np.argsort(values)
    return values[order], vectors[:, order]


def seeded_start(n: int, attempt: int = 0) -> np.ndarray:
    """A fixed Lanczos start vector, so the same mesh always gives the same bits
    (another fixed one for each retry)."""
    return np.random.default_rng(attempt).standard_normal(n)


def in_diffusion_time_units(area_eigenvalues: np.ndarray, n_reference: int) -> np.ndarray:
    """Scale-free eigenvalues ``lambda_FEM * area`` in the surface presets' unit of
    eq. (4)'s diffusion times, ``area / (15 n_reference)``.

    Eq. (3)'s ``A = c M`` with ``c = 15 / mean triangle area`` counts time in a unit
    that follows the resampled mesh's triangle size; for a closed mesh of
    ``n_reference`` vertices (``2 n`` triangles) it is this one, which no
    triangulation of the surface changes.
    """
    scaled: np.ndarray = area_eigenvalues / (15.0 * n_reference)
    return scaled


def surface_eigenpairs(
    op: LaplaceBeltrami, eigenvalues: np.ndarray, eigenvectors: np.ndarray, n_reference: int
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (3)'s eigenpairs in units of the surface instead of the triangles.

    The paper's ``A`` is proportional to the FEM mass, ``A = c M`` with
    ``c = 15 / mean triangle area``, and its ``L`` is twice the FEM stiffness, so
    ``lambda = 2 lambda_FEM / c``. Here the eigenvalues are ``lambda_FEM`` in the
    time unit of :func:`in_diffusion_time_units`.

    Parameters
    ----------
    op : the paper's operator pair.
    eigenvalues, eigenvectors : its eigenpairs (:func:`laplace_beltrami_eigenpairs`).
    n_reference : vertex count that defines the time unit (the preset's).

    Returns
    -------
    eigenvalues : (k,) float, ``lambda_FEM * area / (15 n_reference)``.
    eigenvectors : (n, k) float, orthonormal in the lumped-area inner product
        (``phi^T M phi = 1``, i.e. in L2 of the surface).
    """
    c = op.fem_scale
    area_eigenvalues = 0.5 * c * eigenvalues * op.total_area  # lambda_FEM * area
    return in_diffusion_time_units(area_eigenvalues, n_reference), eigenvectors * np.sqrt(c)


def normalized_spectrum(op: LaplaceBeltrami, eigenvalues: np.ndarray, size: int) -> np.ndarray:
    """The first ``size`` non-zero eigenvalues, scale-normalized as in ShapeDNA.

    ShapeDNA multiplies the FEM eigenvalues by the surface area. The paper's pair
    (L, A) has ``lambda = lambda_FEM * 2 * mean_area / 5 / 3``, so
    ``lambda_FEM * area = lambda * sum(a_i) / 2``.

    Returns
    -------
    (size,) float
    """
    spectrum: np.ndarray = eigenvalues[1 : size + 1] * (op.mass.sum() / 2.0)
    return spectrum


def averaged_mass_eigenpairs(
    op: LaplaceBeltrami,
    mesh: IntrinsicMesh,
    ops: FEMOperators,
    eigenvalues: np.ndarray,
    eigenvectors: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The Laplace-Beltrami eigenpairs with the averaged mass
    (:func:`.intrinsic.averaged_mass`), as Rayleigh-Ritz pairs in the span of eq. (3)'s.

    With the lumped mass of eq. (3) the 50 eigenvalues of a 2,500-vertex resample of a
    TOSCA figure are a median 1.45% off those of the full-resolution file (0.8-2.7% per
    input, the 50th up to 9%), by amounts that follow the triangulation; with the
    averaged mass 0.91% (0.1-1.6%; ``python -m experiments.spectrum_accuracy``, docs/evaluation.md).
    The eigenvectors of eq. (3) span nearly the same low-frequency space, so the
    averaged-mass pairs are taken as Rayleigh-Ritz pairs in their span (the values
    within 0.2% of a full solve at the 50th of 100; tested) instead of by a second
    eigensolve: ``B^T K B y = mu B^T M B y``, eigenvectors ``B y``. With
    ``B = sqrt(c) Phi``, eq. (3)'s eigenvectors made M-orthonormal
    (:func:`surface_eigenpairs`), ``B^T K B`` is ``diag(lambda_FEM)`` by eq. (3) itself
    (to the eigensolver's residual), so only ``B^T M B`` is formed (tested against
    forming both). The vectors are returned as their coordinates ``y`` in ``B``, the
    basis they share with eq. (3)'s (:func:`worker.engine.modal.small_ddt` needs no
    other).

    Parameters
    ----------
    op : the paper's operator pair.
    mesh, ops : the triangulation and its operators (:func:`.intrinsic.surface_operators`).
    eigenvalues, eigenvectors : (k,), (n, k) float, eq. (3)'s
        (:func:`laplace_beltrami_eigenpairs`).

    Returns
    -------
    eigenvalues : (k,) float, ascending, ``lambda_FEM`` in the mesh's units (the first
        zero, to rounding).
    coordinates : (k, k) float, the eigenvectors ``sqrt(c) Phi @ coordinates``,
        orthonormal in the averaged mass's inner product.
    """
    c = op.fem_scale
    basis = np.sqrt(c) * eigenvectors
    small_mass = basis.T @ (averaged_mass(mesh, ops.face_areas) @ basis)
    values, coordinates = la.eigh(np.diag(0.5 * c * eigenvalues), 0.5 * (small_mass + small_mass.T))
    return values, coordinates


def diffusion_distance_tensor(
    eigenvalues: np.ndarray, eigenvectors: np.ndarray, times: tuple[float, ...]
) -> np.ndarray:
    """The dense DDT of eq. (4) (the reference the low-rank path is tested against).

    Parameters
    ----------
    eigenvalues : (k,) float
    eigenvectors : (n, k) float, A-orthonormal.
    times : diffusion times t_D.

    Returns
    -------
    (n, n, len(times)) float, slice ``[:, :, s]`` is ``d_{times[s]}``.
    """
    slices = []
    for t in times:
        psi = eigenvectors * np.exp(-eigenvalues * t)
        r = np.einsum("ik,ik->i", psi, psi)
        d = r[:, None] + r[None, :] - 2.0 * psi @ psi.T
        np.fill_diagonal(d, 0.0)
        slices.append(np.maximum(d, 0.0))
    return np.stack(slices, axis=2)
