"""Where uploaded files are kept: a directory (the embedded default) or the database.

* :class:`DirectoryStore`: content-addressed files ``uploads/<sha[:2]>/<sha>``
  under the data directory. A stored file is never rewritten: the same bytes
  always land on the same path, so storing twice is a no-op and a crash can leave
  at most an unreferenced file. Workers read the file where it lies, so they must
  share the volume.
* :class:`DatabaseStore` (``SHAPES_UPLOADS=database``): the bytes in the
  ``uploads`` table, written in the transaction that creates the mesh and deleted
  in the one that deletes it. Workers on other hosts read them with the database
  URL (:mod:`worker.jobs.sources`); API replicas serve them from any host. The
  limit is the column's: 1 GB on PostgreSQL (``bytea``) and SQLite, far above
  ``SHAPES_MAX_UPLOAD_BYTES`` (64 MB); every file is read into memory once to
  store it and once per worker task.

A mesh keeps its file's *reference* (``meshes.storage_path``): a path relative to
the uploads directory, or ``db:<sha256>``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from sqlalchemy import select
from sqlalchemy.orm import Session

from worker.jobs.sources import DATABASE_PREFIX, database_source

from .db import after_commit
from .models import Upload


@dataclass(frozen=True)
class ReceivedFile:
    """An upload received into a temporary file: where it waits, its original name,
    its size in bytes and its sha256 (hex). What the services take, free of HTTP types."""

    path: Path
    filename: str
    size: int
    sha256: str


class UploadStore(Protocol):
    def put(self, session: Session, received: ReceivedFile) -> str:
        """Keep a received file (its temporary file is consumed); its reference."""
        ...

    def task_source(self, reference: str) -> str | Path:
        """What a descriptor task is given to find the file."""
        ...

    def read(self, session: Session, reference: str) -> Path | bytes | None:
        """The file (a local path, or its bytes); None when it is missing."""
        ...

    def remove(self, session: Session, reference: str) -> None:
        """Delete the file with the session's transaction (or once it has committed)."""
        ...


class DirectoryStore:
    def __init__(self, root: Path) -> None:
        self.root = root

    def put(self, session: Session, received: ReceivedFile) -> str:
        relative = f"{received.sha256[:2]}/{received.sha256}"
        target = self.root / relative
        if target.exists():
            received.path.unlink(missing_ok=True)
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            os.chmod(received.path, 0o444)
            os.replace(received.path, target)
        return relative

    def task_source(self, reference: str) -> Path:
        return self.root / reference

    def read(self, session: Session, reference: str) -> Path | None:
        path = self.root / reference
        return path if path.is_file() else None

    def remove(self, session: Session, reference: str) -> None:
        after_commit(session, lambda: (self.root / reference).unlink(missing_ok=True))


class DatabaseStore:
    def put(self, session: Session, received: ReceivedFile) -> str:
        if session.get(Upload, received.sha256) is None:
            session.add(Upload(sha256=received.sha256, data=received.path.read_bytes()))
        received.path.unlink(missing_ok=True)
        return database_source(received.sha256)

    def task_source(self, reference: str) -> str:
        return reference

    def read(self, session: Session, reference: str) -> bytes | None:
        sha256 = reference.removeprefix(DATABASE_PREFIX)
        data: bytes | None = session.scalar(select(Upload.data).where(Upload.sha256 == sha256))
        return data

    def remove(self, session: Session, reference: str) -> None:
        upload = session.get(Upload, reference.removeprefix(DATABASE_PREFIX))
        if upload is not None:
            session.delete(upload)
