"""Geodesic distance matrix (GDM, sec. 2.1) by the heat method.

The paper solves the Eikonal equation (eq. 1) by fast marching. We use the heat
method (Crane, Weischedel & Wardetzky 2013) on the intrinsic Delaunay
triangulation, which solves the same problem with two sparse linear systems:

1. heat flow ``(M + t L) u = delta_s`` for a short time ``t = h^2`` (longer on
   very long, thin surfaces, see :class:`HeatMethod`),
2. the unit field ``X = -grad u / |grad u|`` points along geodesics,
3. ``L phi = div X`` recovers the distance ``phi`` up to a constant.

Both systems are factored once per mesh (banded Cholesky, :mod:`worker.engine.linalg`)
and solved for a whole block of sources at once; the result is symmetrized, since
the exact GDM is symmetric. :func:`geodesic_distances_reference` is the plain
per-source version with SuperLU that the fast path is tested against.

The surface presets need distances only from a few hundred sources spread evenly
over the surface (:func:`farthest_point_samples`, :func:`sample_distances`): the
modal representation of the surface's distance operator integrates over them with
their Voronoi areas as weights (:mod:`worker.engine.modal`).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from scipy.sparse.csgraph import dijkstra

from .intrinsic import FEMOperators, IntrinsicMesh
from .linalg import BandedCholesky, band_ordering
from .tol import TOL
from .topology import edge_keys

SOURCE_BLOCK = 1024

#: Past this bandwidth (after reverse Cuthill-McKee) the banded factor loses to SuperLU,
#: whose fill does not grow with a vertex's valence: TOSCA's resamples reach 238 (the
#: banded solves as fast as SuperLU at cat0's 216, twice as fast at michael0's 98), a
#: CAD cylinder's cap fan of 2,048 triangles 4,082 (18.5 s banded, 0.75 s SuperLU).
MAX_BANDWIDTH = 500


def heat_time(
    mesh: IntrinsicMesh, ops: FEMOperators, factor: float, n_reference: int | None = None
) -> float:
    """The heat step's time: ``factor`` squared edge lengths.

    Crane et al. take ``t = h^2`` with ``h`` the mesh's mean edge length, which
    gives the most accurate distances on that mesh; a larger ``t`` gives smoother
    ones (their sec. 3.2). With ``n_reference``, ``h`` is instead the edge of the
    equilateral triangulation of the same area with ``n_reference`` vertices
    (``2 n`` triangles: ``h^2 = 2 area / (sqrt(3) n)``), a length of the surface
    that no tessellation changes.

    Returns
    -------
    float, in squared length units.
    """
    if n_reference is None:
        return factor * mesh.mean_edge_length**2
    return factor * 2.0 * float(ops.face_areas.sum()) / (math.sqrt(3.0) * n_reference)


def diameter_bound(mesh: IntrinsicMesh) -> float:
    """An upper bound of the surface's geodesic diameter: twice the eccentricity of
    vertex 0 on the edge graph (graph paths are never shorter than geodesics)."""
    # Each interior edge is listed by both its faces: keep one copy (a sparse matrix
    # would add the two lengths).
    _, first = np.unique(edge_keys(mesh.faces, mesh.n_vertices).ravel(), return_index=True)
    edges = mesh.faces[:, [1, 2, 2, 0, 0, 1]].reshape(-1, 2)[first]
    graph = sp.csr_matrix(
        (mesh.lengths.ravel()[first], (edges[:, 0], edges[:, 1])),
        shape=(mesh.n_vertices, mesh.n_vertices),
    )
    reach = dijkstra(graph, directed=False, indices=np.array([0]))[0]
    return 2.0 * float(np.max(reach[np.isfinite(reach)]))


class HeatMethod:
    """Factored heat-method solver for one mesh.

    Parameters
    ----------
    mesh : intrinsic triangulation (its Delaunay one gives the best accuracy).
    ops : the mesh's finite-element operators.
    time_factor : heat time in squared edge lengths (see :func:`heat_time`).
    n_reference : count edge lengths on the surface rather than on this mesh
        (see :func:`heat_time`).
    reference : solve with SuperLU in double precision throughout (the plain
        version the fast path is tested against). The fast path factors both
        systems with :class:`BandedCholesky` and runs the Poisson step in single
        precision: its input is a unit vector field and its output a distance, both
        of order one. A mesh whose band stays wider than :data:`MAX_BANDWIDTH` (a
        vertex with hundreds of neighbours, such as a CAD cap's fan centre) takes the
        reference path instead.

    Notes
    -----
    One backward-Euler heat step decays like ``exp(-d / sqrt(t))`` with the distance
    ``d`` from the source. On a long thin surface (a helical spring of wire at 2,500
    vertices is 700 edge lengths long) ``u`` underflows to zero far from the source
    with ``t = h^2``, the unit field loses its direction there and the distances
    become meaningless: the time is therefore never shorter than keeps
    ``diameter / sqrt(t)`` below ``TOL.heat_max_decay`` (on ordinary shapes that
    bound is far below ``h^2`` and changes nothing). When the decay stays within
    ``TOL.heat_max_decay_single`` (the surface presets' longer times), ``u`` fits
    single precision too and the fast path runs the heat step in it as well.
    """

    def __init__(
        self,
        mesh: IntrinsicMesh,
        ops: FEMOperators,
        time_factor: float = 1.0,
        n_reference: int | None = None,
        reference: bool = False,
    ):
        self.n = mesh.n_vertices
        diameter = diameter_bound(mesh)
        t = max(
            heat_time(mesh, ops, time_factor, n_reference), (diameter / TOL.heat_max_decay) ** 2
        )
        mass = sp.diags(ops.vertex_areas)
        heat = (mass + t * ops.stiffness).tocsc()
        # L is singular (constants); a tiny mass term makes it definite and only
        # shifts phi by a constant, which the source normalization removes.
        eps = TOL.poisson_regularization * ops.stiffness.diagonal().mean() / ops.vertex_areas.mean()
        poisson = (ops.stiffness + eps * mass).tocsc()
        # Either solver answers solve(b) for a block of right-hand sides.
        self._heat: sla.SuperLU | BandedCholesky
        self._poisson: sla.SuperLU | BandedCholesky
        order, bandwidth = band_ordering(heat) if not reference else (None, 0)
        if reference or bandwidth > MAX_BANDWIDTH:
            self._heat, self._poisson = sla.splu(heat), sla.splu(poisson)
            self._gradient, self._divergence = ops.gradient, ops.divergence
        else:
            single = diameter / np.sqrt(t) <= TOL.heat_max_decay_single
            heat_dtype = np.float32 if single else np.float64
            self._heat = BandedCholesky(heat, dtype=heat_dtype, order=order)
            # Both systems have the sparsity of the stiffness matrix: one ordering.
            self._poisson = BandedCholesky(poisson, dtype=np.float32, order=order)
            self._gradient = ops.gradient.astype(heat_dtype)
            self._divergence = ops.divergence.astype(np.float32)

    def distances_from(self, sources: np.ndarray) -> np.ndarray:
        """Geodesic distances from each source to every vertex.

        Parameters
        ----------
        sources : (s,) int vertex indices.

        Returns
        -------
        (n, s) float (float32 on the fast path, whose Poisson step is single
        precision), column ``c`` holds the distances from ``sources[c]``.
        """
        sources = np.asarray(sources, dtype=np.int64)
        rhs = np.zeros((self.n, len(sources)))
        rhs[sources, np.arange(len(sources))] = 1.0
        u = self._heat.solve(rhs)
        g = self._gradient @ u  # (2m, s): x components of all faces, then y
        m = len(g) // 2
        gx, gy = g[:m], g[m:]
        # hypot, not sqrt(x^2 + y^2): far from a source the gradient can be below
        # 1e-154, whose square underflows and would turn the unit field into 1e150s.
        # A face where u is flat to the last bit has no direction; it stays zero.
        length = np.hypot(gx, gy)
        np.divide(-1.0, length, out=length, where=length > 0)
        gx *= length
        gy *= length
        phi = self._poisson.solve(self._divergence @ g.astype(self._divergence.dtype, copy=False))
        phi -= phi[sources, np.arange(len(sources))]
        distances: np.ndarray = np.maximum(phi, 0.0, out=phi)
        return distances


def _distance_columns(solver: HeatMethod, sources: np.ndarray) -> np.ndarray:
    """``solver.distances_from(sources)``, one block of ``SOURCE_BLOCK`` sources at a
    time (a block's right-hand sides stay in cache; all at once is slower)."""
    columns = np.empty((solver.n, len(sources)), dtype=np.float32)
    for start in range(0, len(sources), SOURCE_BLOCK):
        stop = min(start + SOURCE_BLOCK, len(sources))
        columns[:, start:stop] = solver.distances_from(sources[start:stop])
    return columns


def geodesic_distance_matrix(
    mesh: IntrinsicMesh,
    ops: FEMOperators,
    time_factor: float = 1.0,
    n_reference: int | None = None,
) -> np.ndarray:
    """All-pairs geodesic distances (the GDM of sec. 2.1).

    Parameters
    ----------
    mesh, ops : intrinsic triangulation and its operators.
    time_factor, n_reference : the heat step's time (:func:`heat_time`).

    Returns
    -------
    (n, n) float32, symmetric with zero diagonal, in the mesh's length unit (single
    precision, as the Poisson step that makes it: 2,500 vertices take 25 MB).
    """
    n = mesh.n_vertices
    gdm = sample_distances(mesh, ops, np.arange(n), time_factor, n_reference)
    # Symmetrize block by block: gdm += gdm.T would copy the whole transpose first.
    for start in range(0, n, SOURCE_BLOCK):
        rows = slice(start, min(start + SOURCE_BLOCK, n))
        upper = 0.5 * (gdm[rows, start:] + gdm[start:, rows].T)
        gdm[rows, start:] = upper
        gdm[start:, rows] = upper.T
    np.fill_diagonal(gdm, 0.0)
    return gdm


def farthest_point_samples(vertices: np.ndarray, count: int, mass: np.ndarray) -> np.ndarray:
    """``count`` vertices spread evenly over the surface, by farthest-point sampling.

    Each next sample is the vertex farthest (in space) from all samples so far,
    starting from the vertex farthest from the area-weighted centroid, so the choice
    follows the surface rather than the vertex order or density. Straight-line
    distance is enough to spread the samples: the quadrature weights that make them
    a discretization of the surface are their geodesic Voronoi areas
    (:func:`worker.engine.modal.voronoi_areas`).

    Parameters
    ----------
    vertices : (n, 3) float
    count : number of samples; all vertices when ``count >= n``.
    mass : (n,) float, lumped vertex areas (for the centroid).

    Returns
    -------
    (min(count, n),) int vertex indices, in the order they were chosen.
    """
    n = len(vertices)
    if count >= n:
        return np.arange(n)
    centroid = mass @ vertices / mass.sum()
    samples = np.empty(count, dtype=np.int64)
    samples[0] = np.argmax(np.einsum("ij,ij->i", vertices - centroid, vertices - centroid))
    # Squared distances coordinate by coordinate into preallocated arrays: a third of
    # the time of an (n, 3) difference per sample, the same sums in the same order.
    coordinates = np.ascontiguousarray(vertices.T)
    nearest = np.full(n, np.inf)
    squared, term = np.empty(n), np.empty(n)
    for i in range(1, count):
        squared.fill(0.0)
        for axis, value in zip(coordinates, vertices[samples[i - 1]], strict=True):
            np.subtract(axis, value, out=term)
            term *= term
            squared += term
        np.minimum(nearest, squared, out=nearest)
        samples[i] = np.argmax(nearest)
    return samples


def sample_distances(
    mesh: IntrinsicMesh,
    ops: FEMOperators,
    samples: np.ndarray,
    time_factor: float = 1.0,
    n_reference: int | None = None,
) -> np.ndarray:
    """Geodesic distances from a set of sample vertices to every vertex.

    Parameters
    ----------
    mesh, ops : intrinsic triangulation and its operators.
    samples : (m,) int vertex indices (:func:`farthest_point_samples`).
    time_factor, n_reference : the heat step's time (:func:`heat_time`).

    Returns
    -------
    (n, m) float32, column ``c`` holds the distances from ``samples[c]`` (zero there).
    """
    solver = HeatMethod(mesh, ops, time_factor, n_reference)
    return _distance_columns(solver, np.asarray(samples, dtype=np.int64))


def geodesic_distances_reference(
    mesh: IntrinsicMesh, ops: FEMOperators, time_factor: float = 1.0
) -> np.ndarray:
    """The same GDM, one source at a time with SuperLU: the plain reference."""
    solver = HeatMethod(mesh, ops, time_factor, reference=True)
    n = mesh.n_vertices
    gdm: np.ndarray = np.column_stack(
        [solver.distances_from(np.array([s]))[:, 0] for s in range(n)]
    )
    gdm = 0.5 * (gdm + gdm.T)
    np.fill_diagonal(gdm, 0.0)
    return gdm
