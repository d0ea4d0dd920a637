"""A sensor's noise on a single view: how rough the view is, and smoothing it away.

A depth camera errs at each sample on its own, along its ray. On a view that noise
crumples the surface (its area grows, its normals turn) and the view's own object no
longer holds it in a rigid fit (:mod:`.rigid`). Smoothing every view costs clean scans as
much as it gives noisy ones (a filter over a vertex's ring acts at the triangulation's
scale, and a coarse range grid loses its shape), so a view is smoothed only when it is
rougher than a clean surface is at its own sampling (:func:`roughness`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .mesh_io import Mesh
from .topology import edge_keys

#: Vertices each local fit of :func:`roughness` takes (the sample and its nearest).
ROUGHNESS_NEIGHBOURS = 24
#: Vertices :func:`roughness` fits around (seeded); all of a smaller view's.
ROUGHNESS_SAMPLES = 600
#: A view is smoothed above this roughness. The partiality protocol's noiseless views and
#: range scans of TOSCA and SCAPE (300 vertices .. full resolution) have a median 0.010 ..
#: 0.018, 3 of 616 above (two coarse views of the wolf, 0.063 and 0.074, and a SCAPE range
#: scan of 638 vertices, 0.052); with depth noise of 0.25% of the object's diagonal a
#: median 0.087, 2 of 154 under (``python -m experiments.view_roughness``,
#: docs/decisions.md, "Default v16").
ROUGH_VIEW = 0.05
#: Steps of Taubin's filter a rough view is smoothed by (:func:`taubin_smoothed`).
VIEW_SMOOTHING_STEPS = 10
#: Taubin's two factors, shrinking by ``TAUBIN_SHRINK`` and growing back by
#: ``TAUBIN_GROW`` on alternate steps: equal, so the filter passes no frequency unchanged
#: but damps the highest (a vertex against its neighbours) most (trimesh's defaults).
TAUBIN_SHRINK = 0.5
TAUBIN_GROW = 0.5


def roughness(vertices: np.ndarray) -> float:
    """How far a surface strays from smooth at its own sampling: around each of
    ``ROUGHNESS_SAMPLES`` vertices, the RMS residual of a quadric height field fitted
    (least squares) to its ``ROUGHNESS_NEIGHBOURS`` nearest vertices in their principal
    frame, over their radius in that frame; the median.

    A smooth surface sampled at any density leaves only the quadric's higher-order error
    (about the radius's square times the curvature's change); noise leaves its own
    deviation, large against the spacing of the samples it displaces. Scale-free.

    Parameters
    ----------
    vertices : (n, 3) float.

    Returns
    -------
    The median relative residual; 0 for fewer vertices than a quadric has coefficients.
    """
    points = np.asarray(vertices, dtype=np.float64)
    k = min(ROUGHNESS_NEIGHBOURS, len(points))
    if k <= 6:
        return 0.0
    rng = np.random.default_rng(0)
    centres = rng.choice(len(points), size=min(ROUGHNESS_SAMPLES, len(points)), replace=False)
    neighbours = points[cKDTree(points).query(points[centres], k=k)[1]]
    offsets = neighbours - neighbours.mean(axis=1, keepdims=True)
    axes = np.linalg.svd(offsets, full_matrices=False)[2]  # (m, 3, 3), rows by spread
    x, y, z = np.moveaxis(offsets @ np.swapaxes(axes, 1, 2), 2, 0)
    basis = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=2)
    coefficients = np.linalg.pinv(basis) @ z[:, :, None]
    residual = np.sqrt(np.mean((z - (basis @ coefficients)[:, :, 0]) ** 2, axis=1))
    radius = np.sqrt(np.max(x * x + y * y, axis=1))
    return float(np.median(residual / np.maximum(radius, np.finfo(float).tiny)))


def taubin_smoothed(mesh: Mesh, steps: int = VIEW_SMOOTHING_STEPS) -> Mesh:
    """``mesh`` smoothed by Taubin's filter (Taubin 1995, "A signal processing approach to
    fair surface design"), its faces kept: each step moves every vertex toward (even
    steps, by ``TAUBIN_SHRINK``) or away from (odd steps, ``TAUBIN_GROW``) the mean of its
    neighbours along the edges, so noise is damped without the shrinking of Laplacian
    smoothing. A vertex on no face stays where it is."""
    n = mesh.n_vertices
    keys = np.unique(edge_keys(mesh.faces, n))
    a, b = np.divmod(keys, n)
    adjacency = sp.coo_matrix((np.ones(2 * len(a)), (np.r_[a, b], np.r_[b, a])), shape=(n, n))
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    lonely = degree == 0
    mean = sp.diags(1.0 / np.where(lonely, 1.0, degree)) @ adjacency.tocsr()
    vertices = np.array(mesh.vertices, dtype=np.float64)
    for step in range(steps):
        towards = mean @ vertices - vertices
        towards[lonely] = 0.0
        vertices += (TAUBIN_SHRINK if step % 2 == 0 else -TAUBIN_GROW) * towards
    return Mesh(vertices, mesh.faces)


def view_denoised(view: Mesh) -> Mesh:
    """A single view smoothed of its sensor's noise when it is rough (:data:`ROUGH_VIEW`),
    else the view itself."""
    return taubin_smoothed(view) if roughness(view.vertices) > ROUGH_VIEW else view
