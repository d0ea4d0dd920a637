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
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from .intrinsic import FEMOperators
from .tol import TOL


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

    def shift(self) -> float:
        """A small negative shift that makes ``L - shift * A`` positive definite."""
        return -TOL.eigen_shift * float(np.mean(self.laplacian.diagonal() / self.mass))


def laplace_beltrami_eigenpairs(op: LaplaceBeltrami, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of eq. (3), by sparse shift-invert Lanczos (ARPACK).

    (A block-Krylov solver on the banded factorization was tried and was no faster
    at k = 150, n = 2,500 once it was accurate enough; see docs/benchmarks.md.)

    Returns
    -------
    eigenvalues : (k,) float, ascending; the first is 0 (constant eigenvector).
    eigenvectors : (n, k) float, A-orthonormal.
    """
    values, vectors = sla.eigsh(
        op.laplacian.tocsc(),
        k=k,
        M=sp.diags(op.mass).tocsc(),
        sigma=op.shift(),
        which="LM",
        v0=seeded_start(op.n),
    )
    order = np.argsort(values)
    return values[order], vectors[:, order]


def seeded_start(n: int) -> np.ndarray:
    """A fixed Lanczos start vector, so the same mesh always gives the same bits."""
    return np.random.default_rng(0).standard_normal(n)


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
