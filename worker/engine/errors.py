"""Typed errors for meshes the descriptor engine refuses.

Every error carries a machine-readable ``code`` and a ``message`` written for the
person who uploaded the file. The service maps them to HTTP statuses by ``code``;
the library itself knows nothing about HTTP.
"""

from __future__ import annotations


class MeshError(ValueError):
    """A mesh that cannot be described. ``message`` is a user-facing sentence."""

    code = "invalid_mesh"

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class UnsupportedFormatError(MeshError):
    """The file name's extension is not a mesh format we read."""

    code = "unsupported_format"


class UnreadableMeshError(MeshError):
    """The bytes could not be parsed as the declared format."""

    code = "unreadable_mesh"


class EmptyMeshError(MeshError):
    """The file parsed but holds no vertices."""

    code = "empty_mesh"


class PointCloudError(MeshError):
    """The file holds vertices but no triangles."""

    code = "no_faces"


class NonFiniteCoordinatesError(MeshError):
    """Some vertex coordinates are NaN, infinite or too large to compute with."""

    code = "non_finite_coordinates"


class TooFewVerticesError(MeshError):
    """After cleaning, the surface is too small to describe."""

    code = "too_few_vertices"


class NonManifoldError(MeshError):
    """Many faces meet at edges shared by three or more faces: not a surface."""

    code = "non_manifold"


class FileTooLargeError(MeshError):
    """The file (or what it decompresses to) is over the size limit."""

    code = "file_too_large"


class TooManyFacesError(MeshError):
    """The mesh has more faces than the configured limit."""

    code = "too_many_faces"
