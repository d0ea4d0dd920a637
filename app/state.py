"""What the app holds for its lifetime (built in the lifespan, injected through deps)."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session, sessionmaker

from worker.engine.presets import Preset

from .config import Settings
from .index import GalleryIndex
from .metrics import Metrics
from .queue import DescriptorQueue
from .storage import UploadStore


@dataclass
class AppState:
    settings: Settings
    preset: Preset
    engine: Engine
    sessions: sessionmaker[Session]
    read_sessions: sessionmaker[Session]
    queue: DescriptorQueue
    store: UploadStore
    metrics: Metrics
    index: GalleryIndex | None = None
    index_error: str | None = None
    # Held while the database and the index change together (collector, delete),
    # so a shape deleted while its descriptor is being stored never reaches the index.
    gallery_lock: threading.Lock = field(default_factory=threading.Lock)
