"""A sensor's noise: how rough a surface is, whether that is noise, and smoothing it away.

A scanner errs at each sample on its own. That noise crumples the surface (its area grows,
its normals turn): a single view's own object no longer holds it in a rigid fit
(:mod:`.rigid`), and a whole's descriptors move with the area and the geodesics it adds.
Smoothing every surface costs clean scans as much as it gives noisy ones (a filter over a
vertex's ring acts at the triangulation's scale, and a coarse range grid loses its shape),
so a surface is smoothed only when it is rougher than a clean surface is at its own
sampling (:func:`roughness`) and its roughness is noise, not a coarse sampling of a curved
surface (:func:`surface_fits`); a surface that is not one view also only when the
smoothing irons out the area noise adds (:data:`CRUMPLED_KEPT`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .mesh_io import Mesh, face_areas
from .topology import edge_keys

#: Vertices each local fit of :func:`roughness` takes (the sample and its nearest).
ROUGHNESS_NEIGHBOURS = 24
#: Vertices :func:`roughness` fits around (seeded); all of a smaller view's.
ROUGHNESS_SAMPLES = 600
#: A view is smoothed above this roughness (and :data:`NOISE_LIKE`). The partiality
#: protocol's noiseless views and range scans of TOSCA and SCAPE (300 vertices .. full
#: resolution) have a median 0.010 .. 0.018, 4 of 616 above (two coarse views of the wolf,
#: 1,523 and 2,236 vertices, up to 0.074, and two SCAPE range scans of 326 and 361
#: vertices, up to 0.068; none noise-like); with depth noise of 0.25% of the object's
#: diagonal a median 0.087, 2 of 154 under (``python -m experiments.surface_roughness``,
#: v18; docs/evaluation.md; chosen in docs/decisions.md, "Default v16").
ROUGH_VIEW = 0.05
#: A rough view is smoothed only when a cubic fit leaves more than this share of the
#: quadric's residual (each per degree of freedom, :func:`surface_fits`): noise's share is
#: about 1, a smooth surface sampled coarsely leaves less. The protocol's 616 noiseless
#: views and range scans leave 0.42 .. 0.84, its 308 noisy views 0.90 .. 1.04; chosen on
#: TOSCA's or SCAPE's views alone the threshold is 0.868 / 0.899, the latter leaving one
#: of TOSCA's noisy views (0.897) unsmoothed (``python -m experiments.surface_roughness``,
#: v18; docs/evaluation.md; chosen in docs/decisions.md, "Default v17").
NOISE_LIKE = 0.89
#: A surface that is not one view (a whole, a cut or holed copy) is smoothed only when
#: the smoothing leaves it less than this share of its area: noise crumples it at the
#: scale of its vertices, which Taubin's filter irons out (the partiality protocol's
#: ``noise-0.25`` .. ``noise-1`` wholes of TOSCA and SCAPE keep 0.09 .. 0.85), while a
#: coarse noiseless mesh read as rough and noise-like (of the tessellation protocol's
#: decimated files and ``shrec-holes``' fragments) keeps 0.88 .. 0.99, and the tessellation
#: protocol's slight noise (0.1 of an edge) 0.95 .. 0.98. Chosen on TOSCA's copies alone
#: 0.867, on SCAPE's 0.833 (three ``noise-0.25`` wolves of TOSCA, keeping 0.84 .. 0.85, then
#: left as they are) (``python -m experiments.surface_roughness``, docs/decisions.md,
#: "Default v18").
CRUMPLED_KEPT = 0.87
#: The monomials ``x**i y**j`` of :func:`surface_fits`' height fields: a quadric's (in
#: the order :func:`roughness` was measured with), and a cubic's.
QUADRIC_TERMS = ((2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0))
CUBIC_TERMS = (*QUADRIC_TERMS, (3, 0), (2, 1), (1, 2), (0, 3))
#: Steps of Taubin's filter a noisy surface is smoothed by (:func:`taubin_smoothed`).
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
    return surface_fits(vertices)[0]


def surface_fits(vertices: np.ndarray) -> tuple[float, float]:
    """:func:`roughness`, and how much of it is noise: around the same samples, a cubic
    height field's residual over the quadric's, each per degree of freedom left (the
    median; 1 where the cubic leaves no more than noise's share, as a smooth surface's
    higher-order error does not). Both 0 for too few vertices to fit a quadric; the share
    0 for too few to fit a cubic with a degree of freedom to spare, or where every quadric
    fits exactly."""
    points = np.asarray(vertices, dtype=np.float64)
    k = min(ROUGHNESS_NEIGHBOURS, len(points))
    if k <= len(QUADRIC_TERMS):
        return 0.0, 0.0
    rng = np.random.default_rng(0)
    centres = rng.choice(len(points), size=min(ROUGHNESS_SAMPLES, len(points)), replace=False)
    neighbours = points[cKDTree(points).query(points[centres], k=k)[1]]
    offsets = neighbours - neighbours.mean(axis=1, keepdims=True)
    axes = np.linalg.svd(offsets, full_matrices=False)[2]  # (m, 3, 3), rows by spread
    x, y, z = np.moveaxis(offsets @ np.swapaxes(axes, 1, 2), 2, 0)
    tiny = np.finfo(float).tiny
    quadric = _squared_residuals(x, y, z, QUADRIC_TERMS)
    radius = np.sqrt(np.max(x * x + y * y, axis=1))
    relative = float(np.median(np.sqrt(quadric / k) / np.maximum(radius, tiny)))
    if k <= len(CUBIC_TERMS):
        return relative, 0.0
    cubic = _squared_residuals(x, y, z, CUBIC_TERMS)
    fitted = quadric > tiny  # a quadric fitting exactly leaves nothing to share
    if not fitted.any():
        return relative, 0.0
    per_freedom = (cubic[fitted] / (k - len(CUBIC_TERMS))) / (
        quadric[fitted] / (k - len(QUADRIC_TERMS))
    )
    return relative, float(np.median(np.sqrt(per_freedom)))


def _squared_residuals(
    x: np.ndarray, y: np.ndarray, z: np.ndarray, terms: tuple[tuple[int, int], ...]
) -> np.ndarray:
    """(m,) the sum of squared residuals of the least-squares height field ``z`` over the
    monomials ``x**i * y**j`` of ``terms`` around each of m samples ((m, k) each): what
    the projection on the basis's columns (an orthonormal basis of them, by QR) leaves."""
    basis = np.stack([x**i * y**j for i, j in terms], axis=2)
    q = np.linalg.qr(basis)[0]  # (m, k, len(terms))
    fitted = q @ (np.swapaxes(q, 1, 2) @ z[:, :, None])
    squares: np.ndarray = np.sum((z - fitted[:, :, 0]) ** 2, axis=1)
    return squares


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
    """A single view smoothed of its sensor's noise when it is rough (:data:`ROUGH_VIEW`)
    and its roughness is noise (:data:`NOISE_LIKE`), else the view itself."""
    return taubin_smoothed(view) if _rough_with_noise(view) else view


def denoised(mesh: Mesh) -> Mesh:
    """A surface that is not one view smoothed of a sensor's noise when it is rough with
    noise as :func:`view_denoised` reads a view and the smoothing leaves it less than
    :data:`CRUMPLED_KEPT` of its area, else the surface itself."""
    if not _rough_with_noise(mesh):
        return mesh
    smoothed = taubin_smoothed(mesh)
    kept = _area(smoothed) / _area(mesh)
    return smoothed if kept < CRUMPLED_KEPT else mesh


def _rough_with_noise(mesh: Mesh) -> bool:
    rough, noise = surface_fits(mesh.vertices)
    return rough > ROUGH_VIEW and noise > NOISE_LIKE


def _area(mesh: Mesh) -> float:
    return float(face_areas(mesh.vertices, mesh.faces).sum())
