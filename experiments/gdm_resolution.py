"""Is the GDM's confusion of TOSCA's human figures the resampling's? Geodesics on finer surfaces.

    python -m experiments.gdm_resolution [--jobs 2] [--sizes 2500 5000 10000 0]

For every TOSCA mesh, the default preset's surface (canonical frame, small holes
closed) is resampled to each size (0: the file's own vertices, up to 52,565) and
the GDM's modal representation is computed as the default computes it (geodesic
distances from 500 farthest-point samples by the heat method, weighted by vertex
and Voronoi areas, divided by ``A^3/2``), with the heat method's time either the
preset's (12 squared edges of a 2,500-vertex tessellation of the surface: the same
smoothing length at every size) or one squared mean edge of the mesh itself (Crane
et al.'s most accurate time, which sharpens with the size). Every solve is the plain
SuperLU reference in double precision, so the sizes differ only by the surface's
resolution. Prints TOSCA's scores for 19 (the paper's) and 40 singular values, all 83
meshes and the 39 human figures alone (david, michael, victoria). About 20 minutes
with two jobs, most of it the full-resolution solves.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from benchmarks.common import TOSCA, tosca_labels
from worker.engine.compare import dissimilarity
from worker.engine.geodesic import HeatMethod, farthest_point_samples
from worker.engine.holes import close_small_holes
from worker.engine.intrinsic import surface_operators
from worker.engine.mesh_io import CANONICAL_AREA, canonical_frame, load_mesh
from worker.engine.modal import modal_gdm, voronoi_areas
from worker.engine.presets import DEFAULT_PRESET, get_preset
from worker.engine.resample import resample_mesh
from worker.recognition import metrics

PRESET = get_preset(DEFAULT_PRESET)
HUMANS = ("david", "michael", "victoria")
#: Singular values compared: the paper's 19, and more.
COUNTS = (19, 40)
#: Heat times: the preset's, in squared edges of a tessellation of the surface with
#: the preset's vertex count, and one squared edge of the mesh itself.
TIMES = {
    "preset's (12 surface edges)": (PRESET.heat_time_factor, PRESET.n_vertices),
    "1 mesh edge": (1.0, None),
}


def _gdm_values(args: tuple[str, tuple[int, ...]]) -> dict[tuple[int, str], np.ndarray]:
    """(size, heat time) -> the GDM's ``max(COUNTS)`` singular values of one file."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    name, sizes = args
    assert PRESET.gdm_samples is not None and PRESET.max_hole_perimeter is not None
    surface = close_small_holes(
        canonical_frame(load_mesh(TOSCA / name)), PRESET.max_hole_perimeter, CANONICAL_AREA
    )
    out = {}
    for size in sizes:
        mesh = surface if size == 0 else resample_mesh(surface, size)
        intrinsic, ops = surface_operators(mesh.vertices, mesh.faces)
        samples = farthest_point_samples(mesh.vertices, PRESET.gdm_samples, ops.vertex_areas)
        for time_name, (factor, reference) in TIMES.items():
            solver = HeatMethod(intrinsic, ops, factor, reference, reference=True)
            distances = solver.distances_from(samples)
            areas = voronoi_areas(distances, ops.vertex_areas)
            out[size, time_name] = modal_gdm(distances, max(COUNTS), ops.vertex_areas, areas)
    return out


def scores(d: np.ndarray, labels: np.ndarray, names: list[str]) -> str:
    gallery, probes = metrics.first_instance_split(names, labels)
    human = np.isin(labels, HUMANS)
    among = d[np.ix_(human, human)]
    values = (
        metrics.equal_error_rate(d, labels),
        metrics.nearest_neighbor_rate(d, labels),
        metrics.rank1_rate(d, labels, gallery, probes),
        metrics.mean_average_precision(d, labels),
        metrics.equal_error_rate(among, labels[human]),
        metrics.nearest_neighbor_rate(among, labels[human]),
    )
    return " | ".join(f"{100 * v:.2f}" for v in values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--sizes", type=int, nargs="+", default=[2500, 5000, 10000, 0])
    args = parser.parse_args()
    labelled = tosca_labels()
    names = sorted(labelled, key=metrics.natural_sort_key)
    labels = np.array([labelled[n] for n in names])
    sizes = tuple(args.sizes)
    with ProcessPoolExecutor(args.jobs) as pool:
        values = list(pool.map(_gdm_values, [(n, sizes) for n in names]))
    print(f"preset {PRESET.name} v{PRESET.version}: GDM from {PRESET.gdm_samples} samples, D1")
    print(
        "| vertices | heat time | singular values | EER | NN | R1RR | mAP "
        "| humans: EER | humans: NN |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for size in sizes:
        for time_name in TIMES:
            for count in COUNTS:
                vectors = np.stack([v[size, time_name][:count] for v in values])
                d = dissimilarity(vectors, vectors, "D1")
                shown = "the file's" if size == 0 else f"{size:,}"
                print(f"| {shown} | {time_name} | {count} | {scores(d, labels, names)} |")


if __name__ == "__main__":
    main()
