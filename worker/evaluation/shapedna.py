"""ShapeDNA (Reuter, Wolter, Peinecke 2006) through ``lapy``: the evaluation's baseline.

This is the retrieval descriptor a user would otherwise reach for, used the way
lapy's own code and documentation use it (``lapy.shapedna``):

1. ``compute_shapedna(mesh, k=50)``: the ``k`` smallest eigenvalues of the
   Laplace-Beltrami operator (linear FEM, consistent mass matrix), the zero
   eigenvalue of a closed surface included;
2. ``normalize_ev(mesh, evals, method="geometry")``: multiplied by the surface
   area, which makes them scale invariant for a triangle mesh;
3. ``reweight_ev(evals)``: eigenvalue ``i`` (1-based) divided by ``i``;
4. ``compute_distance(a, b, dist="euc")``: Euclidean distance.

Nothing here is tuned: every parameter is lapy's default.
"""

from __future__ import annotations

import io
import time
from dataclasses import dataclass

import numpy as np
from lapy import TriaMesh
from lapy.shapedna import compute_distance, compute_shapedna, normalize_ev, reweight_ev

#: Number of eigenvalues, lapy's default for ``compute_shapedna``.
SHAPEDNA_K = 50
#: The baseline's name: its report row and its cache entries.
BASELINE = "shapedna"


@dataclass
class ShapeDNA:
    """The ShapeDNA of one surface.

    Attributes
    ----------
    eigenvalues : (k,) float, raw Laplace-Beltrami eigenvalues, ascending.
    area : float, surface area (squared length units).
    descriptor : (k,) float, ``eigenvalues * area / (1, 2, ..., k)``, the vector compared.
    vertices : number of mesh vertices it was computed on.
    seconds : wall time of the computation.
    """

    eigenvalues: np.ndarray
    area: float
    descriptor: np.ndarray
    vertices: int
    seconds: float = 0.0

    def to_npz_bytes(self) -> bytes:
        buffer = io.BytesIO()
        np.savez(
            buffer,
            eigenvalues=self.eigenvalues,
            area=np.float64(self.area),
            descriptor=self.descriptor,
            vertices=np.int64(self.vertices),
            seconds=np.float64(self.seconds),
        )
        return buffer.getvalue()

    @classmethod
    def from_npz_bytes(cls, data: bytes) -> ShapeDNA:
        with np.load(io.BytesIO(data)) as npz:
            return cls(
                eigenvalues=np.array(npz["eigenvalues"]),
                area=float(npz["area"]),
                descriptor=np.array(npz["descriptor"]),
                vertices=int(npz["vertices"]),
                seconds=float(npz["seconds"]),
            )


def shapedna(vertices: np.ndarray, faces: np.ndarray, k: int = SHAPEDNA_K) -> ShapeDNA:
    """Compute lapy's normalized, reweighted ShapeDNA of a triangle surface.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int, indices into ``vertices``.
    k : number of eigenvalues (lapy's default 50); needs ``n > k``.

    Returns
    -------
    ShapeDNA
    """
    start = time.perf_counter()
    # No orient_(): neither the FEM eigenvalues nor the area depend on orientation,
    # and lapy refuses to orient the non-manifold edges decimation can leave.
    mesh = TriaMesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))
    evals = np.asarray(compute_shapedna(mesh, k=k)["Eigenvalues"], dtype=np.float64)
    descriptor = reweight_ev(normalize_ev(mesh, evals, method="geometry"))
    return ShapeDNA(
        eigenvalues=evals,
        area=float(mesh.area()),
        descriptor=np.asarray(descriptor, dtype=np.float64),
        vertices=len(mesh.v),
        seconds=time.perf_counter() - start,
    )


def shapedna_dissimilarity(descriptors: np.ndarray) -> np.ndarray:
    """All-to-all ShapeDNA distances with lapy's ``compute_distance(..., dist="euc")``.

    Parameters
    ----------
    descriptors : (n, k) float, ``ShapeDNA.descriptor`` of each object.

    Returns
    -------
    (n, n) float, symmetric, zero diagonal.
    """
    x = np.atleast_2d(np.asarray(descriptors, dtype=np.float64))
    n = len(x)
    out = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            out[i, j] = out[j, i] = compute_distance(x[i], x[j], dist="euc")
    return out
