"""Where a descriptor task's file comes from.

* a path: the service keeps uploads in a directory (the embedded default), which
  a worker on the same machine, or one that mounts the same volume, reads;
  relative paths are under the worker's own data directory;
* ``db:<sha256>``: the service keeps uploads in its database
  (``SHAPES_UPLOADS=database``), so a worker on another host needs nothing but the
  database's and the queue's URLs: it reads that one row of the ``uploads`` table;
* bytes carried by the task itself: a query's upload under database storage (a
  client waits for it, and it is never stored).

Whatever the source, the engine reads a local file: a copy in the worker's
temporary directory, removed when the task ends.
"""

from __future__ import annotations

import functools
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import create_engine, text
from sqlalchemy.engine import Engine
from sqlalchemy.exc import InterfaceError, OperationalError

DATABASE_PREFIX = "db:"
COPY_PREFIX = "task-"


class SourceUnavailableError(Exception):
    """The database holding the task's file is unreachable: try again later (the file
    is not at fault)."""


class SourceGoneError(Exception):
    """The task's file is not where the service put it: its mesh was deleted since the
    task was queued (or this worker does not see the service's uploads)."""


def database_source(sha256: str) -> str:
    """The task source of an upload kept in the database."""
    return f"{DATABASE_PREFIX}{sha256}"


@functools.cache
def _engine(url: str) -> Engine:
    return create_engine(url, pool_pre_ping=True)


@contextmanager
def local_file(
    source: str, data: bytes | None, *, data_dir: Path, database_url: str | None
) -> Iterator[Path]:
    """A local path holding the task's file (see the module docstring).

    Raises
    ------
    SourceGoneError
        The upload is not in its directory or the database (deleted since the task was
        queued).
    RuntimeError
        A database source, and no database URL to read it with.
    SourceUnavailableError
        A database source, and the database is unreachable.
    """
    if data is None and not source.startswith(DATABASE_PREFIX):
        path = Path(source)
        path = path if path.is_absolute() else data_dir / path
        if not path.is_file():
            raise SourceGoneError(f"no upload at {path}")
        yield path
        return
    if data is None:
        if database_url is None:
            raise RuntimeError(f"{source} is in the database: set SHAPES_DATABASE_URL")
        sha256 = source.removeprefix(DATABASE_PREFIX)
        try:
            with _engine(database_url).connect() as connection:
                data = connection.execute(
                    text("SELECT data FROM uploads WHERE sha256 = :sha256"), {"sha256": sha256}
                ).scalar_one_or_none()
        except (OperationalError, InterfaceError) as exc:
            raise SourceUnavailableError(f"the database is unreachable: {exc}") from exc
        if data is None:
            raise SourceGoneError(f"no upload {sha256} in the database")
    scratch = data_dir / "tmp"
    scratch.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=scratch, prefix=COPY_PREFIX) as copy:
        copy.write(bytes(data))
        copy.flush()
        yield Path(copy.name)


def remove_stale_copies(data_dir: Path, older_than_seconds: float) -> int:
    """Remove the copies left by workers killed mid-task (older than any task may run:
    no running task's copy is touched); how many were removed."""
    deadline = time.time() - older_than_seconds
    removed = 0
    for copy in (data_dir / "tmp").glob(f"{COPY_PREFIX}*"):
        try:
            if copy.stat().st_mtime < deadline:
                copy.unlink()
                removed += 1
        except FileNotFoundError:  # removed by another worker meanwhile
            continue
    return removed
