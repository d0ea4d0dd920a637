"""The descriptor job queue (Huey): embedded on SQLite by default, Redis across machines.

This module is the only place that knows about the task queue. Workers never
write to the service's database: a task receives where its upload is (a path,
or a row of the uploads table the worker reads when the service keeps uploads in
the database, or the bytes themselves; :mod:`.sources`) and returns a JSON-able
result, which the service's collector stores. Keeping the database
single-writer (the service) keeps SQLite safe under several workers.

Result of ``describe_upload``::

    {"ok": true, "descriptor": "<base64 of ShapeDescriptor.to_npz_bytes()>",
     "preview": "<base64 GLB>" | null, "thumbnail": "<base64 PNG>" | null}
    {"ok": false, "code": "<MeshError.code>", "message": "<sentence for the user>"}

A :class:`~worker.engine.errors.MeshError` is deterministic (the same file fails the
same way), so it is returned, not raised, and never retried. Any other
exception is raised so that Huey retries the task (``TASK_RETRIES`` times); the
final failure is stored by Huey as the task's error.

While a task runs, a heartbeat ``{"pid", "host", "started", "beat"}`` is kept
fresh in Huey's key-value store under :func:`heartbeat_key`, so the service can
show "processing" and tell a dead worker (stale heartbeat) from a slow one.
"""

from __future__ import annotations

import base64
import logging
import os
import socket
import threading
import time
from collections.abc import Mapping
from typing import Any

from huey import Huey, PriorityRedisHuey, SqliteHuey
from huey.api import Task
from huey.exceptions import RetryTask

from .limits import describe_limited, start_fork_server
from .settings import Queue, QueueSettings
from .sources import SourceGoneError, SourceUnavailableError, local_file, remove_stale_copies

log = logging.getLogger(__name__)

TASK_NAME = "describe_upload"
TASK_RETRIES = 2
TASK_RETRY_DELAY_SECONDS = 1
#: A task whose file is in an unreachable database waits this long and tries again,
#: as often as it takes (these tries do not count against ``TASK_RETRIES``).
SOURCE_RETRY_SECONDS = 3
#: The outcome of a task whose file is gone (its mesh deleted while queued).
FILE_GONE = "file_missing"
FILE_GONE_MESSAGE = (
    "The uploaded file was gone when a worker came to describe it: the mesh was deleted "
    "first (or the worker does not see the service's uploads)."
)
QUEUE_FILE = "queue.sqlite3"
#: How soon an idle consumer looks for a task again, per queue: (first, last) seconds of
#: Huey's backoff between looks. A query's user waits for its describe, so its queue is
#: looked at every 20 ms (on SQLite one indexed read a look; Redis's consumers block on
#: the queue instead); an enrollment can wait half a second.
POLL_SECONDS: dict[Queue, tuple[float, float]] = {"query": (0.005, 0.02), "enroll": (0.1, 0.5)}


def heartbeat_key(task_id: str) -> str:
    """Key of a running task's heartbeat in the queue's key-value store."""
    return f"heartbeat:{task_id}"


def to_base64(data: bytes) -> str:
    """Bytes as the ASCII text a task's arguments and results carry."""
    return base64.b64encode(data).decode("ascii")


def descriptor_npz(result: Mapping[str, Any]) -> bytes:
    """The descriptor of a successful ``describe_upload`` result, as the npz bytes the
    worker made (``ShapeDescriptor.to_npz_bytes``), so they can be stored unchanged."""
    return base64.b64decode(result["descriptor"])


def preview_bytes(result: Mapping[str, Any], part: str) -> bytes | None:
    """The ``preview`` (GLB) or ``thumbnail`` (PNG) of a successful result, or None
    when the worker could not make it."""
    text = result.get(part)
    return None if text is None else base64.b64decode(text)


def make_huey(settings: QueueSettings, queue: Queue = "enroll") -> Huey:
    """The Huey instance of one of the two queues, with ``describe_upload`` registered.

    SQLite (``<data_dir>/queue.sqlite3``, WAL; both queues in the one file) unless
    ``redis_url`` is set. Intermediate errors are not stored, so a task's result is
    either its value or, after the last retry, its final error.
    """
    name = settings.queue_name_of(queue)
    if settings.redis_url:
        huey: Huey = PriorityRedisHuey(
            name, url=settings.redis_url, store_intermediate_errors=False
        )
    else:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        huey = SqliteHuey(
            name,
            filename=str(settings.data_dir / QUEUE_FILE),
            store_intermediate_errors=False,
            timeout=30,
        )
    heartbeat_seconds = settings.heartbeat_seconds
    data_dir = settings.data_dir
    database_url = settings.database_url
    time_limit = settings.job_time_limit_seconds
    memory_limit = settings.job_memory_limit_mb * 1024 * 1024

    # untyped-decorator: huey ships no types, so its task decorator is Any to mypy.
    @huey.task(  # type: ignore[untyped-decorator]
        retries=TASK_RETRIES, retry_delay=TASK_RETRY_DELAY_SECONDS, context=True, name=TASK_NAME
    )
    def describe_upload(
        source: str,
        filename: str,
        preset_name: str,
        max_faces: int,
        data: str | None = None,
        task: Task | None = None,
    ) -> dict[str, Any]:
        """Describe one uploaded mesh file; see the module docstring for the result.

        ``source``: a path relative to this worker's data directory (or absolute), or
        ``db:<sha256>``; ``data``: the file itself (base64) instead, for a query.
        """
        assert task is not None  # context=True: Huey passes the running task
        key = heartbeat_key(task.id)
        started = time.time()
        done = threading.Event()

        def beat() -> None:
            while True:
                huey.put(
                    key,
                    {
                        "pid": os.getpid(),
                        "host": socket.gethostname(),
                        "started": started,
                        "beat": time.time(),
                    },
                )
                if done.wait(heartbeat_seconds):
                    return

        beater = threading.Thread(target=beat, name=f"heartbeat-{task.id}", daemon=True)
        beater.start()
        try:
            try:
                inline = None if data is None else base64.b64decode(data)
                with local_file(
                    source, inline, data_dir=data_dir, database_url=database_url
                ) as path:
                    outcome = describe_limited(
                        path,
                        filename,
                        preset_name,
                        max_faces=max_faces,
                        time_limit=time_limit,
                        memory_limit_bytes=memory_limit,
                        with_thumbnail=queue == "enroll",
                    )
            finally:
                done.set()
                beater.join()
        except SourceUnavailableError as exc:
            # Waiting, not running: no heartbeat left to go stale and be taken for a
            # dead worker; the task stays scheduled, where the service sees it.
            huey.delete(key)
            log.warning("task %s: %s; trying again in %d s", task.id, exc, SOURCE_RETRY_SECONDS)
            raise RetryTask(delay=SOURCE_RETRY_SECONDS) from exc
        except SourceGoneError as exc:  # nothing to describe: an outcome, not a crash
            log.info("task %s: %s; its mesh was deleted before it was described", task.id, exc)
            return {"ok": False, "code": FILE_GONE, "message": FILE_GONE_MESSAGE}
        if outcome.descriptor is None:  # refused or over a limit: deterministic, no retry
            return {"ok": False, "code": outcome.code, "message": outcome.message}
        return {
            "ok": True,
            "descriptor": to_base64(outcome.descriptor),
            "preview": None if outcome.preview is None else to_base64(outcome.preview),
            "thumbnail": None if outcome.thumbnail is None else to_base64(outcome.thumbnail),
        }

    huey.describe_upload = describe_upload  # the service enqueues it by this attribute
    return huey


def run_consumer(
    settings: QueueSettings | None = None, workers: int = 1, queue: Queue = "enroll"
) -> None:
    """Run a Huey consumer (blocking) on one of the queues described by ``settings``.

    An enrollment consumer first lowers its CPU priority by ``enroll_nice`` (its
    descriptor processes inherit it), so query consumers on the same machine get the
    cores first. SIGINT stops it gracefully (the running task finishes), SIGTERM at
    once; a task interrupted either way is re-enqueued by the service's collector
    once its heartbeat goes stale.
    """
    settings = settings or QueueSettings()
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(process)d %(name)s %(levelname)s %(message)s"
    )
    if queue == "enroll" and settings.enroll_nice:
        os.nice(settings.enroll_nice)
    start_fork_server()  # after the nice: the describing processes inherit it
    if settings.job_time_limit_seconds > 0:  # else no age says a copy's task is over
        stale = remove_stale_copies(settings.data_dir, settings.job_time_limit_seconds + 60)
        if stale:
            log.info("removed %d copies left by killed workers", stale)
    huey = make_huey(settings, queue)
    first, last = POLL_SECONDS[queue]
    consumer = huey.create_consumer(
        workers=workers, worker_type="thread", initial_delay=first, backoff=1.15, max_delay=last
    )
    consumer.run()
