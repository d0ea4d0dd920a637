"""Do the descriptors see the shape or the triangles of CAD-style files?

    python -m experiments.cad_tessellations [--preset smeets2010-surface]

The robustness protocol (``shapes robustness``) re-tessellates TOSCA's organic,
finely triangulated files. Files exported from CAD tools look different: a cylinder
is a few dozen long strips and two fans, a box twelve triangles. This script takes
eight simple solids (cylinders of two proportions, a cone, two boxes, a capsule, a
torus, a sphere), each as trimesh builds it at two or three facet counts, as the
protocol's isotropic remesh of the finest one (about 12,000 vertices, MeshLab's
filter: needs the ``eval`` extra) and, for the round ones, as a fine chordal tolerance
exports it (thousands of slivers), describes every file with the preset, and prints
per modality and for the preset's fused score (on a product's scale, as the protocol):

* **gap**: for every file, the median distance to the other files of its solid over
  the distance to the nearest file of another solid; the median and the largest
  over the files (the protocol's bar for TOSCA is 0.1);
* **NN**: the files whose nearest other file is one of the same solid.

Then the fused score's gap of every file against each other file of its solid.
"""

from __future__ import annotations

import argparse

import numpy as np
import trimesh

from worker.engine.compare import dissimilarity
from worker.engine.mesh_io import Mesh, clean_mesh
from worker.engine.pipeline import describe_mesh
from worker.engine.presets import DEFAULT_PRESET, MODALITIES, get_preset
from worker.evaluation.remesh import remeshed
from worker.evaluation.robustness import protocol_distance

#: Vertices of the isotropic remesh each solid is also described as.
REMESH_VERTICES = 12_000

#: The sides of a round solid's coarse files: a few dozen strips.
FACETS = (24, 48, 96)


def solids() -> dict[str, list[tuple[str, trimesh.Trimesh]]]:
    """Solid -> its CAD-style tessellations (label, mesh), coarse to fine."""
    c = trimesh.creation
    return {
        "cylinder 1:2": [(f"{s} sides", c.cylinder(0.5, 2.0, sections=s)) for s in FACETS],
        "cylinder 1:3": [(f"{s} sides", c.cylinder(0.5, 3.0, sections=s)) for s in FACETS],
        "cone": [(f"{s} sides", c.cone(0.5, 2.0, sections=s)) for s in FACETS],
        "box 1:2:3": [("12 triangles", c.box((1.0, 2.0, 3.0)))],
        "box 1:1:3": [("12 triangles", c.box((1.0, 1.0, 3.0)))],
        "capsule": [(f"{k} x {k}", c.capsule(2.0, 0.5, count=[k, k])) for k in (8, 16, 32)],
        "torus": [
            (f"{a} x {b}", c.torus(1.0, 0.3, major_sections=a, minor_sections=b))
            for a, b in ((24, 8), (48, 12), (96, 24))
        ],
        "sphere": [
            ("icosphere 2", c.icosphere(2)),
            ("UV 16 x 16", c.uv_sphere(count=[16, 16])),
            ("icosphere 5", c.icosphere(5)),
        ],
    }


def fine_exports() -> dict[str, tuple[str, trimesh.Trimesh]]:
    """Solid -> its file as a fine chordal tolerance exports it (label, mesh): thousands
    of slivers, which quadric decimation cannot thin."""
    c = trimesh.creation
    return {
        "cylinder 1:2": ("2048 sides", c.cylinder(0.5, 2.0, sections=2048)),
        "cylinder 1:3": ("2048 sides", c.cylinder(0.5, 3.0, sections=2048)),
        "cone": ("2048 sides", c.cone(0.5, 2.0, sections=2048)),
        "torus": ("1024 x 16", c.torus(1.0, 0.3, major_sections=1024, minor_sections=16)),
    }


def files() -> list[tuple[str, str, Mesh]]:
    """(solid, tessellation, mesh) of every file the script describes: a solid's coarse
    files, the isotropic remesh of the finest of them, and its fine export if it has one."""
    out = []
    fine = fine_exports()
    for solid, tessellations in solids().items():
        for label, shape in tessellations:
            out.append((solid, label, clean_mesh(shape.vertices, shape.faces)))
        out.append((solid, "isotropic remesh", remeshed(out[-1][2], REMESH_VERTICES)))
        if solid in fine:
            label, shape = fine[solid]
            out.append((solid, label, clean_mesh(shape.vertices, shape.faces)))
    return out


def gaps(d: np.ndarray, solid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per file: median distance to its own solid's other files over the distance to
    the nearest other solid's file, and whether its nearest other file is its solid's."""
    d = d.copy()
    np.fill_diagonal(d, np.nan)
    same = solid[:, None] == solid[None, :]
    own = np.nanmedian(np.where(same, d, np.nan), axis=1)
    other = np.nanmin(np.where(same, np.nan, d), axis=1)
    nearest = np.nanargmin(np.where(np.isnan(d), np.inf, d), axis=1)
    return own / other, solid[nearest] == solid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default=DEFAULT_PRESET)
    args = parser.parse_args()
    preset = get_preset(args.preset)
    meshes = files()
    described = [describe_mesh(mesh, preset) for _, _, mesh in meshes]
    solid = np.array([s for s, _, _ in meshes])
    per = {}
    for m in MODALITIES:
        vectors = np.stack([d.vector(m) for d in described])
        per[m] = dissimilarity(vectors, vectors, preset.dissimilarity)
    rows = {m: per[m] for m in MODALITIES}
    rows["fused"] = protocol_distance(per, preset)
    count = f"{len(described)} files of {len(set(solid))} solids"
    print(f"preset {preset.name} v{preset.version}, {count}")
    print("\n| | gap (median) | gap (largest) | NN |")
    print("|---|---:|---:|---:|")
    for name, d in rows.items():
        ratio, hit = gaps(d, solid)
        print(f"| {name} | {np.median(ratio):.2f} | {ratio.max():.2f} | {hit.mean():.0%} |")
    ratio, _ = gaps(rows["fused"], solid)
    print("\n| solid | tessellation | input vertices | resampled vertices | fused gap | seconds |")
    print("|---|---|---:|---:|---:|---:|")
    for (s, label, mesh), descriptor, r in zip(meshes, described, ratio, strict=True):
        seconds = sum(descriptor.timings.values())
        print(
            f"| {s} | {label} | {mesh.n_vertices:,} | {descriptor.vertices:,} | {r:.2f} "
            f"| {seconds:.2f} |"
        )


if __name__ == "__main__":
    main()
