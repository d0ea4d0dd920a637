"""What each room may import (docs/architecture.md), checked in a fresh interpreter."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import worker
from app.client import MESH_SUFFIXES
from worker.engine.formats import MESH_FORMATS

#: What the engine's source may import besides the standard library and itself (trimesh
#: and pye57 read files).
ENGINE_DEPENDENCIES = {"numpy", "scipy", "trimesh", "tensorly", "fast_simplification", "pye57"}
#: Libraries of the service, the queue and the evaluation harness: never loaded with the
#: engine. (threadpoolctl is not listed: scipy.io loads it, not the engine.)
NOT_IN_ENGINE = {
    "huey",
    "pydantic",
    "pydantic_settings",
    "fastapi",
    "starlette",
    "sqlalchemy",
    "lapy",
    "matplotlib",
    "tqdm",
    "faiss",
}
ENGINE_DIR = Path(worker.__file__).parent / "engine"
ENGINE_MODULES = sorted(
    f"worker.engine.{p.stem}" for p in ENGINE_DIR.glob("*.py") if p.stem != "__init__"
)


def modules_loaded_by(statement: str) -> set[str]:
    """Every module in ``sys.modules`` after running ``statement`` in a new interpreter."""
    code = f"import sys\n{statement}\nprint('\\n'.join(sorted(sys.modules)))"
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    return set(result.stdout.split())


def test_the_engines_source_imports_only_its_numeric_libraries():
    imported: dict[str, set[str]] = {}
    for path in sorted(ENGINE_DIR.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue  # relative imports stay inside the engine
            for name in names:
                imported.setdefault(name.split(".")[0], set()).add(path.name)
    allowed = ENGINE_DEPENDENCIES | set(sys.stdlib_module_names)
    assert {name: files for name, files in imported.items() if name not in allowed} == {}


def test_importing_the_engine_loads_no_service_queue_or_harness_library():
    loaded = modules_loaded_by("\n".join(f"import {m}" for m in ENGINE_MODULES))
    assert set(ENGINE_MODULES) <= loaded  # the statement did import the engine
    assert {m.split(".")[0] for m in loaded} & NOT_IN_ENGINE == set()
    rooms = {m for m in loaded if m.startswith(("app", "worker.jobs", "worker.evaluation"))}
    assert rooms == set()


@pytest.mark.parametrize("settings", ["app.config", "worker.jobs.settings"])
def test_settings_load_neither_the_queue_nor_the_engines_pipeline(settings):
    loaded = modules_loaded_by(f"import {settings}")
    assert "pydantic_settings" in loaded
    assert "huey" not in loaded and "worker.engine.pipeline" not in loaded
    assert "worker.jobs.queue" not in loaded and "faiss" not in loaded


RECOGNITION_MODULES = sorted(
    f"worker.recognition.{p.stem}"
    for p in (ENGINE_DIR.parent / "recognition").glob("*.py")
    if p.stem != "__init__"
)


def test_the_recognition_room_is_pure_numpy():
    loaded = modules_loaded_by("\n".join(f"import {m}" for m in RECOGNITION_MODULES))
    assert set(RECOGNITION_MODULES) <= loaded
    assert {m.split(".")[0] for m in loaded} & (NOT_IN_ENGINE | {"pymeshlab"}) == set()
    assert {m for m in loaded if m.startswith(("app", "worker.jobs", "worker.evaluation"))} == set()


def test_the_service_never_imports_the_evaluation_harness():
    app_dir = Path(worker.__file__).parents[1] / "app"
    importers = set()
    for path in app_dir.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                "worker.evaluation"
            ):
                importers.add(path.name)
    assert importers == set()


#: The floors of ``app/``, top to bottom (docs/architecture.md draws the same house): a
#: package, or a module at app/'s top level, imports only what stands on a floor below
#: its own, never a neighbour on its floor; the resources (router and service each)
#: share a floor, so none reaches into another.
APP_FLOORS = (
    ("app.__main__", "app.main", "app.cli"),
    (
        "app.collections",
        "app.jobs",
        "app.keys",
        "app.meshes",
        "app.search",
        "app.system",
        "app.verification",
    ),
    ("app.deps",),
    ("app.collector",),
    ("app.descriptors",),
    ("app.state",),
    ("app.galleries", "app.keyring"),
    ("app.gallery",),
    ("app.backup", "app.uploads"),
    (
        "app.client",
        "app.links",
        "app.queue",
        "app.recent",
        "app.repositories",
        "app.schemas",
        "app.storage",
    ),
    ("app.models",),
    ("app.config", "app.db", "app.errors", "app.metrics", "app.migrations"),
)
REPO = Path(worker.__file__).parents[1]


def _room(module: str) -> str:
    """The package or top-level module of app/ that ``module`` belongs to."""
    return ".".join(module.split(".")[:2])


def _app_imports() -> dict[str, set[str]]:
    """room -> the other rooms of app/ its source imports (relative imports resolved)."""
    arrows: dict[str, set[str]] = {}
    for path in sorted((REPO / "app").rglob("*.py")):
        parts = list(path.relative_to(REPO).with_suffix("").parts)
        package = parts[:-1]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        room = _room(".".join(parts))
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = package[: len(package) - node.level + 1] if node.level else []
                module = ".".join([*base, *([node.module] if node.module else [])])
                names = [module] + [f"{module}.{alias.name}" for alias in node.names]
            else:
                continue
            for name in names:
                if name.startswith("app.") and _room(name) != room:
                    arrows.setdefault(room, set()).add(_room(name))
    return arrows


def test_every_room_of_the_service_stands_on_one_floor():
    floors = [room for floor in APP_FLOORS for room in floor]
    rooms = {
        _room(".".join(p.relative_to(REPO).with_suffix("").parts))
        for p in (REPO / "app").rglob("*.py")
        if p.name != "__init__.py" or p.parent != REPO / "app"
    }
    assert len(floors) == len(set(floors))
    assert rooms == set(floors)


def test_the_service_imports_only_downwards():
    floor_of = {room: i for i, floor in enumerate(APP_FLOORS) for room in floor}
    known = set(floor_of)
    upward = {
        (room, target)
        for room, targets in _app_imports().items()
        for target in targets
        if target in known and floor_of[target] <= floor_of[room]
    }
    assert upward == set()
    # Submodules named by attribute (``from app import x``) resolve to rooms too.
    assert {t for targets in _app_imports().values() for t in targets} <= known


def test_the_engines_package_never_imports_the_service():
    importers = {
        path.relative_to(REPO).as_posix()
        for path in (REPO / "worker").rglob("*.py")
        if any(name.split(".")[0] == "app" for name in _top_level_imports(path))
    }
    assert importers == set()


def test_the_shapes_command_starts_without_the_engine_the_server_or_the_migrations():
    loaded = modules_loaded_by("import app.cli\napp.cli.build_parser()")
    heavy = {"scipy", "trimesh", "tensorly", "fastapi", "sqlalchemy", "alembic", "faiss"}
    assert {m.split(".")[0] for m in loaded} & heavy == set()
    assert {m for m in loaded if m.startswith(("app.", "worker."))} <= {
        "app.cli",
        "app.client",
        "worker.cli",
        "worker.engine",
        "worker.engine.errors",
        "worker.engine.formats",
        "worker.engine.presets",
        "worker.evaluation",
        "worker.evaluation.datasets",
        "worker.recognition",
        "worker.recognition.fusion",
        "worker.recognition.metrics",
        "worker.engine.compare",
    }


def test_the_service_and_a_queue_consumer_start_without_the_describing_engine():
    """Only a job describes, in a process from the fork server that preloaded the engine
    (worker/jobs/limits.py): the API and the consumers, started for every deployment
    and test service, do not import it themselves."""
    describing = {"scipy", "trimesh", "tensorly", "matplotlib", "fast_simplification"}
    for script in ("import app.main", "import worker.__main__"):
        loaded = {m.split(".")[0] for m in modules_loaded_by(script)}
        assert loaded & describing == set(), script


def test_the_cli_client_loads_nothing_of_the_server():
    loaded = modules_loaded_by("import app.client")
    assert {m.split(".")[0] for m in loaded} & {"fastapi", "sqlalchemy", "faiss", "huey"} == set()
    assert {m for m in loaded if m.startswith(("app.", "worker."))} == {"app.client"}
    # So it keeps its own copy of the file suffixes the engine reads.
    assert MESH_SUFFIXES == tuple(f".{f}" for f in MESH_FORMATS)


#: Packages of the repository that are not installed: the scripts' and the tests'.
SCRIPT_PACKAGES = {"benchmarks", "experiments", "tests"}


def _top_level_imports(path: Path) -> set[str]:
    """Every absolute module name ``path`` imports."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


def test_benchmarks_and_experiments_share_only_benchmarks_common_and_no_tests():
    """No script imports another (what two share is in benchmarks.common or the
    library), nor the tests, nor edits sys.path: all run as modules from the root."""
    repo = Path(worker.__file__).parents[1]
    scripts = sorted([*repo.glob("benchmarks/*.py"), *repo.glob("experiments/*.py")])
    assert scripts
    reaching = {}
    for path in scripts:
        names = {n for n in _top_level_imports(path) if n.split(".")[0] in SCRIPT_PACKAGES}
        if names - {"benchmarks.common"}:
            reaching[path.name] = sorted(names - {"benchmarks.common"})
    assert reaching == {}
    assert [path.name for path in scripts if "sys.path" in path.read_text()] == []
