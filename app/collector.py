"""The collector: the one writer that turns queue results into database rows and index entries.

Workers never touch the database. Every ``collector_interval_seconds`` the
collector (a thread started in the app's lifespan) reads the results and
heartbeats of unfinished jobs from the queue's key-value store and

* stores a descriptor (with its preset name and version), marks the job
  succeeded and the mesh ready, and adds the shape to the index at once;
* marks job and mesh failed with the engine's sentence for a refused mesh;
* marks job and mesh failed when the task raised on every Huey retry;
* marks a queued job "processing" once its heartbeat appears;
* re-enqueues a job whose heartbeat went stale (its worker died), at most
  ``max_requeues`` times, then fails it with a sentence saying so;
* every ``sweep_interval_seconds``, enqueues the unfinished jobs the queue does not
  know (accepted while it was down, or lost with its data);
* after changes, at most every ``calibration_refit_seconds``, starts learning the
  gallery's fusion weights again (in a thread of its own: :mod:`app.gallery.weights`).

Results are read without removing them and deleted only after the commit, so
a crash in between makes the collector store the same result again (at least
once, idempotent), never lose it.

Several API processes on one database each run a collector. They are safe
together: a round locks the unfinished jobs it reads (``FOR UPDATE SKIP LOCKED``
on PostgreSQL; SQLite has one writer anyway), so each result is stored by one of
them, and every stored descriptor and deletion is logged (:mod:`app.repositories.changes`)
for the others' indexes, which each collector applies after its round.
"""

from __future__ import annotations

import logging
import threading
import time
from datetime import UTC, datetime
from typing import Any

from huey.utils import Error
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session

from worker.engine.descriptor import ShapeDescriptor
from worker.jobs.queue import descriptor_npz, preview_bytes

from .db import unit_of_work
from .descriptors import enqueue_job, enqueue_soon, lost, new_job
from .gallery.service import Shape
from .models import Descriptor, Job, JobStatus, MeshStatus, utcnow
from .queue import QUEUE_ERRORS
from .repositories import changes, jobs, meshes
from .state import AppState

log = logging.getLogger("shapes.collector")

BATCH = 500


def _fail(job: Job, code: str, detail: str) -> None:
    job.status = JobStatus.failed.value
    job.error_code, job.error_detail = code, detail
    job.finished_at = utcnow()
    mesh = job.mesh
    mesh.status = MeshStatus.failed.value
    mesh.error_code, mesh.error_detail = code, detail


class JobCollector:
    def __init__(self, state: AppState) -> None:
        self.state = state
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_save = time.monotonic()

    # ---------------------------------------------------------------- startup
    def recover(self) -> int:
        """At startup: re-enqueue the unfinished jobs the queue no longer holds (see
        :meth:`sweep`), and queue jobs for meshes not yet described with the current
        preset version."""
        state = self.state
        try:
            to_enqueue = self._lost(grace_seconds=0.0)
        except QUEUE_ERRORS as exc:  # the queue is down: the sweep does this once it is back
            log.warning("queue unreachable at startup (%r); the sweep will recover", exc)
            to_enqueue = []
        with unit_of_work(state.sessions) as session:
            for gallery in state.galleries:
                preset = gallery.base_preset
                for mesh in meshes.meshes_missing_descriptor(
                    session, gallery.collection_id, preset.name, preset.version
                ):
                    job = jobs.add(session, new_job(preset, mesh))
                    mesh.status = MeshStatus.queued.value
                    mesh.error_code = mesh.error_detail = None
                    to_enqueue.append(job)
        for job in to_enqueue:
            enqueue_soon(state, job)
        if to_enqueue:
            log.info("re-enqueued %d unfinished jobs", len(to_enqueue))
        return len(to_enqueue)

    def sweep(self) -> int:
        """Enqueue the unfinished jobs the queue does not know (accepted while it was
        down, or lost with its data); runs every ``sweep_interval_seconds``."""
        lost = self._lost(grace_seconds=self.state.settings.sweep_interval_seconds)
        for job in lost:
            enqueue_job(self.state, job)
        if lost:
            log.info("enqueued %d jobs the queue did not hold", len(lost))
            self.state.metrics.jobs.labels("swept").inc(len(lost))
        return len(lost)

    def _lost(self, *, grace_seconds: float) -> list[Job]:
        with unit_of_work(self.state.read_sessions) as session:
            return lost(self.state, jobs.unfinished(session), grace_seconds=grace_seconds)

    # ------------------------------------------------------------------- loop
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="job-collector", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30)

    def _run(self) -> None:
        settings = self.state.settings
        last_sweep = time.monotonic()
        while not self._stop.is_set():
            try:
                self.run_once()
                galleries = self.state.galleries
                galleries.sync()  # collections other API processes created or deleted
                galleries.follow()
                galleries.maybe_refit_fusion(settings.calibration_refit_seconds)
                galleries.maybe_refit_references(settings.calibration_refit_seconds)
                self._maybe_save()
                if time.monotonic() - last_sweep > settings.sweep_interval_seconds:
                    last_sweep = time.monotonic()
                    self.sweep()
            except SQLAlchemyError as exc:  # e.g. a mesh deleted meanwhile: next round
                log.warning("collector round rolled back: %s", exc)
            except QUEUE_ERRORS as exc:  # the queue is down: next round, and the sweep
                log.warning("collector round: queue unreachable: %r", exc)
            except Exception:
                log.exception("collector round failed")
            self._stop.wait(settings.collector_interval_seconds)

    def _maybe_save(self) -> None:
        galleries = self.state.galleries
        interval = self.state.settings.index_save_interval_seconds
        if galleries.dirty and time.monotonic() - self._last_save > interval:
            galleries.save()
            self._last_save = time.monotonic()

    def run_once(self) -> int:
        """One pass over unfinished jobs; returns how many changed."""
        state = self.state
        ready: list[tuple[int, Shape]] = []
        finished: list[str] = []
        requeue: list[Job] = []
        changed = 0
        with state.galleries.changing():
            with unit_of_work(state.sessions) as session:
                # Locked (PostgreSQL): the collectors of other API processes skip
                # these jobs until this round commits, so no result is stored twice.
                unfinished = jobs.unfinished(session, limit=BATCH, lock=True)
                state.metrics.jobs_unfinished.set(len(unfinished))
                if not unfinished:
                    return 0
                ids = [j.task_id for j in unfinished]
                results = state.queue.results(ids)
                pending_beats = [j.task_id for j in unfinished if j.task_id not in results]
                beats = state.queue.heartbeats(pending_beats)
                for job in unfinished:
                    result = results.get(job.task_id)
                    if result is not None:
                        descriptor = self._finish(session, job, result)
                        if descriptor is not None:
                            shape = Shape(job.mesh_id, job.mesh.label, descriptor)
                            ready.append((job.mesh.collection_id, shape))
                        finished.append(job.task_id)
                        changed += 1
                    elif (beat := beats.get(job.task_id)) is not None:
                        changed += self._track(job, beat, requeue)
            # Committed: now the index and the queue may follow.
            for collection_id, shape in ready:
                gallery = state.galleries.of(collection_id)
                if gallery is not None:  # else its collection was deleted meanwhile
                    gallery.add(shape)
        for task_id in finished:
            state.queue.forget(task_id)
        for job in requeue:
            enqueue_job(state, job)
        return changed

    def _finish(
        self, session: Session, job: Job, result: dict[str, Any] | Error
    ) -> ShapeDescriptor | None:
        state, mesh = self.state, job.mesh
        job.finished_at = utcnow()
        state.metrics.job_seconds.observe((job.finished_at - job.created_at).total_seconds())
        if isinstance(result, Error):
            log.error("job %s crashed: %s", job.id, result.metadata.get("error"))
            _fail(
                job,
                "describe_crashed",
                "Computing the descriptor crashed on every try "
                f"({str(result.metadata.get('error', 'unknown error'))[:200]}); "
                "the file is kept, and an operator can look into it.",
            )
            state.metrics.jobs.labels("crashed").inc()
            return None
        if not result.get("ok"):
            _fail(job, result["code"], result["message"])
            state.metrics.jobs.labels("refused").inc()
            return None
        # Stored as the worker made it; decoded once, for the index and the row's columns.
        npz = descriptor_npz(result)
        descriptor = ShapeDescriptor.from_npz_bytes(npz)
        if (descriptor.preset, descriptor.preset_version) != (job.preset, job.preset_version):
            _fail(job, "preset_mismatch", "The worker runs another version of the method.")
            state.metrics.jobs.labels("crashed").inc()
            return None
        changes.record(session, mesh.id, mesh.collection_id, "add")
        meshes.upsert_descriptor(
            session,
            Descriptor(
                mesh_id=mesh.id,
                preset=descriptor.preset,
                preset_version=descriptor.preset_version,
                data=npz,
                input_vertices=descriptor.input_vertices,
                input_faces=descriptor.input_faces,
                vertices=descriptor.vertices,
                timings=descriptor.timings,
                kept_area_fraction=descriptor.kept_area_fraction,
                input_points=descriptor.input_points,
                input_grid=None if descriptor.input_grid is None else list(descriptor.input_grid),
                input_support=descriptor.input_support,
                input_hidden=descriptor.input_hidden,
                facing_share=descriptor.facing_share,
                smoothed=descriptor.surface_smoothed,
            ),
        )
        glb, png = preview_bytes(result, "preview"), preview_bytes(result, "thumbnail")
        if glb is not None and png is not None:
            meshes.put_preview(session, mesh.id, glb, png)
        job.status = JobStatus.succeeded.value
        job.error_code = job.error_detail = None
        mesh.status = MeshStatus.ready.value
        mesh.error_code = mesh.error_detail = None
        state.metrics.jobs.labels("succeeded").inc()
        state.metrics.describe_seconds.observe(descriptor.timings.get("total", 0.0))
        return descriptor

    def _track(self, job: Job, beat: dict[str, Any], requeue: list[Job]) -> int:
        """Follow a running job's heartbeat; re-enqueue or fail it if its worker died."""
        state = self.state
        changed = 0
        if job.status == JobStatus.queued.value:
            job.status = JobStatus.processing.value
            started = datetime.fromtimestamp(float(beat["started"]), UTC)
            job.started_at = started.replace(tzinfo=None)  # stored naive, in UTC like utcnow
            job.worker = f"{beat.get('pid')}@{beat.get('host')}"
            job.mesh.status = MeshStatus.processing.value
            changed = 1
        if not state.queue.is_stale(beat):
            return changed
        if job.enqueues > state.settings.max_requeues:
            _fail(
                job,
                "worker_lost",
                f"The worker computing this descriptor stopped responding {job.enqueues} "
                "times; the file is kept and can be uploaded again after a fix.",
            )
            state.queue.forget(job.task_id)
            state.metrics.jobs.labels("lost").inc()
            return 1
        log.warning("job %s: worker %s stopped responding; re-enqueueing", job.id, job.worker)
        job.enqueues += 1
        job.status = JobStatus.queued.value
        job.worker = None
        job.mesh.status = MeshStatus.queued.value
        state.metrics.jobs.labels("requeued").inc()
        requeue.append(job)
        return 1
