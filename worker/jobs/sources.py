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
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import create_engine, text
from sqlalchemy.engine import Engine

DATABASE_PREFIX = "db:"


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
    FileNotFoundError
        The upload is not in the database (deleted since the task was queued).
    RuntimeError
        A database source, and no database URL to read it with.
    """
    if data is None and not source.startswith(DATABASE_PREFIX):
        path = Path(source)
        yield path if path.is_absolute() else data_dir / path
        return
    if data is None:
        if database_url is None:
            raise RuntimeError(f"{source} is in the database: set SHAPES_DATABASE_URL")
        sha256 = source.removeprefix(DATABASE_PREFIX)
        with _engine(database_url).connect() as connection:
            data = connection.execute(
                text("SELECT data FROM uploads WHERE sha256 = :sha256"), {"sha256": sha256}
            ).scalar_one_or_none()
        if data is None:
            raise FileNotFoundError(f"no upload {sha256} in the database")
    scratch = data_dir / "tmp"
    scratch.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=scratch, prefix="task-") as copy:
        copy.write(bytes(data))
        copy.flush()
        yield Path(copy.name)
