"""``shapes backup DEST`` and ``shapes restore SRC``: a live embedded gallery, copied whole.

A backup is a directory:

* ``shapes.sqlite3``: the database, copied online with SQLite's backup API (a
  consistent snapshot while the service keeps writing);
* ``uploads/``: the uploaded files of the snapshot's meshes (none when uploads are
  kept in the database: they are in it);
* ``index/``: the default collection's saved search index of the preset's version (a
  head start: the service reconciles it with the database on start, or rebuilds it
  from the stored descriptors, as it does the other collections' indexes), and
  ``index.parts``, the rows of its parts file it refers to (the file only grows: rows
  a saved index refers to are never written again, so a copy of them while the service
  runs is whole);
* ``manifest.json``: what it holds, with every file's size and sha256.

A mesh deleted while the backup runs loses its file before the copy reaches it: it is
left out of the backup, as if deleted just before (``left_out`` in the manifest).
The backup is written to ``DEST.partial`` and renamed, so a ``DEST`` is always whole.

``restore`` checks every checksum, then copies the backup into an empty data
directory; a service started on it answers as the one backed up did. PostgreSQL
deployments are backed up with ``pg_dump`` instead (docs/deployment.md).
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import sqlite3
import time
from contextlib import closing
from pathlib import Path
from typing import Any

from .config import Settings
from .migrations import upgrade_head

FORMAT = 1
MANIFEST = "manifest.json"
DATABASE = "shapes.sqlite3"
#: Attempts at copying the index while the service may save it (every 30 s by default).
INDEX_ATTEMPTS = 5


class BackupError(Exception):
    """Why a backup or restore cannot be made, as a sentence for the operator."""


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _database_path(settings: Settings) -> Path:
    url = settings.sqlalchemy_url
    if not url.startswith("sqlite:///"):
        raise BackupError(
            "shapes backup copies the embedded SQLite deployment; this service's database "
            "is a server: back it up with pg_dump (docs/deployment.md)."
        )
    return Path(url.removeprefix("sqlite:///"))


def backup(settings: Settings, dest: Path) -> dict[str, Any]:
    """Copy the gallery of ``settings`` (running or not) to ``dest``; the manifest."""
    source = _database_path(settings)
    if not source.is_file():
        raise BackupError(f"There is no database at {source}: nothing to back up.")
    if dest.exists():
        raise BackupError(f"{dest} exists; back up to a new directory.")
    partial = dest.with_name(dest.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True)
    copy = partial / DATABASE
    with closing(sqlite3.connect(source, timeout=30)) as live:
        with closing(sqlite3.connect(copy)) as snapshot:
            live.backup(snapshot)
    left_out = (
        _copy_uploads(copy, settings.uploads_dir, partial / "uploads")
        if settings.uploads == "directory"
        else []
    )
    _copy_index(settings.preset_index_directory, partial / "index")
    with closing(sqlite3.connect(copy)) as db:
        meshes = db.execute("SELECT count(*) FROM meshes").fetchone()[0]
        descriptors = db.execute("SELECT count(*) FROM descriptors").fetchone()[0]
        revision = db.execute("SELECT version_num FROM alembic_version").fetchone()[0]
    manifest = {
        "format": FORMAT,
        "created_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "preset": settings.preset,
        "schema_revision": revision,
        "uploads": settings.uploads,
        "meshes": meshes,
        "descriptors": descriptors,
        "left_out": left_out,
        "files": {
            str(path.relative_to(partial)): {"bytes": path.stat().st_size, "sha256": _sha256(path)}
            for path in sorted(partial.rglob("*"))
            if path.is_file()
        },
    }
    (partial / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
    partial.rename(dest)
    return manifest


def _copy_uploads(database: Path, uploads: Path, target: Path) -> list[int]:
    """Copy the files of the snapshot's meshes; drop the meshes whose file is gone
    (deleted since the snapshot) from it. The ids left out."""
    with closing(sqlite3.connect(database)) as db:
        db.execute("PRAGMA foreign_keys = ON")  # their descriptors, jobs and previews too
        left_out = []
        for mesh_id, reference in db.execute("SELECT id, storage_path FROM meshes").fetchall():
            file = uploads / reference
            try:
                (target / reference).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(file, target / reference)
            except FileNotFoundError:
                left_out.append(mesh_id)
        if left_out:
            marks = ",".join("?" * len(left_out))
            with db:
                db.execute(f"DELETE FROM meshes WHERE id IN ({marks})", left_out)
    return left_out


def _copy_index(index: Path, target: Path) -> None:
    """Copy the saved index, again if the service saved a new one meanwhile (its
    manifest changed); none copied if it never holds still (the service rebuilds it)."""
    for _ in range(INDEX_ATTEMPTS):
        shutil.rmtree(target, ignore_errors=True)
        manifest = index / "manifest.json"
        if not manifest.is_file():
            return
        before = manifest.read_bytes()
        try:
            shutil.copytree(index, target)
            _copy_parts_rows(index, json.loads(before), target.with_name(target.name + ".parts"))
        except (FileNotFoundError, shutil.Error):  # replaced while copied
            continue
        if manifest.is_file() and manifest.read_bytes() == before:
            return
    shutil.rmtree(target, ignore_errors=True)
    target.with_name(target.name + ".parts").unlink(missing_ok=True)


def _copy_parts_rows(index: Path, manifest: dict[str, Any], target: Path) -> None:
    """The first rows of the index's parts file, as many as its manifest refers to."""
    if not manifest.get("parts_file"):
        return
    remaining = int(manifest["parts_count"]) * 2 * math.prod(manifest["parts_shape"])
    with open(index.parent / manifest["parts_file"], "rb") as source, open(target, "wb") as out:
        while remaining > 0:
            block = source.read(min(remaining, 1 << 20))
            if not block:
                raise FileNotFoundError("the parts file is shorter than its index")
            out.write(block)
            remaining -= len(block)


def restore(source: Path, settings: Settings) -> dict[str, Any]:
    """Check the backup at ``source`` and copy it into the (empty) data directory of
    ``settings``; the backup's manifest."""
    try:
        manifest: dict[str, Any] = json.loads((source / MANIFEST).read_text())
    except (OSError, ValueError):
        raise BackupError(f"{source} is not a backup: it has no readable {MANIFEST}.") from None
    if manifest.get("format") != FORMAT:
        raise BackupError(f"{source} is a backup of another format ({manifest.get('format')}).")
    for name, facts in manifest["files"].items():
        path = source / name
        if not path.is_file() or _sha256(path) != facts["sha256"]:
            raise BackupError(f"{path} is missing or damaged (its checksum differs): not restored.")
    target = _database_path(settings)
    if target.exists():
        raise BackupError(
            f"{target} exists: restore into an empty data directory (SHAPES_DATA_DIR)."
        )
    if manifest["uploads"] != settings.uploads:
        raise BackupError(
            f"The backup keeps uploads in the {manifest['uploads']}, this service in the "
            f"{settings.uploads}: set SHAPES_UPLOADS={manifest['uploads']}."
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    if (source / "uploads").is_dir():
        shutil.copytree(source / "uploads", settings.uploads_dir, dirs_exist_ok=True)
    if (source / "index").is_dir():
        index = settings.preset_index_directory
        shutil.copytree(source / "index", index)
        if (source / "index.parts").is_file():
            shutil.copyfile(source / "index.parts", index.with_name(index.name + ".parts"))
    shutil.copyfile(source / DATABASE, target)  # last: a half restore has no database
    upgrade_head(settings.sqlalchemy_url)  # a backup of an earlier version: its migrations
    return manifest
