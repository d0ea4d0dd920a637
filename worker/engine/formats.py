"""The file formats the engine reads, told by a file's name, and how much a file may hold.

Light on purpose (no numpy): the service checks an upload's name with it before any
byte is stored, and the command line builds its help from it.
"""

from __future__ import annotations

from pathlib import Path

from .errors import UnsupportedFormatError

MESH_FORMATS = ("obj", "ply", "off", "stl", "glb", "gltf", "pcd", "e57", "xyz", "pts", "csv")
DEFAULT_MAX_FACES = 2_000_000
DEFAULT_MAX_DECOMPRESSED_BYTES = 512 * 1024 * 1024


def mesh_format(filename: str) -> tuple[str, bool]:
    """Return ``(format, gzipped)`` for a file name, or raise ``UnsupportedFormatError``."""
    name = Path(filename).name.lower()
    gzipped = name.endswith(".gz")
    if gzipped:
        name = name[: -len(".gz")]
    ext = name.rsplit(".", 1)[-1] if "." in name else ""
    if ext not in MESH_FORMATS:
        shown = f".{ext}" if ext else "no extension"
        raise UnsupportedFormatError(
            f"Files with {shown} are not supported; upload one of "
            + ", ".join(f".{f}" for f in MESH_FORMATS)
            + " (optionally .gz-compressed)."
        )
    return ext, gzipped
