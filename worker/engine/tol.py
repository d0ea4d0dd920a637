"""Numerical tolerances of the descriptor engine, kept in one place."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tolerances:
    # Vertices closer than this fraction of the bounding-box diagonal are merged.
    merge_fraction: float = 1e-9
    # Faces with area below this fraction of the mean face area are dropped.
    degenerate_area_fraction: float = 1e-12
    # Coordinates above this magnitude overflow squared lengths and areas.
    max_abs_coordinate: float = 1e100
    # A surface is refused when more than this fraction of its faces touch an edge
    # shared by three or more faces (a stray one or two in a scan are tolerated).
    max_non_manifold_face_fraction: float = 0.01
    # Every triangle keeps its triangle inequality by this fraction of the mean edge
    # length (intrinsic mollification; robust-laplacian's default).
    mollify_fraction: float = 1e-5
    # An interior edge is flipped when cot(alpha) + cot(beta) < -delaunay_slack.
    delaunay_slack: float = 1e-9
    # Shift of the shift-invert eigensolver, relative to Weyl's estimate of lambda_1.
    eigen_shift: float = 1e-3
    # ARPACK's relative residual for the eigenpairs (0 would be machine precision):
    # the eigenvalues stay within 5e-15 and the DDT within 1.3e-9 of the converged
    # ones, in 9% less time (TOSCA, k = 100).
    eigen_residual: float = 1e-10
    # Relative eigenvalue of a Gram matrix below which a direction is numerically absent.
    basis_rank: float = 1e-12
    # Columns whose Gram matrix is within this of the identity (element-wise) are an
    # orthonormal basis as they are (ARPACK's eigenvectors are, to about 4e-15).
    orthonormal: float = 1e-10
    # Singular values of a DDT slice below this fraction of the slice's largest are
    # rounding (a symmetric eigensolve is accurate to about 2e-16 of the largest): they
    # are raised to it, so that eq. (8)'s relative differences compare them as equal.
    # On TOSCA at 2,500 vertices the smallest kept value is 1.1e-8 of its slice's
    # largest; a 500-vertex resample's longest times reach 1e-17.
    slice_value_floor: float = 1e-12
    # Regularization of the singular Poisson system of the heat method, relative.
    poisson_regularization: float = 1e-9
    # Largest diameter / sqrt(heat time): the heat step decays like exp(-d / sqrt(t)),
    # and exp(-400) = 1e-174 leaves room above float64's smallest normal number.
    heat_max_decay: float = 400.0
    # The same bound under which the heat step fits single precision (exp(-60) =
    # 9e-27, above float32's smallest normal 1e-38 with room for the gradient).
    heat_max_decay_single: float = 60.0
    # A geodesic ball's area over pi r^2 is floored here before its logarithm: the
    # parts modality's profiles stay finite where a thin part's ball saturates.
    parts_ratio_floor: float = 1e-3
    # Rigid verification: a voxel whose unit normals sum to less than this times their
    # count has none (they cancel); a point pair whose line is within this sine of its
    # source's normal has no Darboux frame; ICP stops at a step below this.
    cancelled_normals: float = 1e-9
    parallel_sine: float = 1e-12
    icp_step: float = 1e-9
    # A stored grid at most this much finer than the anchors' is used as it is.
    grid_match: float = 1e-6


TOL = Tolerances()
