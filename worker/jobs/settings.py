"""The queue's settings, shared by the service and the workers.

Kept apart from :mod:`worker.jobs.queue` so that importing them (the service's
settings class extends this one; ``alembic/env.py`` reads those) loads neither
Huey nor the descriptor engine.
"""

from __future__ import annotations

from pathlib import Path

from pydantic_settings import BaseSettings, SettingsConfigDict


class QueueSettings(BaseSettings):
    """Queue settings, read from ``SHAPES_*`` environment variables.

    The service's settings class extends this one, so the API process and the
    worker processes read the same variables the same way.
    """

    model_config = SettingsConfigDict(env_prefix="SHAPES_", extra="ignore")

    data_dir: Path = Path("data")
    redis_url: str | None = None
    queue_name: str = "shapes"
    heartbeat_seconds: float = 2.0
    # Per job, in a child process; a job over either fails with a sentence (0: no limit).
    job_time_limit_seconds: float = 600.0
    job_memory_limit_mb: int = 4096
