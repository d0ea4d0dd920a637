"""``shapes import`` and ``shapes query`` against a real service, as a person runs them."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator

import pytest
from conftest import EXAMPLES, example, with_a_far_half_copy

from app.client import default_url, mesh_files
from benchmarks.common import REPO, Service

from .conftest import migrated_service, running


@pytest.fixture(scope="module")
def served(tmp_path_factory) -> Iterator[Service]:
    with running(migrated_service(tmp_path_factory, "cli")) as svc:
        yield svc


def shapes(svc: Service, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args, "--url", svc.url],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Two examples, a broken file and a file that is not a mesh, with labels."""
    root = tmp_path_factory.mktemp("import")
    for name in ("quadruped-0", "biped-0"):
        shutil.copy(example(name), root)
    (root / "broken.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n")  # a face, but no third vertex
    (root / "notes.txt").write_text("not a mesh: skipped")
    (root / "labels.csv").write_text(
        "file,class\nquadruped-0.off.gz,quadruped\nbiped-0.off.gz,biped\n"
    )
    return root


def test_import_reports_the_broken_file_and_resumes(served: Service, folder):
    first = shapes(served, "import", str(folder), "--labels", str(folder / "labels.csv"), "--wait")
    assert first.returncode == 1, first.stderr
    assert "3 files: 2 enrolled, 0 already enrolled, 1 failed" in first.stdout
    reason = next(line for line in first.stdout.splitlines() if line.startswith("broken.off"))
    assert "unreadable_mesh" in reason  # the service's code and sentence
    assert "upload" in first.stderr and "ETA" in first.stderr  # the progress bars
    listed = served.client.get("/meshes", params={"status": "ready"}).json()["items"]
    assert {(m["name"], m["label"]) for m in listed} == {
        ("quadruped-0", "quadruped"),
        ("biped-0", "biped"),
    }

    again = shapes(served, "import", str(folder), "--labels", str(folder / "labels.csv"))
    # Nothing uploaded twice; the file that failed before is reported again.
    assert "3 files: 0 enrolled, 2 already enrolled, 1 failed" in again.stdout
    assert again.returncode == 1


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_an_interrupted_import_resumes_and_enrolls_nothing_twice(tmp_path_factory):
    # No descriptor worker: uploads only queue jobs, and all the examples take seconds.
    svc = migrated_service(tmp_path_factory, "interrupt")
    with running(svc, workers=0):
        files = mesh_files([str(EXAMPLES)])  # what the import takes: sub-folders too
        command = [sys.executable, "-m", "app.cli", "import", str(EXAMPLES), "--url", svc.url]
        first = subprocess.Popen(
            [*command, "--concurrency", "1"],
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            # Ctrl-C as in a terminal: a test run started in the background (`cmd &` in
            # a script) ignores SIGINT, and its children would inherit that.
            preexec_fn=_default_sigint,
        )
        # Interrupt right after the third upload, as its progress line says: polling the
        # service instead raced a fast machine, which had sent all of them before the signal.
        assert first.stderr is not None
        progress = []
        for line in first.stderr:
            progress.append(line)
            if f" 3/{len(files)} " in line:
                first.send_signal(signal.SIGINT)
                break
        _, rest = first.communicate(timeout=120)
        err = "".join(progress) + rest
        assert first.returncode == 130, err
        assert f"of {len(files)} files; run the same command again" in err
        stored = svc.client.get("/meshes", params={"limit": 100}).json()["total"]
        assert 3 <= stored < len(files)

        again = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=600)
        assert again.returncode == 0, again.stdout
        assert (
            f"{len(files)} files: {len(files) - stored} enrolled, {stored} already enrolled, "
            "0 failed" in again.stdout
        )
        names = [
            m["name"] for m in svc.client.get("/meshes", params={"limit": 100}).json()["items"]
        ]
        assert sorted(names) == sorted(f.name.split(".")[0] for f in files)
        # Queued (no worker here): its preview comes when it is described.
        queued = svc.client.get("/meshes", params={"limit": 1}).json()["items"][0]
        waiting = svc.client.get(queued["links"]["preview"])
        assert waiting.status_code == 409 and waiting.json()["error"] == "mesh_not_ready"


def test_query_prints_the_ranked_matches(served: Service, folder):
    table = shapes(served, "query", str(example("quadruped-1")), "-k", "2")
    assert table.returncode == 0, table.stderr
    lines = table.stdout.splitlines()
    assert lines[1].split()[:4] == ["rank", "name", "label", "score"]
    assert lines[2].split()[:3] == ["1", "quadruped-0", "quadruped"]
    body = json.loads(shapes(served, "query", str(example("quadruped-1")), "--json").stdout)
    assert body["matches"][0]["name"] == "quadruped-0"


def test_an_unreachable_service_is_a_sentence_not_a_traceback(tmp_path):
    down = Service.__new__(Service)
    down.url = "http://127.0.0.1:9"  # nothing listens on the discard port
    result = shapes(down, "query", str(example("quadruped-1")))
    assert result.returncode == 2
    assert "no service answers at http://127.0.0.1:9" in result.stderr
    assert "Traceback" not in result.stderr


def test_an_import_lists_the_files_described_in_part(served: Service, tmp_path):
    """(After the query test: the two-part quadruped joins the gallery.)"""
    _, both = with_a_far_half_copy(example("quadruped-2"))
    (tmp_path / "quadruped-2-and-a-copy.off").write_bytes(both)
    shutil.copy(example("hand-0"), tmp_path)
    result = shapes(served, "import", str(tmp_path), "--wait")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == "2 files: 2 enrolled, 0 already enrolled, 0 failed"
    assert lines[1].startswith("1 described in part: only their largest connected part")
    assert lines[3].split() == ["quadruped-2-and-a-copy.off", "80%"]
    assert len(lines) == 4  # hand-0 is one connected surface


def test_the_commands_find_the_service_where_its_settings_put_it():
    assert default_url({}) == "http://127.0.0.1:8000"
    assert default_url({"SHAPES_PORT": "8765"}) == "http://127.0.0.1:8765"
    assert default_url({"SHAPES_HOST": "0.0.0.0", "SHAPES_PORT": "9000"}) == "http://127.0.0.1:9000"
    assert default_url({"SHAPES_HOST": "::1"}) == "http://[::1]:8000"
    remote = {"SHAPES_URL": "https://shapes.example.org/", "SHAPES_PORT": "8765"}
    assert default_url(remote) == "https://shapes.example.org"


def test_collections_from_the_command_line(served: Service, folder):
    made = shapes(served, "collections", "create", "casts", "--units", "metric")
    assert made.returncode == 0, made.stderr
    assert made.stdout.startswith("created collection casts (units metric")
    again = shapes(served, "collections", "create", "casts")
    assert again.returncode == 1 and "collection_exists" in again.stderr
    imported = shapes(
        served, "import", str(folder / "quadruped-0.off.gz"), "--collection", "casts", "--wait"
    )
    assert imported.returncode == 0, imported.stderr
    assert imported.stdout.startswith("1 files: 1 enrolled")
    listed = shapes(served, "collections", "list")
    rows = {line.split()[0]: line.split() for line in listed.stdout.splitlines()[1:]}
    assert rows["casts"][1] == "metric" and rows["casts"][-2:] == ["1", "1"]
    found = shapes(served, "query", str(folder / "quadruped-0.off.gz"), "--collection", "casts")
    assert found.returncode == 0 and "quadruped-0" in found.stdout
    assert shapes(served, "collections", "delete", "casts").returncode == 0
    missing = shapes(served, "query", str(folder / "biped-0.off.gz"), "--collection", "casts")
    assert missing.returncode == 2 and "collection_not_found" in missing.stderr


def test_keys_need_the_admin_key_from_the_command_line(served: Service):
    refused = shapes(served, "keys", "list")
    assert refused.returncode == 1 and "no_admin_key" in refused.stderr
