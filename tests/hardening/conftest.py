"""A real service with small limits for the hardening tests (same machinery as tests/service).

The service runs with a 10,000-face limit and a 1 MB upload limit, two real
worker processes and an Alembic-built SQLite database, and has two of the bundled
examples enrolled before any hostile input arrives, so tests can check that
nothing about them changes.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator

import pytest

from benchmarks.common import Service
from tests.service.conftest import migrated_service, running

MAX_FACES = 10_000  # over the examples' 4,996 faces
ENROLLED = {"quadruped-0": "quadruped", "quadruped-1": "quadruped"}


def make_service(tmp_path_factory, name: str, **env: str) -> Service:
    return migrated_service(tmp_path_factory, name, SHAPES_MAX_FACES=str(MAX_FACES), **env)


@pytest.fixture(scope="session")
def hardened(tmp_path_factory) -> Iterator[Service]:
    with running(make_service(tmp_path_factory, "hardened")) as svc:
        yield svc


@pytest.fixture(scope="session")
def enrolled(hardened: Service) -> dict[str, int]:
    ids = {}
    for name, label in ENROLLED.items():
        response = hardened.upload(name, label)
        assert response.status_code in (200, 202), response.text
        ids[name] = response.json()["id"]
    for mesh_id in ids.values():
        assert hardened.wait_mesh(mesh_id)["status"] == "ready"
    return ids


def db_rows(service: Service, mesh_ids) -> dict[str, list[tuple]]:
    """The rows (every column) that belong to ``mesh_ids``, read straight from SQLite."""
    marks = ",".join("?" * len(mesh_ids))
    with sqlite3.connect(f"file:{service.data_dir / 'shapes.sqlite3'}?mode=ro", uri=True) as db:
        return {
            table: db.execute(
                f"SELECT * FROM {table} WHERE {key} IN ({marks}) ORDER BY 1", list(mesh_ids)
            ).fetchall()
            for table, key in (("meshes", "id"), ("descriptors", "mesh_id"), ("jobs", "mesh_id"))
        }


def integrity_check(service: Service) -> str:
    with sqlite3.connect(service.data_dir / "shapes.sqlite3") as db:
        return db.execute("PRAGMA integrity_check").fetchone()[0]
