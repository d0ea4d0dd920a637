"""Resampling a surface to a fixed number of vertices.

The modal representation compares matrices of the same size, so every mesh is
brought to the preset's vertex count first (sec. 4.2: 2,500 points for SHREC).

Method: quadric error decimation (Garland-Heckbert, via ``fast_simplification``).
It keeps the shape's features at this density (an earlier measurement on TOSCA
found isotropic remeshing worse for every modality; not repeated here), at the
price of badly shaped triangles; the operators built on the result therefore use
its intrinsic Delaunay triangulation (:mod:`worker.engine.intrinsic`), which makes them
insensitive to triangle shape (measured: docs/engine.md). Meshes with fewer
vertices than the target are first refined by midpoint subdivision, which does not
change the surface.
"""

from __future__ import annotations

import numpy as np

from .mesh_io import Mesh, clean_mesh
from .topology import euler_and_boundary, unique_rows


def _subdivide(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split every triangle into four at its edge midpoints; the surface is unchanged."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    first, edge_index = unique_rows(edges)
    midpoints = vertices[edges[first]].mean(axis=1)
    m = len(faces)
    mid = edge_index.reshape(3, m).T + len(vertices)  # midpoints of edges 01, 12, 20
    a, b, c = faces.T
    ab, bc, ca = mid.T
    new_faces = np.concatenate(
        [
            np.stack([a, ab, ca], axis=1),
            np.stack([ab, b, bc], axis=1),
            np.stack([ca, bc, c], axis=1),
            np.stack([ab, bc, ca], axis=1),
        ]
    )
    return np.concatenate([vertices, midpoints]), new_faces


def resample_mesh(mesh: Mesh, n_vertices: int) -> Mesh:
    """Return a mesh of the same surface with about ``n_vertices`` vertices.

    Parameters
    ----------
    mesh : a cleaned, connected mesh.
    n_vertices : target vertex count. Quadric decimation stops on a face budget,
        so the result can differ from the target by a few vertices on surfaces
        with boundaries or handles; the descriptors are normalized to be
        insensitive to that (see :func:`worker.engine.modal.normalize_slices`).

    Returns
    -------
    Mesh, cleaned again (decimation can leave unreferenced or merged vertices).
    """
    import fast_simplification

    vertices, faces = mesh.vertices, mesh.faces
    while len(vertices) < n_vertices:
        vertices, faces = _subdivide(vertices, faces)
    if len(vertices) == n_vertices:
        return Mesh(vertices=vertices, faces=faces)

    # Euler: F = 2V - 2chi for a closed surface, so aim at the face count that
    # gives n_vertices for this surface's own characteristic and boundary.
    euler, boundary = euler_and_boundary(faces, len(vertices))
    target_faces = max(2 * n_vertices - 2 * euler - boundary, 4)
    reduced_vertices, reduced_faces = fast_simplification.simplify(
        vertices, faces.astype(np.int32), target_count=int(target_faces)
    )
    return clean_mesh(reduced_vertices, reduced_faces)
