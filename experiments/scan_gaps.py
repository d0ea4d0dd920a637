"""Scan gaps: how far small holes in a surface move each modality of the default.

    python -m experiments.scan_gaps [--holes 3:0.002,10:0.001]

Real scans have gaps where the scanner did not see the surface. The robustness
protocol (``shapes robustness``) changes only the triangles; this measures the
surface losing a little of itself. For the first mesh of every TOSCA class, ``h``
holes are cut, each the faces nearest a random face (seed 0) up to a fraction ``f``
of the area (``--holes h:f,...``), and the holed and the intact file are described
as the default preset does (which closes small holes first,
:func:`worker.engine.holes.close_small_holes`) and, for comparison, with the holes
left open (the same preset with ``max_hole_perimeter=None``; each cell reads
"open / closed"). Each distance (D1; the fused score with the preset's weights, on
the protocol's scale, :func:`worker.evaluation.robustness.protocol_distance`) is
divided by the median distance from a TOSCA mesh to the nearest mesh of another
class, read from the preset's robustness report, as the protocol's *gap* is (bar
there: below 0.1). As a reference for the spectrum, the same ratio for the
full-resolution files' own spectra (averaged mass, as ``experiments.spectrum_accuracy``),
once as the descriptor scales them (by each file's area) and once both scaled by
the intact file's area: the part of the movement that is the area the holes took.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

import numpy as np

from benchmarks.common import REPO, TOSCA, first_of_each_class, full_resolution_spectra
from worker.engine.compare import dissimilarity
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.mesh_io import Mesh, clean_mesh, face_areas, load_mesh
from worker.engine.pipeline import describe_mesh
from worker.engine.presets import MODALITIES, get_preset
from worker.evaluation.robustness import protocol_distance

PRESET = get_preset("smeets2010-surface")
LEFT_OPEN = replace(PRESET, max_hole_perimeter=None)
REPORT = REPO / "docs/evaluation/robustness" / PRESET.name / "robustness.json"


def punch_holes(mesh: Mesh, count: int, fraction: float, seed: int = 0) -> Mesh:
    """``count`` holes, each the faces nearest a random face up to ``fraction`` of the area."""
    v, f = mesh.vertices, mesh.faces
    areas = face_areas(v, f)
    centroids = v[f].mean(axis=1)
    keep = np.ones(len(f), dtype=bool)
    for centre in np.random.default_rng(seed).choice(len(f), count, replace=False):
        order = np.argsort(np.linalg.norm(centroids - centroids[centre], axis=1))
        taken = np.searchsorted(np.cumsum(areas[order]), fraction * areas.sum()) + 1
        keep[order[:taken]] = False
    return clean_mesh(v, f[keep])


def d1(a: np.ndarray, b: np.ndarray) -> float:
    return float(dissimilarity(np.ravel(a)[None], np.ravel(b)[None], "D1")[0, 0])


def gap(holed: ShapeDescriptor, intact: ShapeDescriptor, row: str) -> float:
    """D1 between two descriptors in one modality, or their fused score (``row="preset"``)."""
    if row != "preset":
        return d1(getattr(holed, row), getattr(intact, row))
    single = {
        m: np.array([[d1(getattr(holed, m), getattr(intact, m))]]) for m in PRESET.fused_modalities
    }
    return float(protocol_distance(single, PRESET)[0, 0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--holes", default="3:0.002,10:0.001")
    args = parser.parse_args()
    settings = [(int(h), float(f)) for h, f in (item.split(":") for item in args.holes.split(","))]
    tessellation = json.loads(REPORT.read_text())["tessellation"]
    rows = (*MODALITIES, "preset")
    nearest = {row: tessellation[row]["nearest_other_class_median"] for row in rows}

    print(
        "| mesh | holes | area removed | GDM | DDT | Spectrum | fused (the preset's score) "
        "| full-resolution spectrum (open) | same, at the intact area |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    closing = {"open": LEFT_OPEN, "closed": PRESET}
    gaps: dict[str, dict[str, list[float]]] = {row: {way: [] for way in closing} for row in rows}
    full_gaps: dict[str, list[float]] = {"full": [], "full_area": []}
    for name in first_of_each_class():
        mesh = load_mesh(TOSCA / name)
        intact = {way: describe_mesh(mesh, preset) for way, preset in closing.items()}
        reference = full_resolution_spectra(mesh, PRESET.spectrum_size, ("averaged",))["averaged"]
        intact_area = face_areas(mesh.vertices, mesh.faces).sum()
        for count, fraction in settings:
            holed = punch_holes(mesh, count, fraction)
            described = {way: describe_mesh(holed, preset) for way, preset in closing.items()}
            cells = []
            for row in rows:
                for way in closing:
                    gaps[row][way].append(gap(described[way], intact[way], row) / nearest[row])
                cells.append(f"{gaps[row]['open'][-1]:.3f} / {gaps[row]['closed'][-1]:.3f}")
            full = full_resolution_spectra(holed, PRESET.spectrum_size, ("averaged",))["averaged"]
            kept = face_areas(holed.vertices, holed.faces).sum() / intact_area
            full_gaps["full"].append(d1(full, reference) / nearest["spectrum"])
            full_gaps["full_area"].append(d1(full / kept, reference) / nearest["spectrum"])
            cells += [f"{values[-1]:.3f}" for values in full_gaps.values()]
            print(
                f"| {name.split('.')[0]} | {count} x {fraction:.1%} | {1.0 - kept:.2%} | "
                + " | ".join(cells)
                + " |"
            )
    medians = [
        f"{np.median(gaps[row]['open']):.3f} / {np.median(gaps[row]['closed']):.3f}" for row in rows
    ]
    medians += [f"{np.median(values):.3f}" for values in full_gaps.values()]
    print("| median | | | " + " | ".join(medians) + " |")


if __name__ == "__main__":
    main()
