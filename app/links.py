"""Where a collection's resources are: its name's rule, and the paths that name it."""

from __future__ import annotations

from .models import DEFAULT_COLLECTION

#: A collection's name: it is a path segment, so letters, digits, "-" and "_".
NAME_PATTERN = "^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$"

#: Where a collection's own resources are: its meshes, searches and calibration.
SCOPED_PREFIX = "/collections/{collection}"


def collection_path(name: str) -> str:
    """The path prefix of a collection's resources: none for the default collection."""
    return "" if name == DEFAULT_COLLECTION else f"/collections/{name}"
