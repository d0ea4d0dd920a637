"""Candidate transforms: the vector faiss holds per modality, fixed between refits.

D2: ``t(x) = P^T (x / sigma_fit - mu)``; D1 (and the size's): ``t(x) = P^T (log max(x,
floor) - mu)`` (eq. 8's terms are ``2 tanh(|log a - log b| / 2)``); ShapeDNA's reweighted
Euclidean distance: ``t(x) = P^T (x / w - mu)`` with its fixed weights ``w``. ``P`` is
orthonormal, so a projected D2 distance never exceeds the whitened one: it is a lower
bound.

faiss index: an exact scan (``IndexFlatL2``) below ``IVF_MIN_SHAPES``; above, an
inverted file (``IndexIVFFlat``: k-means cells, the query's ``IVF_PROBES`` nearest
cells scanned), trained on the transformed gallery at every refit. IVF rather than
HNSW: it supports deletion (a gallery shrinks) and builds in seconds, not minutes,
at a million shapes (``benchmarks/index.py``, ``docs/benchmarks.md``). Its
candidate distances are exact L2 of the transformed vectors, but a shape in an
unprobed cell is missed, so certificates (:mod:`.index`) hold only for what was
scanned; recall@10 at a million shapes is measured instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import faiss
import numpy as np

from worker.engine.compare import spectrum_weights
from worker.engine.presets import REWEIGHTED

MAX_DIMS = 64  # columns of the candidate projection per modality
FIT_SAMPLE = 5_000  # rows used to fit a projection (any orthonormal P keeps the bound)
_CHUNK = 8192  # rows transformed at once: bounded temporary memory
IVF_MIN_SHAPES = 200_000  # from here on an inverted file beats the exact scan
IVF_SHAPES_PER_CELL = 4_000  # cells = gallery size / this (256 at a million shapes)
IVF_PROBES = 16  # cells scanned per search
IVF_TRAIN_PER_CELL = 64  # k-means training rows per cell
IVF_TRAIN_ITERATIONS = 10


@dataclass
class CandidateTransform:
    """Candidate transform of one modality and the faiss index of the transformed gallery.

    Attributes
    ----------
    comparison : the modality's (:meth:`~worker.engine.presets.Preset.comparison`); all
        but D2 and ShapeDNA's compare logarithms.
    mu : (M,) shift (mean of the scaled vectors, or of their logarithms for D1).
    scale : (M,) divisor before projecting (sigma at the fit for D2, ShapeDNA's weights
        for its comparison, 1 for D1).
    floor : (M,) D1 only: values are clipped here before the logarithm.
    projection : (M, r) orthonormal columns.
    index : faiss ``IndexIDMap2`` over the transformed gallery, by shape id.
    """

    comparison: str
    mu: np.ndarray
    scale: np.ndarray
    floor: np.ndarray
    projection: np.ndarray
    index: faiss.Index = field(repr=False)

    @property
    def log(self) -> bool:
        """Logarithms are compared (eq. 8's modalities)."""
        return self.comparison not in ("D2", REWEIGHTED)

    @classmethod
    def fit(
        cls,
        rows: np.ndarray,
        *,
        comparison: str,
        max_dims: int = MAX_DIMS,
        gallery_size: int = 0,
    ) -> CandidateTransform:
        """Fit on ``rows`` ((n, M) float, a sample of the gallery) for the modality's
        ``comparison``; the faiss index is empty (an inverted file, untrained, when
        ``gallery_size`` reaches ``IVF_MIN_SHAPES``)."""
        dim = rows.shape[1]
        if comparison == REWEIGHTED:
            floor, scale = np.zeros(dim), spectrum_weights(dim)
            t = rows / scale
        elif comparison == "D2":
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
        index = _empty_index(projection.shape[1], gallery_size)
        return cls(
            comparison=comparison,
            mu=mu,
            scale=scale,
            floor=floor,
            projection=projection,
            index=index,
        )

    def transform(self, x: np.ndarray) -> np.ndarray:
        """(p, M) float -> (p, r) float32, what faiss compares."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        t = np.log(np.maximum(x, self.floor)) if self.log else x / self.scale
        return np.ascontiguousarray((t - self.mu) @ self.projection, dtype=np.float32)

    def transform_into(self, out: np.ndarray, rows: np.ndarray, ids: np.ndarray) -> None:
        """Transform every row into ``out[:len(rows)]`` and add them to faiss under ``ids``
        (training an inverted file on them first)."""
        n = len(rows)
        if not n:
            return
        for start in range(0, n, _CHUNK):
            stop = min(start + _CHUNK, n)
            out[start:stop] = self.transform(rows[start:stop])
        if not self.index.is_trained:
            cells = faiss.extract_index_ivf(self.index).nlist
            size = min(n, IVF_TRAIN_PER_CELL * cells)
            sample = np.sort(np.random.default_rng(0).choice(n, size, replace=False))
            self.index.train(out[sample])
        self.index.add_with_ids(out[:n], ids[:n])


def _empty_index(dim: int, gallery_size: int) -> faiss.Index:
    """An exact scan for ordinary galleries; an (untrained) inverted file for large ones."""
    if gallery_size < IVF_MIN_SHAPES:
        return faiss.IndexIDMap2(faiss.IndexFlatL2(dim))
    cells = max(1, gallery_size // IVF_SHAPES_PER_CELL)
    index = faiss.IndexIVFFlat(faiss.IndexFlatL2(dim), dim, cells)
    index.cp.niter = IVF_TRAIN_ITERATIONS
    # Deletions look ids up in a hash table instead of scanning every cell.
    # attr-defined: faiss's stubs lack the DirectMap enum its module has.
    index.set_direct_map_type(faiss.DirectMap.Hashtable)  # type: ignore[attr-defined]
    return searchable(index)


def searchable(index: faiss.Index) -> faiss.Index:
    """Set the search parameters a faiss file does not keep (an inverted file's probes)."""
    ivf = faiss.try_extract_index_ivf(index)
    if ivf is not None:
        ivf.nprobe = IVF_PROBES
    return index


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
