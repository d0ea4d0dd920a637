"""``shapes evaluate --resampling figure``: one resampling per figure, carried to all its
poses through their shared vertex ids.

The paper's TOSCA subset (sec. 4.1) had about 3,000 vertices per object and the poses of
one figure shared one triangulation, so their matrices were compared vertex for vertex of
the same sampling; the evaluation otherwise resamples every file on its own. With this
option each class of the labels is taken for one figure: its first mesh in natural
file-name order is resampled (:func:`~worker.engine.resample.shared_resampling`) and the
same vertex ids and triangles make the resampling of every other mesh of the class whose
file has as many vertices (:func:`~worker.engine.resample.carry_resampling`). A mesh with
another vertex count cannot share it and is resampled on its own, as without the option;
the report names those meshes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from worker.engine.errors import MeshError
from worker.engine.mesh_io import read_numbered_mesh
from worker.engine.presets import Preset
from worker.engine.resample import SharedResampling, shared_resampling

from .cache import file_sha256
from .compute import ComputedSet, compute_descriptors
from .datasets import EvaluationError, LabeledMesh


@dataclass(frozen=True)
class Figure:
    """One class's shared resampling.

    Attributes
    ----------
    reference : the mesh it was made on (the class's first).
    key : the cache's name of the descriptors made with it (the reference's digest).
    resampling : its kept vertex ids and triangles.
    poses : the class's meshes that take it (the reference among them).
    """

    reference: LabeledMesh
    key: str
    resampling: SharedResampling
    poses: list[LabeledMesh]


def figures_of(
    meshes: Sequence[LabeledMesh], n_vertices: int
) -> tuple[list[Figure], list[LabeledMesh]]:
    """Each class's shared resampling, and the meshes that cannot take their class's.

    Parameters
    ----------
    meshes : the collection, in natural file-name order (:func:`.datasets.read_labels`).
    n_vertices : the resampling's target (the preset's).

    Returns
    -------
    figures : one per class, in the order of their first meshes.
    own : the meshes whose files have another number of vertices than their class's
        first, to be resampled on their own.

    Raises
    ------
    EvaluationError
        A class's first file cannot be read.
    """
    figures: list[Figure] = []
    own: list[LabeledMesh] = []
    by_label: dict[str, Figure] = {}
    for mesh in meshes:
        figure = by_label.get(mesh.label)
        try:
            numbered = read_numbered_mesh(mesh.path)
        except MeshError as exc:
            if figure is None:
                raise EvaluationError(f"{mesh.name}: {exc.message}") from exc
            own.append(mesh)  # its own description will say why it fails
            continue
        if figure is None:
            figure = Figure(
                reference=mesh,
                key=f"figure-{file_sha256(mesh.path)[:16]}",
                resampling=shared_resampling(numbered, n_vertices),
                poses=[mesh],
            )
            by_label[mesh.label] = figure
            figures.append(figure)
        elif numbered.n_vertices == figure.resampling.source_vertices:
            figure.poses.append(mesh)
        else:
            own.append(mesh)
    return figures, own


def compute_by_figure(
    meshes: Sequence[LabeledMesh],
    preset: Preset,
    cache_root: str | Path,
    jobs: int = 1,
    progress: bool = True,
) -> tuple[ComputedSet, dict[str, Any]]:
    """Descriptors of every mesh with its figure's resampling (through the cache), those
    that cannot take it resampled on their own, in the input order.

    Returns
    -------
    computed : as :func:`.compute.compute_descriptors` returns it.
    about : for the report: ``figures`` (class -> the mesh its resampling was made on,
        its vertices, and how many meshes took it) and ``resampled_on_their_own``.
    """
    figures, own = figures_of(meshes, preset.n_vertices)
    parts = [
        compute_descriptors(
            f.poses, preset, cache_root, jobs=jobs, progress=progress, carried=(f.key, f.resampling)
        )
        for f in figures
    ]
    if own:
        parts.append(compute_descriptors(own, preset, cache_root, jobs=jobs, progress=progress))
    order = {m.name: i for i, m in enumerate(meshes)}
    rows = sorted(
        (
            (order[m.name], m, d, b)
            for part in parts
            for m, d, b in zip(part.meshes, part.descriptors, part.baselines, strict=True)
        ),
        key=lambda row: row[0],
    )
    failures = {name: why for part in parts for name, why in part.failures.items()}
    stats = {
        "meshes": len(meshes),
        "from_cache": sum(p.stats["from_cache"] for p in parts),
        "computed": sum(p.stats["computed"] for p in parts),
        "failed": len(failures),
        "hash_and_cache_seconds": sum(p.stats["hash_and_cache_seconds"] for p in parts),
        "compute_seconds": sum(p.stats["compute_seconds"] for p in parts),
        "jobs": jobs,
        "cache_namespace": parts[0].stats["cache_namespace"],
    }
    computed = ComputedSet(
        meshes=[m for _, m, _, _ in rows],
        descriptors=[d for _, _, d, _ in rows],
        baselines=[b for _, _, _, b in rows],
        failures=dict(sorted(failures.items(), key=lambda item: order[item[0]])),
        stats=stats,
    )
    about: dict[str, Any] = {
        "figures": {
            f.reference.label: {
                "made_on": f.reference.name,
                "vertices": len(f.resampling.corners),
                "poses": len(f.poses),
            }
            for f in figures
        },
        "resampled_on_their_own": [m.name for m in own],
    }
    return computed, about
