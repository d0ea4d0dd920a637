"""Isotropic remeshing by MeshLab (the robustness protocol's ``remeshed-*`` variants).

Apart from :mod:`.variants` so that the meshes it makes, slow to make and stored
(:class:`.cache.VariantMeshCache`), depend on this code and on reading and cleaning the
file only: an edit of the partial copies keeps them.
"""

from __future__ import annotations

from types import ModuleType
from typing import cast

import numpy as np

from worker.engine.mesh_io import Mesh, clean_mesh, face_areas, tiling_edge

#: Isotropic remeshing: split/collapse/flip/relax/reproject rounds.
REMESH_ITERATIONS = 10


def import_pymeshlab(purpose: str) -> ModuleType:
    """MeshLab's Python module, an optional dependency of the evaluation harness (the
    ``eval`` extra).

    Raises
    ------
    RuntimeError
        When it is not installed; the message names ``purpose`` and the extra.
    """
    try:
        import pymeshlab
    except ImportError as exc:
        raise RuntimeError(f"{purpose} needs pymeshlab: pip install 'modalshape[eval]'") from exc
    # pymeshlab ships no types: mypy sees the module as Any.
    return cast(ModuleType, pymeshlab)


def remeshed(mesh: Mesh, n_vertices: int) -> Mesh:
    """Isotropic remeshing (Botsch & Kobbelt 2004, MeshLab's filter) to about ``n_vertices``.

    The target edge length is the side of the equilateral triangle that tiles the
    surface's area with ``2 n_vertices`` triangles; MeshLab reprojects vertices onto
    the input surface and refuses collapses that leave it. Its results land at 1.0 to
    1.35 times ``n_vertices`` on TOSCA. (gpytoolbox's remesher, used before, lost up
    to 7% of the area on thin parts and moved the first eigenvalues by up to 35%:
    another surface, not another tessellation; docs/evaluation.md.)
    """
    pymeshlab = import_pymeshlab("isotropic remeshing")
    edge = tiling_edge(float(face_areas(mesh.vertices, mesh.faces).sum()), n_vertices)
    meshes = pymeshlab.MeshSet()
    meshes.add_mesh(pymeshlab.Mesh(mesh.vertices, mesh.faces.astype(np.int32)))
    meshes.meshing_isotropic_explicit_remeshing(
        iterations=REMESH_ITERATIONS, targetlen=pymeshlab.PureValue(float(edge))
    )
    result = meshes.current_mesh()
    return clean_mesh(result.vertex_matrix(), result.face_matrix())
