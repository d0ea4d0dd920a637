"""Shared fixtures: generated meshes, the TOSCA set, a small preset for fast tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from worker.engine.presets import Preset
from worker.evaluation.datasets import shared_dataset

TOSCA_DIR = shared_dataset("tosca")

#: Fixtures that start real service processes. A test using one is marked ``service``
#: and ``slow`` here, so ``-m "not slow"`` never waits for an API or a worker.
SERVICE_FIXTURES = {
    "service",
    "gallery",
    "hardened",
    "enrolled",
    "fuzzed",
    "guarded",
    "crashy",
    "limited",
}


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if SERVICE_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.service)
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def tosca_dir() -> Path:
    if not TOSCA_DIR.is_dir():
        pytest.skip(f"TOSCA set not found at {TOSCA_DIR}")
    return TOSCA_DIR


@pytest.fixture(scope="session")
def small_preset() -> Preset:
    """The paper's method at 800 vertices, so whole-pipeline tests stay fast."""
    return Preset(name="test-small", version=0, n_vertices=800, n_eigenpairs=100)


def bent_cylinder(bend: float, sections: int = 60, count: int = 24) -> trimesh.Trimesh:
    """A closed cylinder (radius 1, length 8) bent by ``bend`` radians into an arc.

    Bending is a near-isometry: lengths along the axis are kept.
    """
    tube = trimesh.creation.cylinder(radius=1.0, height=8.0, sections=count)
    tube = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(tube.vertices, tube.faces, 0.35))
    if bend == 0:
        return tube
    v = tube.vertices.copy()
    radius = 8.0 / bend
    theta = v[:, 2] / radius
    r = radius - v[:, 0]
    v[:, 0] = radius - r * np.cos(theta)
    v[:, 2] = r * np.sin(theta)
    return trimesh.Trimesh(v, tube.faces)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q
