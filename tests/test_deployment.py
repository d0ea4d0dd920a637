"""The container deployments, checked without a container engine (none runs on these
machines): both compose files are valid for ``docker-compose config`` (Debian's
package), every ``SHAPES_*`` variable they set is a setting the service reads, and
the scale-out file shares nothing through a filesystem."""

from __future__ import annotations

import re
import shutil
import subprocess
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
