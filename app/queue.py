"""The service's side of the descriptor queue (``worker.jobs.queue``): enqueue, wait, collect."""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path
from typing import Any

from huey import Huey
from huey.exceptions import ResultTimeout, TaskException
from huey.utils import Error

from worker.engine.descriptor import ShapeDescriptor
from worker.engine.errors import MeshError
from worker.jobs.queue import (
    descriptor_npz,
    heartbeat_key,
    make_huey,
    preview_bytes,
    to_base64,
)

from .config import Settings
from .errors import UnavailableError


def _queue_errors() -> tuple[type[Exception], ...]:
    errors: list[type[Exception]] = [sqlite3.OperationalError]  # the embedded queue, locked
    try:
        from redis.exceptions import ConnectionError, TimeoutError
    except ImportError:  # the redis extra is not installed: no Redis queue to lose
        return tuple(errors)
    return (*errors, ConnectionError, TimeoutError)


#: What an unreachable queue raises: a request answers 503 with ``Retry-After``
#: (:func:`app.errors.install_error_handlers`); the collector tries again next round.
QUEUE_ERRORS = _queue_errors()
#: How often a query looks for its describe's result (Huey polls the result store; an
#: indexed read a look): the answer's user waits on it.
RESULT_POLL_SECONDS = 0.01


class QueryMeshError(MeshError):
    """A mesh error reported by a worker for a query upload (keeps the worker's code)."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code


class DescriptorQueue:
    """Enrollments go to one Huey queue (collected by :mod:`app.collector`),
    queries to another with consumers of their own (:func:`describe_now` waits)."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.huey = make_huey(settings, "enroll")
        self.query_huey = make_huey(settings, "query")

    def task_path(self, path: Path) -> str:
        """The path handed to workers: relative to the data directory when inside it,
        so workers that mount the data elsewhere (containers) still find it."""
        try:
            return str(path.resolve().relative_to(self.settings.data_dir.resolve()))
        except ValueError:
            return str(path.resolve())

    def _enqueue(
        self,
        huey: Huey,
        task_id: str,
        source: str | Path,
        filename: str,
        preset: str,
        data: str | None = None,
    ) -> None:
        huey.delete(heartbeat_key(task_id))
        if isinstance(source, Path):
            source = self.task_path(source)
        huey.enqueue(
            huey.describe_upload.s(
                source, filename, preset, self.settings.max_faces, data, id=task_id
            )
        )

    def enqueue_describe(
        self, task_id: str, source: str | Path, filename: str, preset: str
    ) -> None:
        """Queue the description of an enrolled mesh, whose file is at ``source`` (a
        path, or a database reference: :mod:`worker.jobs.sources`); the collector
        stores the result."""
        self._enqueue(self.huey, task_id, source, filename, preset)

    def describe_now(
        self, task_id: str, path: Path, filename: str, preset: str
    ) -> tuple[ShapeDescriptor, bytes | None]:
        """Describe a file on the query queue and wait (blocking) for it: its
        descriptor and its preview (GLB; None when the worker could not make one).

        Raises
        ------
        MeshError
            The worker refused the mesh (its code and sentence).
        UnavailableError
            No query worker answered in time, or the task crashed on every try.
        """
        huey = self.query_huey
        # Under database storage a worker may be on another host: the query's bytes
        # travel with the task (queries are never stored).
        data = to_base64(path.read_bytes()) if self.settings.uploads == "database" else None
        self._enqueue(huey, task_id, path, filename, preset, data)
        try:
            result = huey.result(
                task_id,
                blocking=True,
                timeout=self.settings.query_timeout_seconds,
                max_delay=RESULT_POLL_SECONDS,
                revoke_on_timeout=True,
            )
        except ResultTimeout:
            raise UnavailableError(
                "No descriptor worker answered in time; try again later.", code="workers_busy"
            ) from None
        except TaskException:
            raise UnavailableError(
                "Describing the query mesh failed unexpectedly on every try.",
                code="describe_crashed",
            ) from None
        finally:
            huey.delete(heartbeat_key(task_id))
        if not result["ok"]:
            raise QueryMeshError(result["code"], result["message"])
        descriptor = ShapeDescriptor.from_npz_bytes(descriptor_npz(result))
        return descriptor, preview_bytes(result, "preview")

    # -- for the collector ----------------------------------------------------
    def peek(self, keys: list[str]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for start in range(0, len(keys), 500):
            chunk = keys[start : start + 500]
            raw = self.huey.storage.peek_many(chunk)
            for key, value in raw.items():
                if value is not None:
                    out[key] = self.huey.serializer.deserialize(value)
        return out

    def results(self, task_ids: list[str]) -> dict[str, dict[str, Any] | Error]:
        return self.peek(task_ids)

    def heartbeats(self, task_ids: list[str]) -> dict[str, dict[str, Any]]:
        beats = self.peek([heartbeat_key(t) for t in task_ids])
        return {t: beats[heartbeat_key(t)] for t in task_ids if heartbeat_key(t) in beats}

    def forget(self, task_id: str) -> None:
        self.huey.delete(task_id)
        self.huey.delete(heartbeat_key(task_id))

    def cancel(self, task_id: str) -> None:
        self.huey.revoke_by_id(task_id, revoke_once=True)
        self.forget(task_id)

    def waiting_count(self) -> int:
        """Enrollments waiting for a worker (asks the queue: raises while it is down)."""
        count: int = self.huey.pending_count()
        return count

    def waiting_task_ids(self) -> set[str]:
        """Ids of tasks still in the queue or scheduled for a retry."""
        return {t.id for t in self.huey.pending()} | {t.id for t in self.huey.scheduled()}

    def is_stale(self, beat: dict[str, Any]) -> bool:
        return time.time() - float(beat.get("beat", 0)) > self.settings.stalled_after_seconds
