"""The descriptors of recent query uploads, by content, so asking again costs nothing."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Hashable

from worker.engine.pipeline import ShapeDescriptor


class RecentDescriptors:
    """A thread-safe least-recently-used map from a query's content key to its
    descriptor (a few kilobytes each: 1,024 of them take a few MB).

    Parameters
    ----------
    size : entries kept; 0 keeps none.
    """

    def __init__(self, size: int) -> None:
        self.size = size
        self._items: OrderedDict[Hashable, ShapeDescriptor] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._items)

    def get(self, key: Hashable) -> ShapeDescriptor | None:
        with self._lock:
            descriptor = self._items.get(key)
            if descriptor is not None:
                self._items.move_to_end(key)
            return descriptor

    def put(self, key: Hashable, descriptor: ShapeDescriptor) -> None:
        if self.size <= 0:
            return
        with self._lock:
            self._items[key] = descriptor
            self._items.move_to_end(key)
            while len(self._items) > self.size:
                self._items.popitem(last=False)
