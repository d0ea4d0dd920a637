"""The FastAPI application: ``create_app(settings)``; ``app`` for ``uvicorn app.main:app``."""

from __future__ import annotations

import logging
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

from worker.engine.presets import get_preset

from .collections.router import include_scoped, openapi_with_scoped
from .collections.router import router as collections_router
from .collector import JobCollector
from .config import Settings, get_settings
from .db import DATABASE_ERRORS, make_engine, make_session_factory
from .deps import document_open_access
from .errors import install_error_handlers
from .galleries import Galleries
from .gallery.weights import pinned_fusion
from .jobs.router import router as jobs_router
from .keyring import KeyRing
from .keys.router import router as keys_router
from .meshes.router import router as meshes_router
from .metrics import Metrics, RequestMetricsMiddleware
from .migrations import upgrade_head
from .queue import QUEUE_ERRORS, DescriptorQueue
from .recent import Recent
from .search.router import document_limits
from .search.router import router as search_router
from .state import AppState
from .storage import DatabaseStore, DirectoryStore
from .system.router import router as system_router
from .verification.router import router as verification_router

log = logging.getLogger("shapes")

STATIC = Path(__file__).parent / "static"

DESCRIPTION = """
Pose-invariant 3D shape retrieval with the modal representation of Smeets et al.
(2010): geodesic distance matrix (GDM) singular values and the diffusion distance
tensor (DDT) core, compared with D1/D2 and fused with the sum or product rule.

Enroll meshes with `POST /meshes`, wait until they are `ready`, then search with
`POST /query` (a mesh file) or `POST /meshes/{id}/similar`. Errors are
`{"error": code, "detail": sentence}`.
"""


def _start_background(state: AppState, collector: JobCollector) -> None:
    """Load every collection's index (can take a while for a big gallery), recover jobs,
    start collecting."""
    try:
        state.galleries.sync()
        collector.recover()
        collector.start()
    except Exception as exc:  # shown by /ready; the process stays up for diagnosis
        log.exception("startup failed")
        state.galleries.error = f"error: {exc}"


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or get_settings()
    metrics = Metrics()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        preset = get_preset(settings.preset)
        for directory in (settings.data_dir, settings.uploads_dir, settings.tmp_dir):
            directory.mkdir(parents=True, exist_ok=True)
        # Uploads interrupted by a previous stop; this process is the only writer here.
        for leftover in settings.tmp_dir.glob("upload-*"):
            leftover.unlink(missing_ok=True)
        await anyio.to_thread.run_sync(upgrade_head, settings.sqlalchemy_url)
        if settings.fusion_weights is not None:  # refused at start, not in the background
            pinned_fusion(preset, settings.fusion_weights)
        engine = make_engine(
            settings.sqlalchemy_url, timeout_seconds=settings.database_timeout_seconds
        )
        read_sessions = make_session_factory(engine, read_only=True)
        state = AppState(
            settings=settings,
            preset=preset,
            engine=engine,
            sessions=make_session_factory(engine),
            read_sessions=read_sessions,
            queue=DescriptorQueue(settings),
            store=(
                DatabaseStore()
                if settings.uploads == "database"
                else DirectoryStore(settings.uploads_dir)
            ),
            metrics=metrics,
            galleries=Galleries(settings, metrics, read_sessions),
            keys=KeyRing(settings.api_key, read_sessions),
            recent_queries=Recent(settings.query_cache_size),
            verify_anchors=Recent(settings.verify_cache_size),
        )
        app.state.shapes = state
        collector = JobCollector(state)
        starter = threading.Thread(
            target=_start_background, args=(state, collector), name="startup", daemon=True
        )
        starter.start()
        try:
            yield
        finally:
            await anyio.to_thread.run_sync(starter.join)
            await anyio.to_thread.run_sync(collector.stop)
            await anyio.to_thread.run_sync(state.galleries.save)
            engine.dispose()

    app = FastAPI(
        title="Shape retrieval (GDM/DDT modal representation)",
        version="0.1.0",
        description=DESCRIPTION,
        lifespan=lifespan,
    )
    install_error_handlers(app, database_errors=DATABASE_ERRORS, queue_errors=QUEUE_ERRORS)
    app.add_middleware(RequestMetricsMiddleware, metrics=metrics)
    if settings.cors_origins:  # closed by default: browsers get no CORS headers at all
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "DELETE"],
            allow_headers=["X-API-Key", "Content-Type"],
        )
    scoped = (meshes_router, search_router, verification_router)
    for router in (*scoped, collections_router, keys_router, jobs_router, system_router):
        app.include_router(router)
    include_scoped(app, scoped)
    # The web page: static files, no build step (three.js vendored under static/vendor).
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/", include_in_schema=False)
    def page() -> FileResponse:
        return FileResponse(STATIC / "index.html")

    @app.get("/favicon.ico", include_in_schema=False)
    def favicon() -> FileResponse:  # browsers ask for it whatever the page links
        return FileResponse(STATIC / "favicon.svg", media_type="image/svg+xml")

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is not None:
            return app.openapi_schema
        schema = openapi_with_scoped(app)  # builds and caches app.openapi_schema
        document_limits(schema, max_k=settings.max_k, preset=settings.preset)
        if settings.api_key is None:
            document_open_access(schema)
        return schema

    # method-assign: replacing app.openapi is FastAPI's documented way to extend the schema.
    app.openapi = openapi  # type: ignore[method-assign]
    return app


# ``uvicorn app.main:app`` builds the app from the environment.
def __getattr__(name: str) -> FastAPI:
    if name == "app":
        return create_app()
    raise AttributeError(name)
