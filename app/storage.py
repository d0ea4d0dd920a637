"""Content-addressed storage of original uploads: ``uploads/<sha[:2]>/<sha>``.

A stored file is never rewritten: the same bytes always land on the same path,
so storing twice is a no-op and a crash can leave at most an unreferenced file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class ReceivedFile:
    """An upload received into a temporary file: where it waits, its original name,
    its size in bytes and its sha256 (hex). What the services take, free of HTTP types."""

    path: Path
    filename: str
    size: int
    sha256: str


class UploadStore:
    def __init__(self, root: Path) -> None:
        self.root = root

    def relative_path(self, sha256: str) -> str:
        return f"{sha256[:2]}/{sha256}"

    def path(self, relative: str) -> Path:
        return self.root / relative

    def put(self, temp_path: Path, sha256: str) -> str:
        """Move a received temporary file into the store; returns its relative path."""
        relative = self.relative_path(sha256)
        target = self.root / relative
        if target.exists():
            temp_path.unlink(missing_ok=True)
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            os.chmod(temp_path, 0o444)
            os.replace(temp_path, target)
        return relative

    def remove(self, relative: str) -> None:
        (self.root / relative).unlink(missing_ok=True)
