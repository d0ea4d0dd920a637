"""Variants of a mesh that keep its shape and change its triangles (robustness protocol).

Each variant is what an uploaded file of the same object could look like: the
same surface simplified, remeshed, subdivided, in other units and orientation,
or scanned with a little noise. A descriptor of the *surface* should barely move
between a mesh and its variants; :mod:`.robustness` measures how much it does.

Variants are deterministic: the random ones take a seed (the protocol derives it
from the file name), so a rerun describes the same meshes and hits the cache.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable

import numpy as np

from worker.engine.mesh_io import Mesh, clean_mesh

from .partial import (
    DRAWN_AS,
    LOG10_SCALE_RANGE,
    ORBITING,
    PARTIAL_VARIANTS,
    decimated,
    random_rotation,
)
from .remesh import remeshed

#: Gaussian vertex noise, as a fraction of the mesh's mean edge length.
NOISE_FRACTION = 0.1


def subdivided(mesh: Mesh) -> Mesh:
    """One step of Loop subdivision (four times the faces, a slightly smoothed surface)."""
    import trimesh

    # no-untyped-call: trimesh's subdivide_loop carries no annotations.
    vertices, faces = trimesh.remesh.subdivide_loop(  # type: ignore[no-untyped-call]
        mesh.vertices, mesh.faces, iterations=1
    )
    return clean_mesh(vertices, faces)


def rotated_scaled(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """A uniformly random rotation and a scale of ``10**u``, u in ``LOG10_SCALE_RANGE``."""
    scale = 10.0 ** rng.uniform(*LOG10_SCALE_RANGE)
    return Mesh(vertices=mesh.vertices @ random_rotation(rng).T * scale, faces=mesh.faces)


def noisy(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """Gaussian noise of ``NOISE_FRACTION`` times the mean edge length on every vertex."""
    edges = mesh.vertices[mesh.faces[:, [1, 2, 0]]] - mesh.vertices[mesh.faces]
    sigma = NOISE_FRACTION * float(np.linalg.norm(edges, axis=2).mean())
    return Mesh(
        vertices=mesh.vertices + rng.normal(scale=sigma, size=mesh.vertices.shape),
        faces=mesh.faces,
    )


#: Variants slow enough to make that the evaluation stores their meshes
#: (:class:`.cache.VariantMeshCache`): MeshLab's remeshing takes 1.6-35 s per TOSCA file
#: (wolf0 to michael0), every other variant under a second.
STORED_VARIANTS = ("remeshed-8k", "remeshed-15k")
#: name -> how to make it from a mesh and a random generator, in report order.
VARIANTS: dict[str, Callable[[Mesh, np.random.Generator], Mesh]] = {
    "decimated-50": lambda mesh, _: decimated(mesh, 0.5),
    "decimated-20": lambda mesh, _: decimated(mesh, 0.2),
    "remeshed-8k": lambda mesh, _: remeshed(mesh, 8_000),
    "remeshed-15k": lambda mesh, _: remeshed(mesh, 15_000),
    "subdivided": lambda mesh, _: subdivided(mesh),
    "rotated-scaled": rotated_scaled,
    "noisy": noisy,
}


def variant_seed(name: str, variant: str) -> int:
    """A fixed seed per (file, variant), independent of Python's hash randomization."""
    return int.from_bytes(hashlib.sha256(f"{name}/{variant}".encode()).digest()[:8], "little")


#: Separates a variant's name from the number of one more copy of it (:func:`copy_name`).
COPY_MARK = "#"


def copy_name(variant: str, copy: int) -> str:
    """The name of copy ``copy`` of a random variant: the variant itself for copy 0, else
    the variant drawn again from a seed of its own (``range#3``), as SHREC'17 draws
    twenty range scans of every model."""
    return variant if copy == 0 else f"{variant}{COPY_MARK}{copy}"


#: Separates a range camera's variant (:data:`.partial.ORBITING`) from the axis its whole
#: stands on, when that is not z (:func:`standing_name`).
UP_MARK = "@"


def standing_name(variant: str, up: str) -> str:
    """The name ``variant`` (or a copy of it) of a whole standing on the axis ``up`` is
    made and cached by: the variant itself when ``up`` is z or the variant is not shot by
    the range camera, else the axis after :data:`UP_MARK` (``range#3@x``)."""
    shot = variant.partition(COPY_MARK)[0] in ORBITING
    return f"{variant}{UP_MARK}{up}" if shot and up != "z" else variant


def make_variant(mesh: Mesh, variant: str, name: str) -> Mesh:
    """The variant ``variant`` of ``mesh`` (the file called ``name``): one of
    :data:`VARIANTS`, or a partial copy (:data:`.partial.PARTIAL_VARIANTS`), from its
    seed or the one it is drawn as (:data:`.partial.DRAWN_AS`); a further copy of it
    (:func:`copy_name`) from that seed's copy; a range camera's of a whole standing on
    another axis than z (:func:`standing_name`) from the same seed, around that axis."""
    drawn, _, up = variant.partition(UP_MARK)
    base, mark, copy = drawn.partition(COPY_MARK)
    rng = np.random.default_rng(variant_seed(name, DRAWN_AS.get(base, base) + mark + copy))
    if base in ORBITING:
        return ORBITING[base](mesh, rng, up or "z")
    return (VARIANTS.get(base) or PARTIAL_VARIANTS[base])(mesh, rng)
