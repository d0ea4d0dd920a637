"""The container deployments, checked without a container engine (none runs on these
machines): both compose files are valid for ``docker-compose config`` (Debian's
package), every ``SHAPES_*`` variable they set is a setting the service reads, the
scale-out file shares nothing through a filesystem, the Dockerfile's install steps work
in a fresh venv, and a setting out of its range stops ``python -m app`` with its name."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from app.config import Settings

REPO = Path(__file__).resolve().parents[1]
EMBEDDED = REPO / "docker-compose.yml"
SCALE = REPO / "docker-compose.scale.yml"


def _config(path: Path) -> dict:
    """The file as docker-compose resolves it (anchors, merges, defaults)."""
    if shutil.which("docker-compose") is None:
        pytest.fail("docker-compose not found: scripts/test.sh installs Debian's docker-compose")
    done = subprocess.run(
        ["docker-compose", "-f", str(path), "config"], capture_output=True, text=True, cwd=REPO
    )
    assert done.returncode == 0, done.stderr
    return yaml.safe_load(done.stdout)


@pytest.mark.parametrize("path", [EMBEDDED, SCALE], ids=lambda p: p.name)
def test_compose_files_are_valid_and_set_only_real_settings(path: Path):
    services = _config(path)["services"]
    fields = {f"SHAPES_{name.upper()}" for name in Settings.model_fields}
    for name, service in services.items():
        for variable in service.get("environment", {}):
            if variable.startswith("SHAPES_"):
                assert variable in fields, f"{path.name}: {name} sets unknown {variable}"


@pytest.mark.slow  # a fresh venv and an install (from pip's cache after scripts/test.sh)
def test_the_dockerfile_installs_and_imports_in_a_fresh_venv(tmp_path):
    """Replays the image's steps without an engine: the files it COPYs, into a fresh
    venv, its pip install and its import check (a module the service imports but the
    package does not declare fails here, not in production)."""
    lines = (REPO / "Dockerfile").read_text().splitlines()
    root = tmp_path / "srv"
    root.mkdir()
    for line in lines:
        if line.startswith("COPY "):
            *sources, _ = line.split()[1:]
            for pattern in sources:
                for source in REPO.glob(pattern):
                    copy = shutil.copytree if source.is_dir() else shutil.copy2
                    copy(source, root / source.name)
    run = next(line for line in lines if line.startswith("RUN pip install"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    env = {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    done = subprocess.run(
        ["bash", "-c", run.removeprefix("RUN ")], cwd=root, env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]


def test_the_scale_deployment_shares_nothing_but_its_servers():
    services = _config(SCALE)["services"]
    ours = {n: s for n, s in services.items() if s.get("image") == "modalshape:latest"}
    assert {"api-a", "api-b", "worker", "query-worker", "migrate"} <= set(ours)
    for name, service in ours.items():
        env = service["environment"]
        assert env["SHAPES_DATABASE_URL"].startswith("postgresql+psycopg://"), name
        assert env["SHAPES_REDIS_URL"].startswith("redis://"), name
        assert env["SHAPES_UPLOADS"] == "database", name
    # Each replica's volume holds only its own saved index: no volume is shared.
    volumes = [
        v["source"] if isinstance(v, dict) else v.split(":")[0]  # long or short syntax
        for s in ours.values()
        for v in s.get("volumes", [])
    ]
    assert len(volumes) == len(set(volumes))
    for name in ("postgres", "redis", "api-a", "api-b", "proxy", "worker", "query-worker"):
        assert not services[name].get("healthcheck", {}).get("disable"), name
    upstream = re.findall(r"server (\S+):8000", (REPO / "deploy" / "nginx.conf").read_text())
    assert upstream == ["api-a", "api-b"]


def test_a_setting_out_of_its_range_is_refused_by_its_name(monkeypatch, caplog):
    from app.__main__ import main

    monkeypatch.setenv("SHAPES_VERIFY_THREADS", "0")
    assert main([]) == 2
    assert "SHAPES_VERIFY_THREADS: Input should be greater than or equal to 1" in caplog.text
