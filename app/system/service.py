"""Readiness: is the database reachable and the gallery loaded? And how far the
describing with the current preset version has come."""

from __future__ import annotations

from sqlalchemy import text

from ..repositories import meshes
from ..state import AppState


def readiness(state: AppState) -> tuple[bool, dict[str, str]]:
    """``(ready, checks)``: each dependency's check is ``"ok..."`` or why it is not (shown
    by ``/ready``); ready when every one is ok."""
    checks: dict[str, str] = {}
    try:
        with state.read_sessions() as session:
            session.execute(text("SELECT 1"))
        checks["database"] = "ok"
    except Exception as exc:  # any failure means not ready, with the reason shown
        checks["database"] = f"error: {exc.__class__.__name__}"
    try:
        checks["queue"] = f"ok ({state.queue.waiting_count()} enrollments waiting)"
    except Exception as exc:
        checks["queue"] = f"error: {exc.__class__.__name__}"
    galleries = state.galleries
    if galleries.loaded:
        count = sum(1 for _ in galleries)
        plural = "" if count == 1 else "s"
        checks["index"] = f"ok ({len(galleries)} shapes in {count} collection{plural})"
    else:
        checks["index"] = galleries.error or "loading"
    return all(check.startswith("ok") for check in checks.values()), checks


def description_progress(state: AppState) -> dict[str, object]:
    """How many enrolled meshes (of every collection) have a descriptor of their
    collection's preset version (all, except while the meshes of an earlier version are
    described again in the background: only those are searchable meanwhile)."""
    preset = state.preset
    described = describable = 0
    with state.read_sessions() as session:
        for gallery in state.galleries:
            base = gallery.base_preset
            done, total = meshes.description_progress(
                session, gallery.collection_id, base.name, base.version
            )
            described, describable = described + done, describable + total
    return {
        "preset": f"{preset.name} v{preset.version}",
        "described": described,
        "enrolled": describable,
    }
