"""Run one descriptor computation in a child process under a time and memory limit.

A hostile or huge mesh must cost a job, not the worker: the computation runs
in a process forked from a small fork server (``multiprocessing`` forkserver,
with the engine preloaded), whose address space is capped with
``RLIMIT_AS``; the parent waits at most ``time_limit`` seconds and kills it
otherwise. Besides the descriptor, the child makes what the web page shows
(:mod:`.previews`: the 3D preview, and for an enrolled mesh its thumbnail) from
the mesh it loaded; a preview that cannot be made costs nothing but the preview.
"""

from __future__ import annotations

import functools
import logging
import multiprocessing as mp
import pickle
import resource
import signal
from dataclasses import dataclass
from multiprocessing import forkserver
from multiprocessing.connection import Connection
from multiprocessing.context import ForkServerContext
from pathlib import Path

from worker.engine.errors import MeshError
from worker.engine.presets import get_preset

from .previews import IMPORTS as PREVIEW_IMPORTS

log = logging.getLogger("shapes.worker")


@dataclass(frozen=True)
class Outcome:
    """A job's outcome: the descriptor's npz bytes with the preview (GLB) and thumbnail
    (PNG), or the refusal's ``code`` and sentence."""

    descriptor: bytes | None = None
    preview: bytes | None = None
    thumbnail: bytes | None = None
    code: str | None = None
    message: str | None = None


@functools.cache
def _context() -> ForkServerContext:
    """The fork server, set up at the first job rather than at import: importing this
    module (the queue, the tests) must not configure process-wide multiprocessing.

    It preloads what every job imports, the engine and the previews' libraries, so a
    forked job starts with them."""
    context = mp.get_context("forkserver")
    context.set_forkserver_preload(
        ["worker.engine.pipeline", "worker.jobs.previews", *PREVIEW_IMPORTS]
    )
    return context


def start_fork_server() -> None:
    """Start the fork server now, with the engine and the previews' libraries imported
    in it (about 0.9 s), so that a consumer's first job does not wait for it."""
    _context()
    forkserver.ensure_running()


def _child(
    conn: Connection,
    path: str,
    filename: str,
    preset_name: str,
    max_faces: int,
    memory: int,
    with_thumbnail: bool,
) -> None:
    # The engine is imported here, in the job, where the fork server has preloaded it
    # (:func:`_context`): the consumer and the service import this module and never
    # describe (0.7 to 1 s of imports at each start).
    from worker.engine.pipeline import load_and_describe

    from .previews import preview_glb, preview_mesh, thumbnail_png

    if memory > 0:
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    try:
        mesh, descriptor = load_and_describe(
            Path(path), get_preset(preset_name), filename, max_faces=max_faces
        )
        preview = thumbnail = None
        try:
            small = preview_mesh(mesh)  # decimated and turned once, drawn twice
            preview = preview_glb(small)
            thumbnail = thumbnail_png(small) if with_thumbnail else None
        except Exception:  # the descriptor is what matters; the page shows a placeholder
            log.exception("no preview for %s", filename)
        conn.send(("ok", descriptor.to_npz_bytes(), preview, thumbnail))
    except MeshError as exc:
        conn.send((exc.code, exc.message))
    except MemoryError:
        conn.send(("out_of_memory", ""))
    except Exception as exc:  # unexpected: the parent raises it so the queue retries
        conn.send(("crashed", repr(exc)[:500]))
    finally:
        conn.close()


def describe_limited(
    path: Path,
    filename: str,
    preset_name: str,
    *,
    max_faces: int,
    time_limit: float,
    memory_limit_bytes: int,
    with_thumbnail: bool = True,
) -> Outcome:
    """Describe ``path`` in a child under the limits (and make its previews: the
    thumbnail only when ``with_thumbnail``; a query's is never shown).

    Raises ``RuntimeError`` when the child died for another reason (a crash
    worth a retry).
    """
    context = _context()
    receive, send = context.Pipe(duplex=False)
    child = context.Process(
        target=_child,
        args=(
            send,
            str(path),
            filename,
            preset_name,
            max_faces,
            memory_limit_bytes,
            with_thumbnail,
        ),
        daemon=True,
    )
    child.start()
    send.close()
    try:
        ready = receive.poll(time_limit if time_limit > 0 else None)
        message = receive.recv_bytes() if ready else None
    except EOFError:  # the child died without answering (e.g. killed by the kernel)
        message = b""
    finally:
        if child.is_alive():
            child.kill()
        child.join()
        receive.close()
    if message is None:
        return Outcome(
            code="describe_timeout",
            message=(
                f"Describing this mesh took longer than this service's limit of {time_limit:g} "
                "seconds; simplify it or upload a smaller mesh."
            ),
        )
    return outcome_of(message, child.exitcode, memory_limit_bytes)


def outcome_of(message: bytes, exitcode: int | None, memory_limit_bytes: int) -> Outcome:
    """What a finished child's answer (empty when it died without one) and exit code say.

    A MemoryError under the cap, or a signal other than SIGKILL (C code failing to
    allocate under the cap aborts or faults), is the mesh's need for memory: a failure
    of this mesh. SIGKILL comes from outside (the kernel's out-of-memory killer, an
    operator): like any other death, ``RuntimeError``, which the queue retries.
    """
    if message:
        code, *rest = pickle.loads(message)
        if code == "ok":
            npz, preview, thumbnail = rest
            return Outcome(descriptor=npz, preview=preview, thumbnail=thumbnail)
        if code == "crashed":
            raise RuntimeError(f"describing failed: {rest[0]}")
        if code != "out_of_memory":
            return Outcome(code=code, message=rest[0])
    killed = exitcode == -signal.SIGKILL
    if message or (memory_limit_bytes > 0 and (exitcode or 0) < 0 and not killed):
        mb = memory_limit_bytes / (1024 * 1024)
        return Outcome(
            code="describe_out_of_memory",
            message=(
                f"Describing this mesh needed more memory than this service's limit of {mb:g} MB; "
                "simplify it or upload a smaller mesh."
            ),
        )
    if killed:
        raise RuntimeError("the descriptor process was killed (SIGKILL, from outside it)")
    raise RuntimeError(f"the descriptor process exited with code {exitcode}")
