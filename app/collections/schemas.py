"""Request and response models of the collection endpoints."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, JsonValue

from worker.engine.presets import PRESETS

from ..links import NAME_PATTERN
from ..models import Units
from ..schemas import UtcDatetime
from .service import MAX_WEIGHT

PRESET_NAMES: list[JsonValue] = [name for name in sorted(PRESETS)]


class CollectionIn(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str = Field(pattern=NAME_PATTERN, description="part of the collection's paths")
    units: Units = Field(
        Units.any,
        description="`any`: the files' units are arbitrary, shapes are compared scale-free; "
        "`metric`: every file is in one physical unit (a scanner's millimetres or metres), "
        "so the size of a shape is a cue of its own in the fused score",
    )
    preset: str | None = Field(
        None,
        description="the preset its meshes are described with (default: the service's)",
        json_schema_extra={"enum": PRESET_NAMES},
    )


Modality = Literal["gdm", "ddt", "spectrum", "size"]
# Strict: a JSON number (an integer too), never true or false read as 1 or 0.
Weight = Annotated[float, Field(ge=0, le=MAX_WEIGHT, strict=True)]


class FusionPin(BaseModel):
    model_config = ConfigDict(extra="forbid")

    weights: dict[Modality, Weight] | None = Field(
        description="the product's exponent (or the sum's factor) per modality, e.g. "
        '{"gdm": 0, "ddt": 0.5, "spectrum": 1}; a modality left out keeps the preset\'s '
        "weight, and one the collection does not score (the size in units any) is kept "
        "unused; null unpins them",
    )


class CollectionLinks(BaseModel):
    self: str
    meshes: str
    query: str
    calibration: str


class CollectionOut(BaseModel):
    name: str
    units: Units
    preset: str
    preset_version: int
    fusion_weights: dict[str, float] | None = Field(
        description="the weights pinned for this collection; null: learned from its labels, "
        "or the preset's (GET .../calibration says which)"
    )
    meshes: int = Field(description="enrolled meshes")
    ready: int = Field(description="meshes described and searchable")
    created_at: UtcDatetime
    links: CollectionLinks


class CollectionList(BaseModel):
    items: list[CollectionOut]
