"""Keys with scopes: the admin key makes keys for one collection or all; a key may do
what its scope says in its collections and nothing else; a revoked key is refused by
every API process within a second; no key is stored in plain text."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest
from conftest import example
from pydantic import ValidationError

from app.config import Settings, access_notice
from benchmarks.common import REPO, Service

from .conftest import make_service

ADMIN = "admin-key-for-tests"


@pytest.fixture(scope="module")
def keyed(tmp_path_factory) -> Iterator[tuple[Service, Service]]:
    """Two API processes on one database (no workers needed): collections a and b."""
    svc = make_service(tmp_path_factory, "keyed", SHAPES_API_KEY=ADMIN)
    replica = Service(svc.data_dir)
    replica.env.update(svc.env, SHAPES_INDEX_DIR=str(svc.data_dir / "index-replica"))
    try:
        svc.start_api()
        replica.start_api()
        for name in ("a", "b"):
            made = svc.client.post("/collections", json={"name": name}, headers=_as(ADMIN))
            assert made.status_code == 201, made.text
        yield svc, replica
    finally:
        replica.close()
        svc.close()


def _as(key: str) -> dict[str, str]:
    return {"X-API-Key": key}


def _key(svc: Service, collection: str, scope: str) -> tuple[int, str]:
    made = svc.client.post(
        "/keys", json={"collection": collection, "scope": scope}, headers=_as(ADMIN)
    )
    assert made.status_code == 201, made.text
    body = made.json()
    assert body["key"].startswith("shp_") and body["collection"] == collection
    return body["id"], body["key"]


def _upload(svc: Service, collection: str, key: str, name: str = "quadruped-0"):
    files = {"file": (f"{name}.off.gz", example(name).read_bytes())}
    return svc.client.post(f"/collections/{collection}/meshes", files=files, headers=_as(key))


def _forbidden(response) -> None:
    assert response.status_code == 403, response.text
    assert response.json()["error"] == "forbidden"


def test_a_read_key_reads_its_collection_and_nothing_else(keyed):
    svc, _ = keyed
    _, read_a = _key(svc, "a", "read")
    _, write_a = _key(svc, "a", "write")
    enrolled = _upload(svc, "a", write_a)
    assert enrolled.status_code == 202, enrolled.text
    mesh_id = enrolled.json()["id"]
    # Read: list, download, search, calibration (409: too few pairs, but allowed).
    assert svc.client.get("/collections/a/meshes", headers=_as(read_a)).json()["total"] == 1
    file = svc.client.get(f"/collections/a/meshes/{mesh_id}/file", headers=_as(read_a))
    assert file.content == example("quadruped-0").read_bytes()
    calibration = svc.client.get("/collections/a/calibration", headers=_as(read_a))
    assert calibration.status_code == 409
    assert svc.client.get("/collections/a", headers=_as(read_a)).status_code == 200
    # Not write: enroll and delete are refused, and nothing changed.
    _forbidden(_upload(svc, "a", read_a, "hand-0"))
    _forbidden(svc.client.delete(f"/collections/a/meshes/{mesh_id}", headers=_as(read_a)))
    # Not b, nor the default collection through the old paths, nor a collection unknown.
    for method, path in (
        ("GET", "/collections/b/meshes"),
        ("GET", "/collections/b"),
        ("GET", "/meshes"),
        ("GET", "/calibration"),
        ("GET", "/collections/zzz/meshes"),
    ):
        _forbidden(svc.client.request(method, path, headers=_as(read_a)))
    _forbidden(_upload(svc, "b", read_a))
    # Listing shows the collections it may read.
    listed = svc.client.get("/collections", headers=_as(read_a)).json()["items"]
    assert [c["name"] for c in listed] == ["a"]
    # Neither collections nor keys are its business.
    _forbidden(svc.client.post("/collections", json={"name": "c"}, headers=_as(read_a)))
    _forbidden(svc.client.get("/keys", headers=_as(read_a)))
    _forbidden(svc.client.delete("/collections/a", headers=_as(write_a)))
    # The write key deletes in its collection.
    deleted = svc.client.delete(f"/collections/a/meshes/{mesh_id}", headers=_as(write_a))
    assert deleted.status_code == 204


def test_an_all_collections_key_and_a_collection_admin(keyed):
    svc, _ = keyed
    _, everywhere = _key(svc, "*", "read")
    for path in ("/meshes", "/collections/a/meshes", "/collections/b/meshes"):
        assert svc.client.get(path, headers=_as(everywhere)).status_code == 200, path
    _forbidden(_upload(svc, "b", everywhere))
    made = svc.client.post("/collections", json={"name": "temp"}, headers=_as(ADMIN))
    assert made.status_code == 201
    _, temp_admin = _key(svc, "temp", "admin")
    _forbidden(
        svc.client.post(
            "/keys", json={"collection": "temp", "scope": "read"}, headers=_as(temp_admin)
        )
    )
    assert svc.client.delete("/collections/temp", headers=_as(temp_admin)).status_code == 204
    # Its collection gone, so is the key.
    gone = svc.client.get("/collections/a", headers=_as(temp_admin))
    assert gone.status_code == 401


def test_a_revoked_key_is_refused_within_a_second_on_every_replica(keyed):
    svc, replica = keyed
    key_id, key = _key(svc, "a", "read")
    for api in (svc, replica):  # both have it cached
        assert api.client.get("/collections/a/meshes", headers=_as(key)).status_code == 200
    assert svc.client.delete(f"/keys/{key_id}", headers=_as(ADMIN)).status_code == 204
    revoked = time.monotonic()
    refused = svc.client.get("/collections/a/meshes", headers=_as(key))
    assert refused.status_code == 401 and "revoked" in refused.json()["detail"]
    while replica.client.get("/collections/a/meshes", headers=_as(key)).status_code != 401:
        assert time.monotonic() - revoked < 1.0, "the replica still accepts a revoked key"
        time.sleep(0.05)
    listed = svc.client.get("/keys", headers=_as(ADMIN)).json()["items"]
    assert key_id not in {k["id"] for k in listed}
    assert svc.client.delete(f"/keys/{key_id}", headers=_as(ADMIN)).status_code == 404


def test_no_key_is_stored_in_plain_text(keyed):
    svc, _ = keyed
    _, key = _key(svc, "b", "write")
    listed = svc.client.get("/keys", headers=_as(ADMIN)).json()["items"]
    assert all(set(k) == {"id", "collection", "scope", "created_at"} for k in listed)
    database = (svc.data_dir / "shapes.sqlite3").read_bytes()
    wal = svc.data_dir / "shapes.sqlite3-wal"
    stored = database + (wal.read_bytes() if wal.exists() else b"")
    assert key.encode() not in stored and ADMIN.encode() not in stored
    with sqlite3.connect(svc.data_dir / "shapes.sqlite3") as db:
        hashes = [h for (h,) in db.execute("SELECT key_sha256 FROM api_keys")]
    assert hashes and all(len(h) == 64 for h in hashes)


def test_keys_need_an_admin_key(hardened: Service):
    refused = hardened.client.post("/keys", json={"collection": "*", "scope": "read"})
    assert refused.status_code == 409 and refused.json()["error"] == "no_admin_key"


def test_without_a_key_the_service_serves_on_loopback_only():
    assert "open to everyone on this machine" in access_notice(Settings(host="127.0.0.1"))
    with pytest.raises(ValueError, match="refusing to serve on 0.0.0.0 without an API key"):
        access_notice(Settings(host="0.0.0.0"))
    assert "SHAPES_OPEN_ACCESS" in access_notice(Settings(host="0.0.0.0", open_access=True))
    assert "API keys required" in access_notice(Settings(host="0.0.0.0", api_key=ADMIN))


@pytest.mark.parametrize("key", ["", "k", "fifteen-chars-k"])
def test_an_admin_key_too_short_to_protect_anything_is_refused_at_start(key, tmp_path):
    with pytest.raises(ValidationError, match="SHAPES_API_KEY must be at least 16 characters"):
        Settings(api_key=key)
    served = subprocess.run(
        [sys.executable, "-m", "app", "--data-dir", str(tmp_path)],
        env={**os.environ, "SHAPES_API_KEY": key},
        capture_output=True,
        text=True,
        timeout=60,
        cwd=REPO,
    )
    assert served.returncode == 2
    assert "SHAPES_API_KEY must be at least 16 characters" in served.stderr
    assert "Traceback" not in served.stderr


def test_keys_from_the_command_line(keyed):
    svc, _ = keyed

    def shapes(*args: str) -> subprocess.CompletedProcess[str]:
        command = [sys.executable, "-m", "app.cli", "keys", *args, "--url", svc.url]
        return subprocess.run(
            [*command, "--api-key", ADMIN], cwd=REPO, capture_output=True, text=True, timeout=120
        )

    made = shapes("create", "b", "read")
    assert made.returncode == 0, made.stderr
    key = made.stdout.strip()
    assert key.startswith("shp_") and "shown this once" in made.stderr
    assert svc.client.get("/collections/b/meshes", headers=_as(key)).status_code == 200
    key_id = made.stderr.split()[1].rstrip(":")
    listed = shapes("list")
    assert listed.returncode == 0 and any(
        line.split()[:3] == [key_id, "b", "read"] for line in listed.stdout.splitlines()
    )
    assert shapes("revoke", key_id).stdout.strip() == f"revoked key {key_id}"
    assert svc.client.get("/collections/b/meshes", headers=_as(key)).status_code == 401
    unknown = shapes("create", "nowhere", "read")
    assert unknown.returncode == 1 and "collection_not_found" in unknown.stderr


def test_a_collection_made_on_one_replica_is_served_by_the_other(keyed):
    svc, replica = keyed
    made = svc.client.post("/collections", json={"name": "shared"}, headers=_as(ADMIN))
    assert made.status_code == 201
    # At once: a name the replica does not know yet is looked up in the database.
    listed = replica.client.get("/collections/shared/meshes", headers=_as(ADMIN))
    assert listed.status_code == 200 and listed.json()["total"] == 0
    assert svc.client.delete("/collections/shared", headers=_as(ADMIN)).status_code == 204
    deadline = time.monotonic() + 10  # the replica's next collector rounds
    while replica.client.get("/collections/shared/meshes", headers=_as(ADMIN)).status_code != 404:
        assert time.monotonic() < deadline, "the replica still serves a deleted collection"
        time.sleep(0.1)
