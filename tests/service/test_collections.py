"""Collections: galleries side by side in one service, each with its own meshes, index
and calibration; the paths without ``/collections/{name}`` keep working on ``default``."""

from __future__ import annotations

import gzip
import io
import sqlite3
from collections.abc import Iterator

import numpy as np
import pytest
import trimesh
from alembic import command
from conftest import example

from app.migrations import alembic_config
from benchmarks.common import Service
from worker.engine.mesh_io import Mesh
from worker.evaluation.partial import planar_cut

from .conftest import migrated_service, running

pytestmark = [pytest.mark.slow, pytest.mark.service]

# Enough labelled pairs to calibrate (10 of each kind): a 18 genuine and 48 impostor
# pairs; b 12 and 24.
A = {f"{kind}-{pose}": kind for kind in ("quadruped", "hand", "bird") for pose in range(4)}
B = {f"{kind}-{pose}": kind for kind in ("biped", "spider") for pose in range(4)} | {
    "quadruped-0": "quadruped"
}


@pytest.fixture(scope="module")
def two(tmp_path_factory) -> Iterator[tuple[Service, dict[str, dict[str, int]]]]:
    """A service with collections ``a`` and ``b`` enrolled (``b`` shares one file with
    ``a``) and one mesh in ``default``: collection -> name -> id."""
    with running(migrated_service(tmp_path_factory, "collections")) as svc:
        for name in ("a", "b"):
            created = svc.client.post("/collections", json={"name": name})
            assert created.status_code == 201, created.text
            assert created.headers["location"] == f"/collections/{name}"
        ids: dict[str, dict[str, int]] = {"a": {}, "b": {}, "default": {}}
        for collection, meshes in (("a", A), ("b", B)):
            for name, label in meshes.items():
                answer = svc.upload(name, label, collection=collection)
                assert answer.status_code == 202, answer.text
                ids[collection][name] = answer.json()["id"]
        ids["default"]["hand-0"] = svc.upload("hand-0", "hand").json()["id"]
        for collection, meshes in ids.items():
            where = None if collection == "default" else collection
            for mesh_id in meshes.values():
                assert svc.wait_mesh(mesh_id, collection=where)["status"] == "ready"
        yield svc, ids


def test_collections_are_listed_with_their_meshes(two):
    svc, ids = two
    listed = {c["name"]: c for c in svc.client.get("/collections").json()["items"]}
    assert list(listed) == ["default", "a", "b"]
    assert (listed["a"]["meshes"], listed["a"]["ready"]) == (12, 12)
    assert listed["b"]["units"] == "any" and listed["b"]["links"]["query"] == "/collections/b/query"
    assert listed["default"]["meshes"] == 1
    one = svc.client.get("/collections/b").json()
    assert one == listed["b"]
    assert one["preset"] == listed["default"]["preset"]  # the service's, when not given


def test_the_same_bytes_are_two_meshes_in_two_collections(two):
    svc, ids = two
    in_a, in_b = ids["a"]["quadruped-0"], ids["b"]["quadruped-0"]
    assert in_a != in_b
    a = svc.client.get(f"/collections/a/meshes/{in_a}").json()
    b = svc.client.get(f"/collections/b/meshes/{in_b}").json()
    assert a["sha256"] == b["sha256"] and (a["collection"], b["collection"]) == ("a", "b")
    assert b["links"]["self"] == f"/collections/b/meshes/{in_b}"
    # Each collection's mesh is found in its own collection only.
    other = svc.client.get(f"/collections/a/meshes/{in_b}")
    assert other.status_code == 404 and "collection 'a'" in other.json()["detail"]
    assert svc.client.get(f"/meshes/{in_a}").status_code == 404
    # Enrolling the same bytes again in b answers b's mesh, not a's.
    again = svc.upload("quadruped-0", "quadruped", collection="b")
    assert again.status_code == 200 and again.json()["id"] == in_b


def test_a_query_ranks_its_own_collection_only(two):
    svc, ids = two
    in_a = svc.query("quadruped-3", collection="a", k=20).json()
    assert {m["mesh_id"] for m in in_a["matches"]} == set(ids["a"].values())
    assert in_a["gallery_size"] == 12 and in_a["matches"][0]["label"] == "quadruped"
    assert in_a["collection"] == "a"
    in_b = svc.query("quadruped-3", collection="b", k=20).json()
    assert {m["mesh_id"] for m in in_b["matches"]} == set(ids["b"].values())
    # The old path is the default collection.
    default = svc.query("quadruped-3", k=20).json()
    assert [m["mesh_id"] for m in default["matches"]] == [ids["default"]["hand-0"]]
    similar = svc.client.post(f"/collections/b/meshes/{ids['b']['biped-0']}/similar").json()
    assert {m["mesh_id"] for m in similar["matches"]} == set(ids["b"].values()) - {
        ids["b"]["biped-0"]
    }
    assert similar["preview"] == f"/collections/b/meshes/{ids['b']['biped-0']}/preview"
    assert svc.client.get(similar["preview"]).status_code == 200


def test_each_collection_calibrates_on_its_own_pairs(two):
    svc, ids = two
    a = svc.client.get("/collections/a/calibration").json()
    assert a["collection"] == "a" and a["labelled_shapes"] == 12
    assert (a["genuine_pairs"], a["impostor_pairs"]) == (18, 48)
    b = svc.client.get("/collections/b/calibration").json()
    assert b["labelled_shapes"] == 9 and (b["genuine_pairs"], b["impostor_pairs"]) == (12, 24)
    verified = svc.client.post(
        "/collections/b/verify",
        files={"mesh_id": (None, str(ids["b"]["biped-1"])), "claim_label": (None, "biped")},
    )
    assert verified.status_code == 200 and verified.json()["candidates"] == 3
    # a's label is not b's claim.
    hand = svc.client.post(
        "/collections/b/verify",
        files={"mesh_id": (None, str(ids["b"]["biped-1"])), "claim_label": (None, "hand")},
    )
    assert hand.status_code == 404 and hand.json()["error"] == "claim_not_found"


def test_bad_names_and_unknown_collections_are_refused(two):
    svc, _ = two
    taken = svc.client.post("/collections", json={"name": "a"})
    assert taken.status_code == 409 and taken.json()["error"] == "collection_exists"
    for body in ({"name": "no spaces"}, {"name": ""}, {"name": "x", "units": "feet"}):
        refused = svc.client.post("/collections", json=body)
        assert refused.status_code == 422, body
        assert refused.json()["error"] == "invalid_input", refused.text
    preset = svc.client.post("/collections", json={"name": "p", "preset": "nope"})
    assert preset.status_code == 422 and preset.json()["error"] == "unknown_preset"
    for path in ("/collections/zzz", "/collections/zzz/meshes", "/collections/zzz/calibration"):
        missing = svc.client.get(path)
        assert missing.status_code == 404 and missing.json()["error"] == "collection_not_found"
    default = svc.client.delete("/collections/default")
    assert default.status_code == 409 and default.json()["error"] == "default_collection"


def test_the_scoped_operations_are_documented_with_their_links(two):
    svc, _ = two
    schema = svc.client.get("/openapi.json").json()
    enroll = schema["paths"]["/collections/{collection}/meshes"]["post"]
    assert enroll["operationId"] == "collection_enroll_mesh"
    assert any(p["name"] == "collection" and p["in"] == "path" for p in enroll["parameters"])
    link = enroll["responses"]["202"]["links"]["GetMesh"]
    assert link["operationId"] == "collection_get_mesh"
    assert link["parameters"]["collection"] == "$request.path.collection"
    assert schema["paths"]["/meshes"]["post"]["operationId"] == "enroll_mesh"
    ids = [op["operationId"] for ops in schema["paths"].values() for op in ops.values()]
    assert len(ids) == len(set(ids))


def test_deleting_a_collection_keeps_what_another_shares(two):
    svc, ids = two
    shared = ids["a"]["quadruped-0"]
    before = svc.client.get(f"/collections/a/meshes/{shared}/file").content
    made = svc.client.post("/collections", json={"name": "gone"})
    assert made.status_code == 201
    only = svc.upload("biped-0", "biped", collection="gone").json()["id"]
    svc.upload("quadruped-0", "quadruped", collection="gone")
    assert svc.client.delete("/collections/gone").status_code == 204
    assert svc.client.get("/collections/gone").status_code == 404
    assert svc.client.get(f"/collections/gone/meshes/{only}").status_code == 404
    # a's mesh of the same bytes keeps its file; a's search is unchanged.
    assert svc.client.get(f"/collections/a/meshes/{shared}/file").content == before
    assert svc.query("quadruped-3", collection="a").json()["gallery_size"] == 12
    # The name can be used again: a new, empty collection.
    again = svc.client.post("/collections", json={"name": "gone"}).json()
    assert again["meshes"] == 0
    assert svc.client.get("/collections/gone/meshes").json()["total"] == 0


def test_a_collections_fusion_weights_can_be_pinned_and_unpinned(two):
    svc, _ = two
    before = svc.client.get("/collections/a/calibration").json()["fusion"]
    assert before["source"] in ("preset", "learned")
    pin = {"gdm": 1.0, "ddt": 0.0, "spectrum": 0.25}
    pinned = svc.client.put("/collections/a/fusion", json={"weights": pin})
    assert pinned.status_code == 200 and pinned.json()["fusion_weights"] == pin
    fusion = svc.client.get("/collections/a/calibration").json()["fusion"]
    assert fusion["source"] == "pinned" and fusion["weights"] == pin
    assert "PUT /collections/{name}/fusion" in fusion["reason"]
    # b keeps its own; a search in a ranks with the pinned weights.
    assert svc.client.get("/collections/b/calibration").json()["fusion"]["source"] != "pinned"
    ranked = svc.query("quadruped-3", collection="a", k=3).json()["matches"][0]
    scores = ranked["scores"]
    assert ranked["score"] == pytest.approx(scores["gdm"] * scores["spectrum"] ** 0.25)
    for bad in ({"gdm": 1, "ddt": 1, "spectrum": -1}, {"gdm": 1, "colour": 1}, {"gdm": 101}):
        refused = svc.client.put("/collections/a/fusion", json={"weights": bad})
        assert refused.status_code == 422 and refused.json()["error"] == "invalid_input", bad
    # A modality left out keeps the preset's weight (the default's spectrum: 1).
    some = svc.client.put("/collections/a/fusion", json={"weights": {"gdm": 0.5, "ddt": 0}})
    assert some.status_code == 200
    weights = svc.client.get("/collections/a/calibration").json()["fusion"]["weights"]
    assert weights == {"gdm": 0.5, "ddt": 0.0, "spectrum": 1.0}
    unpinned = svc.client.put("/collections/a/fusion", json={"weights": None})
    assert unpinned.status_code == 200 and unpinned.json()["fusion_weights"] is None
    after = svc.client.get("/collections/a/calibration").json()["fusion"]
    assert after["source"] in ("preset", "learned")


def _scaled(name: str, factor: float, cut: float = 0.0) -> bytes:
    """The example ``name`` as an OFF file, scaled by ``factor``, the share ``cut`` of
    its area cut off along x."""
    data = io.BytesIO(gzip.decompress(example(name).read_bytes()))
    mesh = trimesh.load(data, file_type="off", process=False)
    mesh.apply_scale(factor)
    if cut:
        part = planar_cut(Mesh(mesh.vertices, mesh.faces), cut, np.array([1.0, 0.0, 0.0]))
        mesh = trimesh.Trimesh(part.vertices, part.faces, process=False)
    return mesh.export(file_type="off").encode()


def test_a_metric_collection_tells_sizes_apart(two):
    """The same shape at twice the size: one object among others in a collection of
    arbitrary units, another in a metric one, where the size is fused with the shape."""
    svc, _ = two
    files = {"hand-0": _scaled("hand-0", 1.0), "hand-0-large": _scaled("hand-0", 2.0)}
    found = {}
    for units in ("any", "metric"):
        name = f"sizes-{units}"
        made = svc.client.post("/collections", json={"name": name, "units": units})
        assert made.status_code == 201 and made.json()["units"] == units
        ids = {}
        for label, data in files.items():
            answer = svc.client.post(
                f"/collections/{name}/meshes",
                files={"file": (f"{label}.off", data)},
                data={"label": label},
            )
            assert answer.status_code == 202, answer.text
            ids[label] = answer.json()["id"]
        for mesh_id in ids.values():
            assert svc.wait_mesh(mesh_id, collection=name)["status"] == "ready"
        for probe, data in (
            ("whole", _scaled("hand-1", 2.0)),
            ("cut", _scaled("hand-1", 2.0, 0.3)),
        ):
            answer = svc.client.post(
                f"/collections/{name}/query",
                files={"file": (f"{probe}.off", data)},
                data={"k": "2"},
            )
            assert answer.status_code == 200, answer.text
            found[units, probe] = answer.json()
    metric = found["metric", "whole"]
    # Ranked by the modalities of a weight above 0 (the default's GDM is weighed 0).
    assert metric["modalities"] == ["ddt", "spectrum", "size"]
    assert list(metric["weights"]) == ["gdm", "ddt", "spectrum", "size"]
    assert [m["name"] for m in metric["matches"]] == ["hand-0-large", "hand-0"]
    large, small = (m["scores"]["size"] for m in metric["matches"])
    assert large < 0.1 < 0.5 < small  # 2x apart: eq. (8) of the sizes is 2/3
    scale_free = found["any", "whole"]
    assert scale_free["modalities"] == ["ddt", "spectrum"]
    assert all("size" not in m["scores"] for m in scale_free["matches"])
    # Scale-free, the two enrolled files are the same shape: their scores barely differ.
    first, second = (m["score"] for m in scale_free["matches"])
    assert second < 1.5 * first
    # A part: its size and each shape's give the share it keeps of each. The small copy
    # is too small to hold it: no match; scale-free, the two hold it alike.
    cut = found["metric", "cut"]
    assert cut["modalities"] == ["parts"]
    assert [m["name"] for m in cut["matches"]] == ["hand-0-large"]
    free = [m["scores"]["parts"] for m in found["any", "cut"]["matches"]]
    assert abs(free[0] - free[1]) < 0.01


def test_the_migration_moves_every_mesh_into_the_default_collection(tmp_path):
    url = f"sqlite:///{tmp_path / 'shapes.sqlite3'}"
    command.upgrade(alembic_config(url), "0006")
    with sqlite3.connect(tmp_path / "shapes.sqlite3") as db:
        db.execute(
            "INSERT INTO meshes (id, sha256, name, metadata, filename, size_bytes, "
            "storage_path, status, created_at, updated_at) VALUES (5, ?, 'm', '{}', "
            "'m.off', 3, 'x', 'ready', '2026-01-01', '2026-01-01')",
            ("a" * 64,),
        )
        db.execute(
            "INSERT INTO descriptors (mesh_id, preset, preset_version, data, input_vertices, "
            "input_faces, vertices, timings, created_at) VALUES "
            "(5, 'p', 1, x'00', 1, 1, 1, '{}', '2026-01-01')"
        )
    command.upgrade(alembic_config(url), "head")
    with sqlite3.connect(tmp_path / "shapes.sqlite3") as db:
        assert db.execute("SELECT id, name, units FROM collections").fetchall() == [
            (1, "default", "any")
        ]
        assert db.execute("SELECT id, collection_id FROM meshes").fetchall() == [(5, 1)]
        # Re-creating the table kept the rows that refer to it, and AUTOINCREMENT.
        assert db.execute("SELECT mesh_id FROM descriptors").fetchall() == [(5,)]
        (sql,) = db.execute("SELECT sql FROM sqlite_master WHERE name = 'meshes'").fetchone()
        assert "AUTOINCREMENT" in sql
    command.downgrade(alembic_config(url), "0006")
    with sqlite3.connect(tmp_path / "shapes.sqlite3") as db:
        assert db.execute("SELECT mesh_id FROM descriptors").fetchall() == [(5,)]


def test_tosca_cats_and_dogs_in_two_collections(two, tosca_dir):
    """The issue's check: TOSCA's cats in a collection of any units, its dogs in a metric
    one; a query in the cats' never returns a dog, the dogs' calibration counts the dogs'
    pairs only (all genuine: not enough impostor pairs to calibrate)."""
    svc, _ = two
    for name, units in (("cats", "any"), ("dogs", "metric")):
        assert (
            svc.client.post("/collections", json={"name": name, "units": units}).status_code == 201
        )
    enrolled: dict[str, list[int]] = {"cats": [], "dogs": []}
    for collection, kind in (("cats", "cat"), ("dogs", "dog")):
        for path in sorted(tosca_dir.glob(f"{kind}[0-9]*.off.gz")):
            with open(path, "rb") as handle:
                answer = svc.client.post(
                    f"/collections/{collection}/meshes",
                    files={"file": (path.name, handle)},
                    data={"label": kind},
                )
            assert answer.status_code == 202, answer.text
            enrolled[collection].append(answer.json()["id"])
    for collection, ids in enrolled.items():
        for mesh_id in ids:
            assert svc.wait_mesh(mesh_id, collection=collection)["status"] == "ready"
    for dog in sorted(tosca_dir.glob("dog[0-9]*.off.gz")):
        with open(dog, "rb") as handle:
            answer = svc.client.post(
                "/collections/cats/query", files={"file": (dog.name, handle)}, data={"k": "50"}
            ).json()
        assert {m["label"] for m in answer["matches"]} == {"cat"}
        assert {m["mesh_id"] for m in answer["matches"]} == set(enrolled["cats"])
    dogs = svc.client.get("/collections/dogs/calibration")
    assert dogs.status_code == 409
    n = len(enrolled["dogs"])
    assert (
        f"make {n * (n - 1) // 2} genuine (same label) and 0 impostor pairs"
        in dogs.json()["detail"]
    )
    cats = svc.client.get("/collections/cats/calibration")
    assert cats.status_code == 409 and "0 impostor pairs" in cats.json()["detail"]
