"""The bundled examples (``examples/``, written by ``shapes samples``): closed surfaces
of one part, near-isometric poses, reproducible, and told apart by the default preset."""

from __future__ import annotations

import gzip
import io
from collections import Counter

import numpy as np
import pytest
import trimesh
from conftest import EXAMPLES, example
from scipy.spatial import cKDTree

from app.cli import main
from worker.engine.compare import dissimilarity, fuse
from worker.engine.mesh_io import read_mesh
from worker.engine.presets import DEFAULT_PRESET, get_preset
from worker.evaluation.compute import compute_descriptors, descriptor_vectors
from worker.evaluation.datasets import read_labels
from worker.evaluation.samples import (
    CROSSING_MARGIN,
    DEPTH_DIRECTION,
    DEPTH_PIXELS,
    DEPTH_SAMPLE,
    FIGURES,
    FLOOR_SAMPLE,
    N_POSES,
    PARTIAL_SAMPLE,
    SAMPLE_CLASSES,
    SAMPLE_VERTICES,
    marching_tetrahedra,
    posed_bones,
    sample_name,
)
from worker.recognition.metrics import (
    LabelledSet,
    equal_error_rate,
    nearest_neighbor_rate,
    retrieval_scores,
)

SAMPLES = [f"{name}-{pose}" for name in SAMPLE_CLASSES for pose in range(N_POSES)]
#: How far a regenerated sample may lie from the committed one, as a fraction of its
#: bounding box's diagonal (both ways, vertices to the other's surface). On one machine
#: they are the same file; but the decimation follows rounding: level-set vertices
#: computed in another order (the last bit) gave other collapses, within 0.8% of the
#: diagonal (measured, all 20), and another quality weight within 1.0% (the biped);
#: another pose lies 19-21% away.
REGENERATED = 0.02
#: The poses of one figure turn its joints, which keeps its bones' lengths; their
#: surface areas differ by the fillets at the joints (at most 1.3%, measured: the hand).
POSE_AREA = 0.02
#: Candidate triangles per point in :func:`surface_distance`.
CANDIDATES = 8


def read_off_gz(path) -> trimesh.Trimesh:
    """The file's mesh as written (no merging or reordering)."""
    data = io.BytesIO(gzip.decompress(path.read_bytes()))
    return trimesh.load(data, file_type="off", process=False)


def surface_distance(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """(n,) distance of each point of ``points`` (n, 3) to the surface of ``mesh``: the
    nearest point on the ``CANDIDATES`` triangles whose centroids are nearest."""
    triangles = mesh.triangles
    _, nearest = cKDTree(triangles.mean(axis=1)).query(points, k=CANDIDATES)
    repeated = np.repeat(points, CANDIDATES, axis=0)
    closest = trimesh.triangles.closest_point(triangles[nearest.ravel()], repeated)
    return np.linalg.norm(closest - repeated, axis=1).reshape(-1, CANDIDATES).min(axis=1)


@pytest.mark.parametrize("name", SAMPLES)
def test_every_example_is_one_closed_surface_the_service_takes_whole(name):
    cleaned = read_mesh(example(name))
    assert cleaned.kept_area_fraction == 1.0  # no "described in part"
    assert cleaned.mesh.n_vertices == SAMPLE_VERTICES
    surface = trimesh.Trimesh(cleaned.mesh.vertices, cleaned.mesh.faces, process=False)
    assert surface.is_watertight and surface.is_winding_consistent
    assert surface.euler_number == 2  # a sphere's topology: no limb touches another
    assert surface.volume > 0  # normals point outward


def test_the_examples_are_five_classes_of_four_poses_in_under_2_mb():
    meshes = read_labels(EXAMPLES / "labels.csv", EXAMPLES)
    assert [m.name for m in meshes] == sorted(f"{name}.off.gz" for name in SAMPLES)
    assert Counter(m.label for m in meshes) == {name: N_POSES for name in SAMPLE_CLASSES}
    assert all(m.name.startswith(f"{m.label}-") for m in meshes)
    assert sum(path.stat().st_size for path in EXAMPLES.iterdir()) < 2 * 1024**2


@pytest.mark.parametrize("name", SAMPLE_CLASSES)
def test_the_poses_of_a_figure_keep_its_bones_and_nearly_its_area(name):
    figure = FIGURES[name]()
    rest = {bone.name: np.linalg.norm(bone.vector) for bone in figure.bones}
    for pose in range(N_POSES):
        placed = posed_bones(figure, pose)
        lengths = {bone: np.linalg.norm(end - start) for bone, (start, end, _) in placed.items()}
        assert lengths == pytest.approx(rest, rel=1e-12)
    areas = [read_off_gz(example(f"{name}-{pose}")).area for pose in range(N_POSES)]
    assert max(areas) / min(areas) - 1 < POSE_AREA


def test_marching_tetrahedra_closes_a_sphere_on_its_level_set():
    step, radius = 0.1, 1.0
    axis = np.arange(-1.4, 1.4 + step / 2, step)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    values = np.sqrt(x**2 + y**2 + z**2) - radius
    vertices, faces = marching_tetrahedra(values, np.full(3, axis[0]), step)
    sphere = trimesh.Trimesh(vertices, faces, process=False)
    assert sphere.is_watertight and sphere.is_winding_consistent and sphere.euler_number == 2
    assert sphere.volume == pytest.approx(4 / 3 * np.pi * radius**3, rel=0.01)
    # Each vertex interpolates the distance linearly along a grid edge of length L (at
    # most sqrt(3) step), off the sphere by L^2 / (8 radius) at most, and is kept
    # CROSSING_MARGIN L from the edge's ends.
    longest = np.sqrt(3) * step
    bound = longest**2 / (8 * radius) + CROSSING_MARGIN * longest
    np.testing.assert_allclose(np.linalg.norm(vertices, axis=1), radius, atol=bound)


@pytest.fixture(scope="module")
def regenerated(tmp_path_factory):
    """``shapes samples`` into a fresh directory."""
    out = tmp_path_factory.mktemp("samples")
    assert main(["samples", str(out)]) == 0
    return out


@pytest.mark.slow  # generates the 20 samples (about a minute)
def test_shapes_samples_rewrites_the_labels_and_nothing_else(regenerated):
    assert (regenerated / "labels.csv").read_bytes() == (EXAMPLES / "labels.csv").read_bytes()
    assert sorted(p.name for p in regenerated.iterdir()) == sorted(
        p.name for p in EXAMPLES.iterdir()
    )
    assert (regenerated / PARTIAL_SAMPLE).is_file()


def test_the_partial_example_is_the_quadruped_without_its_top():
    """What the walk-through queries with: an open part of quadruped-3, its top gone."""
    whole, part = read_off_gz(example("quadruped-3")), read_off_gz(EXAMPLES / PARTIAL_SAMPLE)
    assert not part.is_watertight and 0.6 < part.area / whole.area < 0.95
    assert part.bounds[1, 2] < whole.bounds[1, 2] and part.bounds[0, 2] == whole.bounds[0, 2]


def test_the_depth_example_is_the_quadruped_s_left_side_as_a_camera_s_grid():
    """What a depth camera would write: the side of quadruped-3 facing it, an organized
    cloud read as the mesh of its grid, every point on the whole's surface."""
    whole = read_off_gz(example("quadruped-3"))
    scan = read_mesh(EXAMPLES / DEPTH_SAMPLE)
    vertices = scan.mesh.vertices
    assert 0.8 * DEPTH_PIXELS < len(vertices) <= 1.1 * DEPTH_PIXELS
    extent = np.ptp(whole.vertices, axis=0).max()
    distance = surface_distance(vertices, whole)  # (its nearest triangles found approximately)
    assert np.quantile(distance, 0.99) < 1e-3 * extent and distance.max() < 2e-3 * extent
    # The side facing the camera (+y), and less than half of the whole's area.
    facing = np.asarray(DEPTH_DIRECTION)
    assert (vertices @ facing).mean() > (whole.vertices @ facing).mean()
    area = trimesh.Trimesh(vertices, scan.mesh.faces, process=False).area
    assert 0.2 < area / whole.area < 0.5


def test_the_floor_example_is_the_quadruped_on_a_floor_that_is_left_out():
    """The same quadruped on a floor, seen from 35 degrees above: the frame holds more
    floor than quadruped, and read as the service reads it only the quadruped's side is
    left, on the whole's surface."""
    whole = read_off_gz(example("quadruped-3"))
    scan = read_mesh(EXAMPLES / FLOOR_SAMPLE)
    assert scan.cloud is not None and scan.cloud.support > scan.cloud.points
    extent = np.ptp(whole.vertices, axis=0).max()
    # (its nearest triangles found approximately)
    assert np.quantile(surface_distance(scan.mesh.vertices, whole), 0.99) < 1e-3 * extent
    assert scan.mesh.vertices[:, 2].min() > whole.vertices[:, 2].min()  # none on the floor


@pytest.mark.slow
@pytest.mark.parametrize("name", SAMPLES)
def test_shapes_samples_regenerates_the_committed_geometry(regenerated, name):
    committed = read_off_gz(example(name))
    made = read_off_gz(regenerated / f"{name}.off.gz")
    assert len(made.vertices) == len(committed.vertices)
    tolerance = REGENERATED * np.linalg.norm(np.ptp(committed.vertices, axis=0))
    assert surface_distance(made.vertices, committed).max() <= tolerance
    assert surface_distance(committed.vertices, made).max() <= tolerance


@pytest.fixture(scope="module")
def default_scores(tmp_path_factory):
    """The default preset's score (its fused dissimilarity, as the service ranks with
    it) between all examples, their labels and names, and each modality's dissimilarity."""
    preset = get_preset(DEFAULT_PRESET)
    meshes = read_labels(EXAMPLES / "labels.csv", EXAMPLES)
    computed = compute_descriptors(
        meshes, preset, tmp_path_factory.mktemp("cache"), jobs=2, progress=False
    )
    assert not computed.failures
    vectors = descriptor_vectors(computed)
    per = {
        m: dissimilarity(vectors[m], vectors[m], preset.dissimilarity)
        for m in preset.fused_modalities
    }
    scores = fuse(per, preset.fusion, {m: preset.weight(m) for m in per})
    names = [m.name.removesuffix(".off.gz") for m in meshes]
    return scores, np.array([m.label for m in meshes]), names, per


@pytest.mark.slow  # describes the 20 examples
def test_the_default_preset_tells_the_classes_apart(default_scores):
    """Every pair of one figure is nearer than any pair of two (measured at v9: at most
    0.0073 against at least 0.026, a quadruped and a hand): NN 100%, EER 0."""
    scores, labels, _, _ = default_scores
    assert nearest_neighbor_rate(scores, labels) == 1.0
    same = labels[:, None] == labels[None, :]
    genuine = scores[same & ~np.eye(len(labels), dtype=bool)]
    assert genuine.max() < scores[~same].min()


@pytest.mark.slow
def test_a_labelled_sets_figures_are_the_metrics_own_on_every_modality(default_scores):
    """:class:`LabelledSet` (what a fusion's weights are chosen with) against the plain
    metrics on real descriptors: each modality's dissimilarity and a product of them,
    labelled by figure (which each tells apart) and by pose (which none does)."""
    scores, labels, names, per = default_scores
    by_pose = np.array([name.rsplit("-", 1)[1] for name in names])
    matrices = [scores, *per.values(), fuse(per, "product", dict.fromkeys(per, 0.5))]
    for classes in (labels, by_pose):
        labelled = LabelledSet(classes)
        for d in matrices:
            retrieval = retrieval_scores(d, classes)
            expected = (equal_error_rate(d, classes), retrieval["nn"], retrieval["map"])
            assert labelled.figures(d) == expected
    assert LabelledSet(by_pose).figures(scores)[0] > 0.1


@pytest.mark.slow
def test_pose_3_of_every_figure_finds_its_own_class_among_poses_0_to_2(default_scores):
    scores, labels, names, _ = default_scores
    gallery = np.array([not name.endswith("-3") for name in names])
    for name in SAMPLE_CLASSES:
        query = names.index(sample_name(name, 3).removesuffix(".off.gz"))
        nearest = np.flatnonzero(gallery)[np.argmin(scores[query, gallery])]
        assert labels[nearest] == name, (name, names[nearest])
