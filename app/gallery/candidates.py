"""Candidate transforms: the vector faiss holds per modality, fixed between refits.

D2: ``t(x) = P^T (x / sigma_fit - mu)``; D1: ``t(x) = P^T (log max(x, floor) - mu)``
(eq. 8's terms are ``2 tanh(|log a - log b| / 2)``). ``P`` is orthonormal, so a
projected D2 distance never exceeds the whitened one: it is a lower bound.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import faiss
import numpy as np

MAX_DIMS = 64  # columns of the candidate projection per modality
FIT_SAMPLE = 5_000  # rows used to fit a projection (any orthonormal P keeps the bound)
_CHUNK = 8192  # rows transformed at once: bounded temporary memory


@dataclass
class CandidateTransform:
    """Candidate transform of one modality and the faiss index of the transformed gallery.

    Attributes
    ----------
    log : D1 (compare logarithms) rather than D2 (compare whitened values).
    mu : (M,) shift (mean of the scaled vectors, or of their logarithms for D1).
    scale : (M,) divisor before projecting (sigma at the fit for D2, 1 for D1).
    floor : (M,) D1 only: values are clipped here before the logarithm.
    projection : (M, r) orthonormal columns.
    index : faiss ``IndexIDMap2`` over the transformed gallery, by shape id.
    """

    log: bool
    mu: np.ndarray
    scale: np.ndarray
    floor: np.ndarray
    projection: np.ndarray
    index: faiss.Index = field(repr=False)

    @classmethod
    def fit(cls, rows: np.ndarray, *, log: bool, max_dims: int = MAX_DIMS) -> CandidateTransform:
        """Fit on ``rows`` ((n, M) float, a sample of the gallery); the faiss index is empty."""
        dim = rows.shape[1]
        if not log:
            floor = np.zeros(dim)
            std = rows.std(axis=0) if len(rows) else np.ones(dim)
            scale = np.where(std > 0, std, 1.0)
            t = rows / scale
        else:
            positive = np.where(rows > 0, rows, np.nan)
            with np.errstate(all="ignore"):
                typical = np.nanmedian(positive, axis=0) if len(rows) else np.ones(dim)
            typical = np.where(np.isfinite(typical), typical, 1.0)
            floor = 1e-6 * typical
            scale = np.ones(dim)
            t = np.log(np.maximum(rows, floor))
        mu = t.mean(axis=0) if len(t) else np.zeros(dim)
        r = min(dim, max_dims)
        if r == dim:
            projection = np.eye(dim)
        else:
            centred = t - mu
            basis = principal_directions(centred, r) if len(centred) >= 2 else np.zeros((dim, 0))
            if basis.shape[1] < r:  # tiny galleries: complete with an orthonormal basis
                q, _ = np.linalg.qr(
                    np.concatenate([basis, np.random.default_rng(1).normal(size=(dim, r))], 1)
                )
                basis = q[:, :r]
            projection = basis
        index = faiss.IndexIDMap2(faiss.IndexFlatL2(projection.shape[1]))
        return cls(log=log, mu=mu, scale=scale, floor=floor, projection=projection, index=index)

    def transform(self, x: np.ndarray) -> np.ndarray:
        """(p, M) float -> (p, r) float32, what faiss compares."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        t = np.log(np.maximum(x, self.floor)) if self.log else x / self.scale
        return np.ascontiguousarray((t - self.mu) @ self.projection, dtype=np.float32)

    def transform_into(self, out: np.ndarray, rows: np.ndarray, ids: np.ndarray) -> None:
        """Transform every row into ``out[:len(rows)]`` and add them to faiss under ``ids``."""
        if not len(rows):
            return
        for start in range(0, len(rows), _CHUNK):
            stop = min(start + _CHUNK, len(rows))
            out[start:stop] = self.transform(rows[start:stop])
        self.index.add_with_ids(out[: len(rows)], ids[: len(rows)])


def principal_directions(centred: np.ndarray, r: int, oversample: int = 16) -> np.ndarray:
    """(M, <=r) orthonormal top principal directions of centred rows (randomized SVD,
    Halko et al. 2011, two power iterations): a full SVD of 5,000 x 2,000 took
    tens of seconds on a busy 2-core machine, this takes well under one."""
    n, dim = centred.shape
    width = min(r + oversample, n, dim)
    rng = np.random.default_rng(0)
    sample = centred @ rng.normal(size=(dim, width))
    for _ in range(2):
        sample, _ = np.linalg.qr(sample)
        sample, _ = np.linalg.qr(centred @ (centred.T @ sample))
    basis_rows = sample.T @ centred  # (width, M): the rows' content in that subspace
    _, _, vt = np.linalg.svd(basis_rows, full_matrices=False)
    return vt[: min(r, len(vt))].T
