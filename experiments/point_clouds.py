"""What a point cloud cannot tell: which nearby points are joined.

    OPENBLAS_NUM_THREADS=1 python -m experiments.point_clouds

A point cloud of a surface's vertices has lost its edges. Where two sheets of a surface
pass closer than a few sample spacings (a hand on a thigh, touching legs, a tail along a
flank), an operator built from the points alone (a point-cloud Laplacian, local
triangulations, a reconstruction) joins them; where the sampling is coarse or uneven it
has too few neighbours to find the surface. Either moves every whole modality (the GDM,
the DDT, the spectrum). For every TOSCA mesh: the share of vertex pairs closer than 3
median edge lengths in space whose path along the mesh's edges is longer than 15 (from
up to 300 vertices of such pairs, seed 0); and, for the first mesh of each class, the 10
lowest nonzero eigenvalues of robust-laplacian's point-cloud operator (Sharp & Crane
2020) on the file's vertices against the file's own (intrinsic Delaunay, averaged mass,
the same vertices), ``|lambda_points / lambda_mesh - 1|``: the median and the largest.
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.sparse.linalg as sla
import trimesh
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from benchmarks.common import TOSCA, first_of_each_class, full_resolution_spectra, tosca_labels
from worker.engine.mesh_io import Mesh, canonical_frame, face_areas, load_mesh
from worker.evaluation.partial import edge_graph

NEAR, FAR, SOURCES, EIGENVALUES = 3.0, 15.0, 300, 10
ONE_SPACING, SPACING_SOURCES = 1.0, 1000


class Contacts:
    """A mesh's edge graph and vertex tree, built once for :meth:`joined_pairs`."""

    def __init__(self, mesh: Mesh) -> None:
        self.graph = edge_graph(mesh)
        self.edge = float(np.median(self.graph.data))
        self.tree = cKDTree(mesh.vertices)
        self.n_vertices = mesh.n_vertices

    def joined_pairs(self, near: float, sources: int) -> tuple[np.ndarray, np.ndarray]:
        """Vertex pairs within ``near`` median edge lengths in space (sampled from up to
        ``sources`` of their vertices, seed 0): (p, 2) the pairs and (p,) bool, those more
        than ``FAR`` apart along the edges."""
        pairs = self.tree.query_pairs(near * self.edge, output_type="ndarray")
        starts = np.unique(pairs[:, 0])
        rng = np.random.default_rng(0)
        chosen = rng.choice(starts, min(sources, len(starts)), replace=False)
        along = dijkstra(self.graph, directed=False, indices=chosen, limit=2 * FAR * self.edge)
        row = np.full(self.n_vertices, -1)
        row[chosen] = np.arange(len(chosen))
        sampled = pairs[row[pairs[:, 0]] >= 0]
        return sampled, along[row[sampled[:, 0]], sampled[:, 1]] > FAR * self.edge


def normals_agreeing(mesh: Mesh, pairs: np.ndarray) -> np.ndarray:
    """(p,) bool: the pairs whose vertex normals (the faces' area-weighted) agree."""
    normals = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).vertex_normals
    agree: np.ndarray = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]) > 0
    return agree


def eigenvalue_errors(mesh: Mesh) -> np.ndarray:
    """``|lambda_points / lambda_mesh - 1|`` of the lowest nonzero eigenvalues."""
    import robust_laplacian

    # In the canonical frame: robust-laplacian's operator moves with the frame (by 0.2%
    # of cat0's lowest eigenvalue between the file's and this one).
    surface = canonical_frame(mesh)
    of_mesh = full_resolution_spectra(surface, EIGENVALUES, ("averaged",))["averaged"]
    stiffness, mass = robust_laplacian.point_cloud_laplacian(surface.vertices)
    area = float(face_areas(surface.vertices, surface.faces).sum())  # the spectra's scale
    values = sla.eigsh(stiffness, EIGENVALUES + 1, mass, sigma=-1e-3 * 4 * np.pi / area)[0]
    errors: np.ndarray = np.abs(np.sort(values)[1:] * area / of_mesh - 1.0)
    return errors


def contacts() -> None:
    labels = tosca_labels()
    shares: dict[str, list[tuple[float, float, float]]] = {}
    for name, label in labels.items():
        mesh = load_mesh(TOSCA / name)
        contacts = Contacts(mesh)
        far = contacts.joined_pairs(NEAR, SOURCES)[1]
        pairs, close_far = contacts.joined_pairs(ONE_SPACING, SPACING_SOURCES)
        agree = normals_agreeing(mesh, pairs[close_far])
        shares.setdefault(label, []).append(
            (float(far.mean()), float(close_far.mean()), float(agree.mean()) if len(agree) else 0.0)
        )
    errors = {labels[n]: eigenvalue_errors(load_mesh(TOSCA / n)) for n in first_of_each_class()}
    print(
        "| class | meshes | near pairs far along the surface, median % | largest % "
        "| within one spacing: far along, largest % | of those, normals agreeing, largest % "
        "| first mesh: point-cloud eigenvalues' error |"
    )
    print("|---|---:|---:|---:|---:|---:|---|")
    for label, values in shares.items():
        near, close, agree = (np.array(v) for v in zip(*values, strict=True))
        e = errors[label]
        print(
            f"| {label} | {len(values)} | {100 * np.median(near):.2f} | {100 * near.max():.2f} "
            f"| {100 * close.max():.2f} | {100 * agree.max():.1f} "
            f"| median {100 * np.median(e):.1f}%, largest {100 * e.max():.1f}% |"
        )


def main() -> None:
    argparse.ArgumentParser(description=__doc__.split("\n")[0]).parse_args()
    contacts()


if __name__ == "__main__":
    main()
