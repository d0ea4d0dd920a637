"""What the app holds for its lifetime (built in the lifespan, injected through deps)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session, sessionmaker

from worker.engine.descriptor import ShapeDescriptor
from worker.engine.presets import Preset

from .config import Settings
from .galleries import Galleries
from .keyring import KeyRing
from .metrics import Metrics
from .queue import DescriptorQueue
from .recent import Recent
from .storage import UploadStore

if TYPE_CHECKING:  # the module needs scipy, imported by the first single view
    from worker.engine.rigid import Anchors


@dataclass
class AppState:
    """``preset`` is the service's (``SHAPES_PRESET``): the default collection's, and any
    collection's created without one."""

    settings: Settings
    preset: Preset
    engine: Engine
    sessions: sessionmaker[Session]
    read_sessions: sessionmaker[Session]
    queue: DescriptorQueue
    store: UploadStore
    metrics: Metrics
    galleries: Galleries
    keys: KeyRing
    recent_queries: Recent[ShapeDescriptor]
    verify_anchors: Recent[Anchors]
