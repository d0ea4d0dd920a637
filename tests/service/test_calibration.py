"""Calibrated answers through HTTP: /calibration, /verify, confidences, open-set /query."""

from __future__ import annotations

import time
from collections.abc import Iterator
from itertools import combinations

import numpy as np
import pytest
from conftest import example

from benchmarks.common import Service
from worker.recognition.fusion import REPEATS, feasible_folds

from .conftest import migrated_service, running

#: Four classes, 1-4 poses each: 12 genuine and 43 impostor pairs once all are ready.
#: Not enrolled: hand-3 and biped-3 (other poses of enrolled classes), the spiders.
LABELLED = {
    "quadruped-0": "quadruped",
    "quadruped-1": "quadruped",
    "quadruped-2": "quadruped",
    "quadruped-3": "quadruped",
    "biped-0": "biped",
    "biped-1": "biped",
    "biped-2": "biped",
    "hand-0": "hand",
    "hand-1": "hand",
    "hand-2": "hand",
    "bird-0": "bird",
}


def form(**fields: str) -> dict[str, tuple[None, str]]:
    """Multipart form fields without a file (what /verify takes for an enrolled probe)."""
    return {name: (None, value) for name, value in fields.items()}


def pair_counts(labels: list[str]) -> tuple[int, int]:
    same = sum(a == b for a, b in combinations(labels, 2))
    return same, len(labels) * (len(labels) - 1) // 2 - same


@pytest.fixture(scope="module")
def verifier(tmp_path_factory) -> Iterator[Service]:
    """A service that refits its calibration on every change."""
    svc = migrated_service(tmp_path_factory, "calibrated", SHAPES_CALIBRATION_REFIT_SECONDS="0")
    with running(svc) as started:
        yield started


def enroll(svc: Service, names: dict[str, str]) -> dict[str, int]:
    ids = {name: svc.upload(name, label).json()["id"] for name, label in names.items()}
    for mesh_id in ids.values():
        assert svc.wait_mesh(mesh_id)["status"] == "ready"
    return ids


def test_too_few_labelled_pairs_is_a_409_with_a_sentence(verifier: Service):
    enroll(verifier, {"quadruped-0": "quadruped", "biped-0": "biped"})
    response = verifier.client.get("/calibration")
    assert response.status_code == 409
    body = response.json()
    assert body["error"] == "not_calibrated" and "at least 10 of each" in body["detail"]
    refused = verifier.client.post("/verify", files=form(mesh_id="1", claim_label="biped"))
    assert refused.status_code == 409 and refused.json()["error"] == "not_calibrated"
    assert verifier.query("quadruped-1", far="0.01").json()["error"] == "not_calibrated"
    uncalibrated = verifier.query("quadruped-1", k=1).json()
    assert uncalibrated["matches"][0]["confidence"] is None


@pytest.fixture(scope="module")
def calibrated(verifier: Service) -> dict[str, int]:
    return enroll(verifier, LABELLED)


def test_calibration_counts_every_labelled_pair(verifier: Service, calibrated):
    body = verifier.client.get("/calibration").json()
    genuine, impostor = pair_counts(list(LABELLED.values()))
    assert (body["genuine_pairs"], body["impostor_pairs"]) == (genuine, impostor)
    assert body["labelled_shapes"] == len(LABELLED) and body["labels"] == 4
    assert body["trusted"] is False and not body["sampled"]
    points = body["operating_points"]
    assert [p["far"] for p in points] == [0.001, 0.01, 0.05]
    assert all(p["estimated_far"] <= p["far"] for p in points)
    thresholds = [p["threshold"] for p in points]
    assert thresholds == sorted(thresholds)
    assert 0.0 <= body["eer"] < 0.5
    assert set(body["modalities"]) == {"gdm", "ddt", "spectrum"}
    assert body["roc"]["far"][0] == 0.0 and body["roc"]["frr"][-1] == 0.0


def test_the_fusion_weights_are_learned_from_the_labels_and_ranked_with(
    verifier: Service, calibrated
):
    """Three labels have three or more shapes (the bird's one takes no part).
    Whatever was adopted, the fused scores of the answers use exactly those weights."""
    deadline = time.monotonic() + 60
    while (fusion := verifier.client.get("/calibration").json()["fusion"])["labelled_shapes"] < 10:
        assert time.monotonic() < deadline, fusion
        time.sleep(0.2)
    learned_on = [label for label in LABELLED.values() if label != "bird"]  # in id order
    assert fusion["labels"] == 3 and not fusion["sampled"]
    folds = feasible_folds(learned_on, repeats=REPEATS)
    assert len(fusion["folds"]) == folds * REPEATS  # every round's folds
    assert sum(f["held_out_shapes"] for f in fusion["folds"]) == 10 * REPEATS
    assert fusion["source"] in ("learned", "preset") and fusion["reason"]
    assert fusion["preset_weights"] == {"gdm": 0.0, "ddt": 0.5, "spectrum": 1.0}
    learned = fusion["held_out"]["eer"] + 1 - fusion["held_out"]["map"]
    preset = fusion["preset_held_out"]["eer"] + 1 - fusion["preset_held_out"]["map"]
    test = fusion["adoption"]
    assert test["gain"] == pytest.approx((preset - learned) / 2, abs=1e-12)
    assert (fusion["source"] == "learned") == test["adopted"]
    assert fusion["preset_comparisons"] == {"gdm": "D1", "ddt": "D1", "spectrum": "D1"}
    if fusion["source"] == "preset":
        assert fusion["comparisons"] == fusion["preset_comparisons"]
    weights = fusion["weights"]
    match = verifier.client.post(f"/meshes/{calibrated['biped-0']}/similar", params={"k": 1})
    best = match.json()["matches"][0]
    fused = np.prod([best["scores"][m] ** w for m, w in weights.items()])
    assert best["score"] == pytest.approx(fused, rel=1e-9)


def test_verify_answers_yes_for_the_same_object_and_no_for_another(verifier: Service, calibrated):
    with open(example("hand-3"), "rb") as fh:  # another pose, not enrolled
        same = verifier.client.post(
            "/verify",
            files={"file": ("hand-3.off.gz", fh)},
            data={"claim_label": "hand", "far": "0.05"},
        ).json()
    assert same["same"] is True and same["score"] <= same["threshold"]
    assert same["candidates"] == 3 and same["probe"] == "upload"
    assert same["estimated_far"] <= 0.05 and set(same["scores"]) == {"gdm", "ddt", "spectrum"}
    probe, claim = str(calibrated["quadruped-2"]), str(calibrated["biped-1"])
    different = verifier.client.post("/verify", files=form(mesh_id=probe, claim_id=claim)).json()
    assert different["same"] is False and different["far"] == 0.01
    assert different["confidence"] < same["confidence"]


def test_open_set_query_rejects_a_class_absent_from_the_gallery(verifier: Service, calibrated):
    absent = verifier.query("spider-0", k=3, far="0.01").json()
    assert absent["far"] == 0.01 and absent["threshold"] is not None
    assert [m["accepted"] for m in absent["matches"]] == [False, False, False]
    present = verifier.query("biped-3", k=1).json()
    assert present["matches"][0]["label"] == "biped"
    assert 0.0 <= present["matches"][0]["confidence"] <= 1.0
    assert present["matches"][0]["accepted"] is None  # no far asked
    # Any fusion a search asks for is calibrated too, from the same pairs.
    summed = verifier.query("biped-3", k=1, fusion="sum", far="0.01").json()
    assert 0.0 <= summed["matches"][0]["confidence"] <= 1.0
    assert summed["threshold"] is not None and summed["threshold"] != absent["threshold"]
    mesh_id = summed["matches"][0]["mesh_id"]
    pair = verifier.client.post(
        f"/meshes/{mesh_id}/similar", params={"modalities": "gdm,ddt", "far": "0.01", "k": 1}
    )
    assert pair.status_code == 200, pair.text
    assert (
        pair.json()["threshold"] is not None and pair.json()["matches"][0]["accepted"] is not None
    )


def test_deleted_shapes_leave_the_calibration(verifier: Service, calibrated):
    before = verifier.client.get("/calibration").json()
    assert verifier.client.delete(f"/meshes/{calibrated['bird-0']}").status_code == 204
    after = verifier.client.get("/calibration").json()
    assert after["labelled_shapes"] == before["labelled_shapes"] - 1
    labels = [label for name, label in LABELLED.items() if name != "bird-0"]
    assert (after["genuine_pairs"], after["impostor_pairs"]) == pair_counts(labels)
