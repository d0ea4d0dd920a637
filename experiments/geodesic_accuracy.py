"""GDM accuracy: heat-method geodesics against exact ones.

    python -m experiments.geodesic_accuracy [--sources 10] [--time-factors 1,16]

Sphere: great-circle distances (exact for the sphere the mesh approximates).
TOSCA meshes, resampled to 2,500 vertices: the exact polyhedral geodesics of the
same mesh by MMP (pygeodesic), from randomly drawn sources (a resample with an edge of
three triangles is left out: MMP's mesh cannot hold one). Relative errors over
all (source, target) pairs with target != source, for each heat time factor (the
heat step's time in squared mean edge lengths), and once without the intrinsic
Delaunay flips.
"""

from __future__ import annotations

import argparse

import numpy as np
import trimesh
from pygeodesic.geodesic import PyGeodesicAlgorithmExact

from benchmarks.common import TOSCA
from worker.engine.geodesic import geodesic_distance_matrix
from worker.engine.intrinsic import IntrinsicMesh, fem_operators, surface_operators
from worker.engine.mesh_io import load_mesh, non_manifold_face_fraction
from worker.engine.resample import resample_mesh


def _gdm(
    vertices: np.ndarray, faces: np.ndarray, time_factor: float, delaunay: bool = True
) -> np.ndarray:
    if delaunay:
        mesh, ops = surface_operators(vertices, faces)
    else:
        mesh = IntrinsicMesh.from_mesh(vertices, faces)
        ops = fem_operators(mesh)
    return geodesic_distance_matrix(mesh, ops, time_factor)


def _row(name: str, errors: list[np.ndarray]) -> str:
    e = np.concatenate(errors)
    return f"| {name} | {np.median(e):.2%} | {np.mean(e):.2%} | {np.percentile(e, 95):.2%} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sources", type=int, default=10)
    parser.add_argument("--time-factors", default="1,16", help="comma-separated")
    args = parser.parse_args()
    factors = [float(f) for f in args.time_factors.split(",")]
    print("| mesh | heat time factor | median rel. error | mean | 95th percentile |")
    print("|---|---|---|---|---|")
    sphere = trimesh.creation.icosphere(subdivisions=4)
    unit = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    exact = np.arccos(np.clip(unit @ unit.T, -1, 1))
    mask = ~np.eye(len(unit), dtype=bool)
    for factor in factors:
        gdm = _gdm(sphere.vertices, sphere.faces, factor)
        errors = [np.abs(gdm - exact)[mask] / exact[mask]]
        print(_row(f"icosphere (2,562 v) vs great circles | {factor:g}", errors))
    rng = np.random.default_rng(0)
    for name in ("michael0", "horse0", "centaur0", "dog0"):
        mesh = resample_mesh(load_mesh(TOSCA / f"{name}.off.gz"), 2500)
        # MMP's mesh (pygeodesic) holds two triangles per edge at most: an edge of three
        # crashes the process (dog0's 2,500-vertex resample has one).
        if non_manifold_face_fraction(mesh.faces, mesh.n_vertices) > 0.0:
            print(f"| {name} ({mesh.n_vertices} v): an edge of three triangles, no MMP | | | | |")
            continue
        solver = PyGeodesicAlgorithmExact(mesh.vertices, mesh.faces.astype(np.int32))
        sources = rng.choice(mesh.n_vertices, size=args.sources, replace=False)
        exact_rows = [solver.geodesicDistances(np.array([s]), None)[0] for s in sources]
        runs = [(factor, True) for factor in factors] + [(factors[0], False)]
        for factor, delaunay in runs:
            gdm = _gdm(mesh.vertices, mesh.faces, factor, delaunay)
            errors = []
            for s, d in zip(sources, exact_rows, strict=True):
                keep = d > 0
                errors.append(np.abs(gdm[s, keep] - d[keep]) / d[keep])
            label = "intrinsic Delaunay" if delaunay else "decimated triangles as they are"
            print(_row(f"{name} ({mesh.n_vertices} v, {label}) vs MMP | {factor:g}", errors))


if __name__ == "__main__":
    main()
