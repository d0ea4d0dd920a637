"""Whole-pipeline invariances (issue 2) with stated tolerances.

Differences are relative Euclidean: ``|a - b| / |a|`` per modality. Vertex order
and rigid motion leave the descriptor (numerically) unchanged; uniform scale and a
different resolution of the same surface change it by a few percent at most
(quadric decimation then picks other vertices); a genuinely different shape
changes it more than that.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import bent_cylinder, random_rotation

from worker.engine.mesh_io import Mesh, clean_mesh, load_mesh
from worker.engine.pipeline import ShapeDescriptor, describe_file, describe_mesh

pytestmark = pytest.mark.slow  # whole pipelines on TOSCA and generated meshes

MODALITIES = ("gdm", "ddt", "spectrum")
EXACT = 1e-6  # vertex permutation
RIGID = 0.01  # rotation + translation
SAME_SURFACE = 0.03  # scale x0.2 / x5, twice the resolution


def _difference(a: ShapeDescriptor, b: ShapeDescriptor, modality: str) -> float:
    x, y = a.vector(modality), b.vector(modality)
    return float(np.linalg.norm(x - y) / np.linalg.norm(x))


@pytest.fixture(scope="module")
def wolf(tosca_dir) -> Mesh:
    return load_mesh(tosca_dir / "wolf0.off.gz")


@pytest.fixture(scope="module")
def wolf_descriptor(wolf, small_preset) -> ShapeDescriptor:
    return describe_mesh(wolf, small_preset)


def test_descriptor_shapes_and_record(wolf_descriptor, small_preset):
    d = wolf_descriptor
    assert d.gdm.shape == (small_preset.gdm_singular_values,)
    assert d.ddt.shape == small_preset.ddt_core_shape
    assert d.spectrum.shape == (small_preset.spectrum_size,)
    assert (d.preset, d.preset_version) == (small_preset.name, small_preset.version)
    assert abs(d.vertices - small_preset.n_vertices) <= 0.03 * small_preset.n_vertices
    assert np.all(np.diff(d.gdm) <= 0) and np.all(d.ddt >= 0)
    assert set(d.timings) == {"resample", "gdm", "eigen_ddt", "modal"}


def test_vertex_permutation(wolf, wolf_descriptor, small_preset):
    perm = np.random.default_rng(0).permutation(wolf.n_vertices)
    permuted = Mesh(wolf.vertices[perm], np.argsort(perm)[wolf.faces])
    d = describe_mesh(permuted, small_preset)
    for m in MODALITIES:
        assert _difference(wolf_descriptor, d, m) <= EXACT


def test_rigid_motion(wolf, wolf_descriptor, small_preset):
    rng = np.random.default_rng(1)
    moved = Mesh(wolf.vertices @ random_rotation(rng).T + [3.0, -2.0, 7.0], wolf.faces)
    d = describe_mesh(moved, small_preset)
    for m in MODALITIES:
        assert _difference(wolf_descriptor, d, m) <= RIGID


@pytest.mark.parametrize("scale", [0.2, 5.0])
def test_uniform_scale(wolf, wolf_descriptor, small_preset, scale):
    d = describe_mesh(Mesh(wolf.vertices * scale, wolf.faces), small_preset)
    for m in MODALITIES:
        assert _difference(wolf_descriptor, d, m) <= SAME_SURFACE


def test_same_surface_at_twice_the_resolution(wolf, wolf_descriptor, small_preset):
    finer = clean_mesh(*trimesh.remesh.subdivide(wolf.vertices, wolf.faces))
    assert finer.n_vertices > 3 * wolf.n_vertices
    d = describe_mesh(finer, small_preset)
    for m in MODALITIES:
        assert _difference(wolf_descriptor, d, m) <= SAME_SURFACE


def test_bent_cylinder_is_closer_than_a_different_shape(small_preset):
    def describe(t: trimesh.Trimesh) -> ShapeDescriptor:
        return describe_mesh(clean_mesh(t.vertices, t.faces), small_preset)

    straight = describe(bent_cylinder(0.0))
    bent = describe(bent_cylinder(1.5))
    capsule = describe(trimesh.creation.capsule(height=6.0, radius=1.2, count=[40, 40]))
    for m in MODALITIES:
        assert _difference(straight, bent, m) < _difference(straight, capsule, m)
    assert _difference(straight, bent, "gdm") < 0.05


def test_descriptor_round_trips(wolf_descriptor):
    for restored in (
        ShapeDescriptor.from_json(wolf_descriptor.to_json()),
        ShapeDescriptor.from_npz_bytes(wolf_descriptor.to_npz_bytes()),
    ):
        for m in MODALITIES:
            np.testing.assert_array_equal(restored.vector(m), wolf_descriptor.vector(m))
        assert restored.preset == wolf_descriptor.preset
        assert restored.timings == wolf_descriptor.timings


def test_describe_file_times_every_stage(tosca_dir, small_preset):
    d = describe_file(tosca_dir / "wolf1.off.gz", small_preset)
    assert list(d.timings) == ["load", "resample", "gdm", "eigen_ddt", "modal", "total"]
    assert d.timings["total"] == pytest.approx(sum(v for k, v in d.timings.items() if k != "total"))
