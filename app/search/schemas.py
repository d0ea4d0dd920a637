"""Response models of the search endpoints."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class MatchOut(BaseModel):
    mesh_id: int
    name: str
    label: str | None
    rank: int = Field(description="1 = most similar")
    score: float = Field(description="fused dissimilarity (lower is more similar)")
    scores: dict[str, float] = Field(
        description="per-modality dissimilarity, each by its comparison (the answer's "
        "'comparisons')"
    )
    confidence: float | None = Field(
        None,
        description="probability that the match has the query's label, from the gallery's "
        "calibration (isotonic on its labelled pairs); null when the gallery is not "
        "calibrated or the fusion asked for is not the preset's",
    )
    accepted: bool | None = Field(
        None, description="with far: whether the score is within the threshold at that FAR"
    )
    closeness: dict[str, float] = Field(
        default_factory=dict,
        description="per modality: the share of the collection's pairs of different objects "
        "that are farther apart than this match (1: closer than all of them); the same "
        "scale in every collection and for every query; empty until the collection has "
        "two shapes",
    )
    fitness: float | None = Field(
        None,
        description="a single view's matches that were fitted to it (the parts' best 20 and "
        "the 10 of their best 100 whose surfaces' features lie closest to the view's): the "
        "share of the view that lies on this match's surface once fitted to it rigidly "
        "(scaled too in a collection without units), the order they come in; null for "
        "other queries and matches",
    )


class PartialOut(BaseModel):
    partiality: float = Field(
        description="how partial the query looks, from its open boundary and the share of "
        "its file left out: 0 a whole, 1 wholly partial (the weight of the parts modality)"
    )
    missing_share: float = Field(
        description="the share of its whole's surface the query seems to miss, from the scale "
        "at which its parts matched best (and the parts of its file left out), rounded to "
        "0.01: an estimate within missing_share_range"
    )
    missing_share_range: tuple[float, float] = Field(
        description="its bounds: the scale is measured on a grid of steps of 2^(1/8)"
    )
    single_view: bool = Field(
        False,
        description="the query is one view of its object (a scanner's point "
        "cloud, or a surface facing one way: query.facing_share at least 0.95), described with "
        "its unseen side taken as the mirror image of the side it sees: missing_share is "
        "then that two-sided surface's, which matches as nearly whole, not what the scan "
        "misses",
    )
    smoothed: bool = Field(
        False,
        description="the query's surface looked noisy (rough, with a residual a cubic fit "
        "takes no more of than a quadric's: a sensor's noise, not a coarse sampling) and was "
        "smoothed: a single view before it was fitted, any other surface before it was "
        "described; the note says so",
    )
    found: bool = Field(
        False,
        description="a single view that a fitted match holds as its own object's surface "
        "does (a fitness of at least 0.9; on the evaluation's views such a match was of the "
        "view's class every time without depth noise, all but 2 of 249 times with it); false "
        "for other queries",
    )
    note: str = Field(description="the same, as a sentence for the user")


class QueryOut(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "preset": "smeets2010-shrec",
                    "preset_version": 1,
                    "dissimilarity": "D2",
                    "comparisons": {"gdm": "D2", "ddt": "D2"},
                    "fusion": "product",
                    "modalities": ["gdm", "ddt"],
                    "k": 2,
                    "collection": "default",
                    "gallery_size": 3,
                    "matches": [
                        {
                            "mesh_id": 2,
                            "name": "wolf1",
                            "label": "wolf",
                            "rank": 1,
                            "score": 0.41,
                            "scores": {"gdm": 0.52, "ddt": 0.79},
                        }
                    ],
                    "timings": {"describe_wall": 1.3, "search": 0.0004},
                    "query": {
                        "input_vertices": 4344,
                        "input_faces": 8684,
                        "vertices": 2500,
                        "kept_area_fraction": 1.0,
                    },
                    "descriptor_source": "computed",
                }
            ]
        }
    )

    preset: str
    preset_version: int
    dissimilarity: str = Field(description="the preset's comparison, D1 (eq. 8) or D2 (eq. 9)")
    comparisons: dict[str, str] = Field(
        description="each searched modality's comparison in this collection: the preset's, "
        "or one its learned fusion chose (D1, D2, 'reweighted euclidean' for the spectrum), "
        "the size's in metric units"
    )
    fusion: str
    modalities: list[str] = Field(
        description="the modalities the matches were ranked by: the fused ones with a weight "
        "above 0 (for a partial query, 'parts' and any the ramp still mixes in)"
    )
    weights: dict[str, float] = Field(
        default_factory=dict,
        description="the weight each ranked modality's score carried in the fused score",
    )
    k: int
    collection: str = Field(description="the collection searched")
    gallery_size: int
    matches: list[MatchOut]
    timings: dict[str, float] = Field(
        description="seconds: descriptor stages of the query (if computed), 'search', "
        "'verify' (a single view's rigid verification), 'total'"
    )
    query: dict[str, bool | int | float | list[int]] = Field(
        default_factory=dict,
        description="the query's mesh: input_vertices, input_faces (cleaned), vertices "
        "(described), and kept_area_fraction, the described surface's share of the file's "
        "surface area (below 1 when the file has other, separate parts, which are left out), "
        "facing_share, the largest share of its surface facing one way (about 0.5 for a "
        "whole, a cut or a holed copy, near 1 for one view); "
        "for a point cloud also input_points (its points that saw the surface), and for "
        "an organized one (a PCD with a grid or a structured E57 scan) input_grid "
        "([width, height]) and input_support (its points on a floor, table or wall its "
        "object stood on or against, left out); for a cloud that is not one view (a whole "
        "object's points) input_hidden, its points hidden from the view that sees most of "
        "it, left out; smoothed (true) when its surface looked "
        "noisy and was smoothed before it was described (a single view: before it was "
        "fitted)",
    )
    partial: PartialOut | None = Field(
        None,
        description="present when the query looks partial (a cut, holes, one view): its "
        "matches are then ranked with the parts modality, which compares a part with a "
        "whole, and their scores are not on the calibrated scale (no confidence, no "
        "threshold)",
    )
    notes: list[str] = Field(
        default_factory=list,
        description="what the answer says of its query, in sentences for a person (as "
        "`shapes query` and the web page print them): the point cloud it was, the part of "
        "the file left out, how partial it looks (the partial note) or, a whole, that its "
        "surface was smoothed of noise; empty when there is nothing to say",
    )
    preview: str | None = Field(
        None, description="where the query mesh's 3D preview (GLB) can be fetched"
    )
    far: float | None = Field(None, description="the false acceptance rate asked for")
    threshold: float | None = Field(
        None,
        description="with far: the score threshold at that FAR (accepted: score <= it); "
        "null without far, or when nothing is accepted at that FAR",
    )
    descriptor_source: Literal["computed", "enrolled", "recent", "stored"] = Field(
        description="where the query's descriptor came from: computed now by a query worker, "
        "the enrolled mesh with the same bytes and format, a recent query with the same "
        "bytes, or the stored descriptor of the mesh /similar starts from"
    )
