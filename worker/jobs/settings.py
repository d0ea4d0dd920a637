"""The queue's settings, shared by the service and the workers.

Kept apart from :mod:`worker.jobs.queue` so that importing them (the service's
settings class extends this one; ``alembic/env.py`` reads those) loads neither
Huey nor the descriptor engine.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic_settings import BaseSettings, SettingsConfigDict

Queue = Literal["enroll", "query"]
#: The two queues: enrollments (bulk, collected by the service) and queries (a client
#: waits for the answer). Each has its own consumers, so a query never waits for a
#: worker busy with an enrollment.
QUEUES: tuple[Queue, ...] = ("enroll", "query")


class QueueSettings(BaseSettings):
    """Queue settings, read from ``SHAPES_*`` environment variables.

    The service's settings class extends this one, so the API process and the
    worker processes read the same variables the same way.
    """

    model_config = SettingsConfigDict(env_prefix="SHAPES_", extra="ignore")

    data_dir: Path = Path("data")
    # SQLAlchemy URL; the service's default is sqlite:///<data_dir>/shapes.sqlite3. A
    # worker reads it only when uploads are kept in the database (worker.jobs.sources).
    database_url: str | None = None
    redis_url: str | None = None
    # Enrollments go to this queue, queries to "<queue_name>-queries" (see QUEUES).
    queue_name: str = "shapes"
    # Enrollment consumers lower their CPU priority by this much (os.nice), so a query
    # consumer on the same cores is never slowed down by a bulk import.
    enroll_nice: int = 19
    heartbeat_seconds: float = 2.0
    # Per job, in a child process; a job over either fails with a sentence (0: no limit).
    job_time_limit_seconds: float = 600.0
    job_memory_limit_mb: int = 4096

    def queue_name_of(self, queue: Queue) -> str:
        """The Huey queue name of ``queue``."""
        return self.queue_name if queue == "enroll" else f"{self.queue_name}-queries"
