"""Request and response models of the mesh endpoints."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from ..models import MeshStatus
from ..schemas import UtcDatetime


class Links(BaseModel):
    self: str
    file: str
    job: str | None = None
    similar: str
    preview: str = Field(description="3D preview (GLB) once described")
    thumbnail: str = Field(description="PNG thumbnail once described")


class DescriptorInfo(BaseModel):
    preset: str
    preset_version: int
    input_vertices: int = Field(description="vertices of the cleaned upload")
    input_faces: int
    vertices: int = Field(description="vertices after resampling")
    timings: dict[str, float] = Field(description="seconds per pipeline stage, with 'total'")
    kept_area_fraction: float | None = Field(
        None,
        description="the described surface's share of the file's surface area: below 1 "
        "when the file has other, separate parts, which are left out (only its largest "
        "connected part is described); null for descriptors made before it was recorded",
    )
    input_points: int | None = Field(
        None,
        description="when the file was a point cloud (one view: an organized PCD or "
        "structured E57 scan triangulated by its grid, or points without one triangulated "
        "as seen from their sensor): its points that saw the surface; null for a mesh",
    )
    input_grid: list[int] | None = Field(
        None,
        description="that cloud's sensor grid, [width, height] pixels; null for a mesh or "
        "a cloud without one",
    )
    input_support: int | None = Field(
        None,
        description="that organized cloud's points on a floor, table or wall its object "
        "stood on or against (a plane running out of the frame with every other point in "
        "front of it), left out before it was triangulated; null for a mesh, a cloud "
        "without a grid, or descriptors made before it was recorded",
    )
    input_hidden: int | None = Field(
        None,
        description="when the cloud was not one view (a whole object's points, or several "
        "views merged): read as the view that sees most of it, the points hidden from "
        "there, left out; null for a mesh, one view, or descriptors made before it was "
        "recorded",
    )
    facing_share: float | None = Field(
        None,
        description="the largest share of the described surface's area facing one way: "
        "about 0.5 for a whole object, a cut or a holed copy of one, at least 0.95 for one "
        "view of a scanner (the faces a camera sees); null for descriptors made before it "
        "was recorded",
    )
    smoothed: bool | None = Field(
        None,
        description="whether the surface looked noisy (rough, as a scanner's noise leaves "
        "it, not as a coarse sampling does) and was smoothed before it was described (a "
        "single view: before it was fitted); null for descriptors made before it was "
        "recorded",
    )


class MeshOut(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "id": 1,
                    "collection": "default",
                    "name": "wolf0",
                    "label": "wolf",
                    "metadata": {"source": "TOSCA"},
                    "filename": "wolf0.off.gz",
                    "size_bytes": 86745,
                    "sha256": "3f1c…",
                    "status": "ready",
                    "error": None,
                    "detail": None,
                    "descriptor": {
                        "preset": "smeets2010-shrec",
                        "preset_version": 1,
                        "input_vertices": 4344,
                        "input_faces": 8684,
                        "vertices": 2500,
                        "timings": {"load": 0.1, "total": 2.3},
                        "kept_area_fraction": 1.0,
                    },
                    "job_id": 1,
                    "created_at": "2025-01-01T00:00:00",
                    "updated_at": "2025-01-01T00:00:03",
                    "links": {
                        "self": "/meshes/1",
                        "file": "/meshes/1/file",
                        "job": "/jobs/1",
                        "similar": "/meshes/1/similar",
                        "preview": "/meshes/1/preview",
                        "thumbnail": "/meshes/1/thumbnail",
                    },
                }
            ]
        }
    )

    id: int
    collection: str = Field(description="the collection it is enrolled in")
    name: str
    label: str | None
    metadata: dict[str, Any]
    filename: str
    size_bytes: int
    sha256: str
    status: MeshStatus
    error: str | None = Field(None, description="machine-readable reason when failed")
    detail: str | None = Field(None, description="why it failed, as a sentence")
    descriptor: DescriptorInfo | None = None
    job_id: int | None = None
    created_at: UtcDatetime
    updated_at: UtcDatetime
    links: Links


class MeshPage(BaseModel):
    items: list[MeshOut]
    total: int
    offset: int
    limit: int
