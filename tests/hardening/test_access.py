"""Access: an optional API key on every request for a collection, file names kept out of
paths, CORS closed."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from conftest import example

from benchmarks.common import Service

from .conftest import make_service

KEY = "s3cret-key-for-tests"
ORIGIN = "https://shapes.example"


@pytest.fixture(scope="module")
def guarded(tmp_path_factory) -> Iterator[Service]:
    """A service with an API key and one allowed browser origin (no workers needed)."""
    svc = make_service(
        tmp_path_factory, "guarded", SHAPES_API_KEY=KEY, SHAPES_CORS_ORIGINS=f'["{ORIGIN}"]'
    )
    try:
        svc.start_api()
        yield svc
    finally:
        svc.close()


def _unauthorized(response, sentence: str) -> None:
    assert response.status_code == 401, response.text
    assert response.json() == {"error": "unauthorized", "detail": response.json()["detail"]}
    assert sentence in response.json()["detail"]
    assert response.headers["www-authenticate"] == "X-API-Key"


def test_every_request_for_a_collection_needs_the_key(guarded: Service):
    files = {"file": ("quadruped-0.off.gz", example("quadruped-0").read_bytes())}
    requests = [
        ("POST", "/meshes", {"files": files}),
        ("POST", "/query", {"files": files}),
        ("DELETE", "/meshes/1", {}),
        ("POST", "/meshes/1/similar", {}),
        ("GET", "/meshes", {}),
        ("GET", "/meshes/1/file", {}),
        ("GET", "/calibration", {}),
        ("GET", "/collections", {}),
        ("GET", "/collections/default/meshes", {}),
        ("GET", "/jobs/1", {}),
        ("GET", "/keys", {}),
    ]
    for method, path, kwargs in requests:
        _unauthorized(guarded.client.request(method, path, **kwargs), "X-API-Key header")
        wrong = guarded.client.request(method, path, headers={"X-API-Key": KEY[:-1]}, **kwargs)
        _unauthorized(wrong, "not valid")
        longer = guarded.client.request(method, path, headers={"X-API-Key": KEY + "x"}, **kwargs)
        _unauthorized(longer, "not valid")
    assert not list((guarded.data_dir / "tmp").glob("upload-*"))  # refused before reading
    for path in ("/health", "/ready", "/", "/openapi.json"):
        assert guarded.client.get(path).status_code == 200, path

    admin = {"X-API-Key": KEY}
    assert guarded.client.get("/meshes", headers=admin).json()["total"] == 0  # nothing got in
    created = guarded.client.post("/meshes", files=files, headers=admin)
    assert created.status_code == 202, created.text
    mesh_id = created.json()["id"]
    for path in ("/meshes", f"/meshes/{mesh_id}", f"/meshes/{mesh_id}/file"):
        assert guarded.client.get(path, headers=admin).status_code == 200, path
    assert guarded.client.delete(f"/meshes/{mesh_id}", headers=admin).status_code == 204


def test_the_key_is_documented_in_the_schema(guarded: Service):
    schema = guarded.client.get("/openapi.json").json()
    assert schema["components"]["securitySchemes"]["APIKeyHeader"]["name"] == "X-API-Key"
    for path, method in (("/meshes", "post"), ("/meshes", "get"), ("/keys", "post")):
        responses = schema["paths"][path][method]["responses"]
        assert {"401", "403"} <= set(responses), (path, method)
    assert "security" not in schema["paths"]["/health"]["get"]


def test_file_names_never_reach_a_path(guarded: Service):
    hostile = "../../etc/passwd.obj"
    data = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# traversal\n"
    created = guarded.client.post(
        "/meshes", files={"file": (hostile, data)}, headers={"X-API-Key": KEY}
    )
    assert created.status_code == 202, created.text
    body = created.json()
    assert body["filename"] == "passwd.obj" and body["name"] == "passwd"
    stored = [p for p in guarded.data_dir.rglob("*") if p.is_file() and p.read_bytes() == data]
    assert stored == [guarded.data_dir / "uploads" / body["sha256"][:2] / body["sha256"]]
    assert not (guarded.data_dir.parent / "etc").exists()
    download = guarded.client.get(f"/meshes/{body['id']}/file", headers={"X-API-Key": KEY})
    assert download.content == data
    assert "passwd.obj" in download.headers["content-disposition"]
    assert ".." not in download.headers["content-disposition"]
    for name in ("..\\..\\windows\\win.ini.obj", "/abs/olute.obj\x00.txt"):
        response = guarded.client.post(
            "/meshes", files={"file": (name, data + name.encode())}, headers={"X-API-Key": KEY}
        )
        assert response.status_code in (202, 415), response.text
        if response.status_code == 202:
            assert "/" not in response.json()["filename"]
            assert "\\" not in response.json()["filename"]


def test_cors_allows_only_the_configured_origin(guarded: Service, hardened: Service):
    preflight = {
        "Access-Control-Request-Method": "POST",
        "Access-Control-Request-Headers": "x-api-key",
    }
    allowed = guarded.client.options("/meshes", headers={"Origin": ORIGIN, **preflight})
    assert allowed.status_code == 200
    assert allowed.headers["access-control-allow-origin"] == ORIGIN
    other = guarded.client.options(
        "/meshes", headers={"Origin": "https://evil.example", **preflight}
    )
    assert "access-control-allow-origin" not in other.headers
    # Closed by default: the service without SHAPES_CORS_ORIGINS sends no CORS headers.
    default = hardened.client.get("/health", headers={"Origin": ORIGIN})
    assert "access-control-allow-origin" not in default.headers


def test_no_key_configured_means_open_writes(hardened: Service):
    response = hardened.client.post("/meshes/999999/similar")
    assert response.status_code == 404  # past the key check, to the lookup
