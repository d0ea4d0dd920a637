"""HTTP layer of the searches: ``POST /query`` and ``POST /meshes/{mesh_id}/similar``."""

from __future__ import annotations

import itertools
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Path, Request, Response

from worker.engine.presets import PARTS, PRESETS

from ..deps import (
    READ_ACCESS,
    GalleryDep,
    MultipartDep,
    ReadSessionDep,
    RowId,
    SessionDep,
    StateDep,
    require_file,
)
from ..errors import InvalidInputError, NotFoundError
from ..links import SCOPED_PREFIX
from ..schemas import (
    ACCESS_RESPONSES,
    ERROR_RESPONSES,
    FILE_RESPONSES,
    MESH_FILE,
    multipart_body,
    or_blank,
    threshold_out,
)
from . import service
from .schemas import MatchOut, PartialOut, QueryOut

#: How the parts modality compares (worker.engine.parts): each query sample's profile
#: with the nearest of the whole's, at the query's best scale.
PARTS_COMPARISON = "nearest profiles"

router = APIRouter(
    tags=["search"], dependencies=READ_ACCESS, responses=ERROR_RESPONSES | ACCESS_RESPONSES
)

# The options, documented once: form fields of /query, query parameters of /similar.
# Both arrive as strings and are validated by service.parse_options.
OPTION_SCHEMAS: dict[str, dict[str, Any]] = {
    "k": {
        "type": "integer",
        "default": service.DEFAULT_K,
        "minimum": 1,
        "description": "number of matches",
    },
    "preset": {
        "type": "string",
        "example": "smeets2010-shrec",
        "description": "must be the collection's preset",
    },
    "fusion": {
        "type": "string",
        "enum": ["sum", "product"],
        "description": "default: the preset's rule",
    },
    "modalities": {
        "type": "string",
        "pattern": service.MODALITIES_PATTERN,
        "example": "gdm,ddt",
        "description": "comma-separated, among gdm, ddt, spectrum (default: the preset's)",
    },
    "far": {
        "type": "number",
        "exclusiveMinimum": 0,
        "exclusiveMaximum": 1,
        "example": 0.01,
        "description": "false acceptance rate: mark each match accepted or not at the "
        "threshold the gallery's calibration gives for it (GET /calibration); 409 "
        "not_calibrated when the gallery has too few labelled pairs",
    },
}


QUERY_BODY = multipart_body(
    {"file": MESH_FILE} | {name: or_blank(schema) for name, schema in OPTION_SCHEMAS.items()},
    required=("file",),
)

SIMILAR_PARAMETERS = {
    "parameters": [
        {
            "name": name,
            "in": "query",
            "required": False,
            "allowEmptyValue": True,  # blank means the default, as for /query's fields
            "description": schema["description"],
            "schema": {k: v for k, v in schema.items() if k != "description"},
        }
        for name, schema in OPTION_SCHEMAS.items()
    ]
}

QUERY_ERRORS: dict[int | str, dict[str, Any]] = FILE_RESPONSES | {
    409: {
        "description": "far given but the gallery is not calibrated (`not_calibrated`), or "
        "a preset other than the collection's (`preset_not_enrolled`)"
    },
    422: {"description": "Unreadable mesh, bad k/preset/fusion/modalities/far"},
    503: {"description": "Index loading, or no worker answered in time"},
}
SIMILAR_ERRORS: dict[int | str, dict[str, Any]] = {
    404: {"description": 'Unknown id: `{"error": "not_found", "detail": ...}`'},
    409: {
        "description": "The mesh is not ready yet (`mesh_not_ready`), far given but the "
        "gallery is not calibrated (`not_calibrated`), or a preset other than the "
        "collection's (`preset_not_enrolled`)"
    },
    422: {"description": "Bad k/preset/fusion/modalities/far"},
    503: {"description": "Index loading"},
}


def document_limits(openapi: dict[str, Any], *, max_k: int, preset: str) -> None:
    """Write the deployment's own limits into the options' schemas (in place): ``k`` at
    most ``SHAPES_MAX_K``; ``preset`` the service's on the default collection's paths (its
    preset, and every collection's created without one), any preset on a collection's
    (which may have been created with another; naming another than its own is 409
    ``preset_not_enrolled``), so that documented and accepted values agree."""
    searches = (("/query", "form"), ("/meshes/{mesh_id}/similar", "query"))
    for prefix, (path, where) in itertools.product(("", SCOPED_PREFIX), searches):
        operation = openapi["paths"][prefix + path]["post"]
        if where == "form":
            content = operation["requestBody"]["content"]["multipart/form-data"]
            fields = content["schema"]["properties"]
            options = {name: fields[name]["anyOf"][0] for name in OPTION_SCHEMAS}
        else:
            options = {p["name"]: p["schema"] for p in operation["parameters"]}
        options["k"]["maximum"] = max_k
        options["preset"]["enum"] = sorted(PRESETS) if prefix else [preset]


def query_out(result: service.SearchResult) -> QueryOut:
    options = result.options
    return QueryOut(
        preset=options.preset.name,
        preset_version=options.preset.version,
        dissimilarity=options.preset.dissimilarity,
        comparisons={
            m: PARTS_COMPARISON if m == PARTS else options.preset.comparison(m)
            for m in result.weights
        },
        fusion=result.fusion,
        modalities=[m for m, w in result.weights.items() if w > 0],
        weights=result.weights,
        k=options.k,
        collection=result.collection,
        gallery_size=result.gallery_size,
        matches=[
            MatchOut(
                mesh_id=m.mesh.id,
                name=m.mesh.name,
                label=m.mesh.label,
                rank=m.rank,
                score=m.score,
                scores=m.scores,
                confidence=m.confidence,
                accepted=m.accepted,
                closeness=m.closeness,
                fitness=m.fitness,
            )
            for m in result.matches
        ],
        far=options.far,
        threshold=None if result.threshold is None else threshold_out(result.threshold),
        timings=result.timings,
        query=result.query,
        descriptor_source=result.descriptor_source,
        partial=None
        if result.partial is None
        else PartialOut(
            partiality=result.partial.partiality,
            missing_share=result.partial.missing_share,
            missing_share_range=result.partial.missing_range,
            single_view=result.partial.single_view,
            smoothed=result.partial.smoothed,
            found=result.partial.found,
            note=result.partial.note,
        ),
        notes=result.notes,
        preview=result.preview,
    )


@router.post(
    "/query",
    response_model=QueryOut,
    operation_id="query",
    summary="Rank the gallery by similarity to an uploaded mesh",
    description=(
        "Computes the query's descriptor in the worker pool (a few seconds), then ranks the "
        "gallery by the collection's exact fused dissimilarity (the preset's, or the fusion "
        "the collection learned from its labels; lower is more similar).\n\n"
        "`curl -F file=@wolf2.off.gz -F k=3 http://127.0.0.1:8000/query`"
    ),
    responses=QUERY_ERRORS,
    openapi_extra=QUERY_BODY,
)
def query(
    gallery: GalleryDep, upload: MultipartDep, session: ReadSessionDep, state: StateDep
) -> QueryOut:
    file = require_file(upload)
    fields = upload.fields
    unknown = set(fields) - set(service.OPTION_NAMES)
    if unknown:
        raise InvalidInputError(
            f"Unknown form fields: {', '.join(sorted(unknown))}; "
            "use file, k, preset, fusion, modalities and far.",
            code="unknown_field",
        )
    options = service.parse_options(
        state,
        gallery,
        k=fields.get("k"),
        preset=fields.get("preset"),
        fusion=fields.get("fusion"),
        modalities=fields.get("modalities"),
        far=fields.get("far"),
    )
    return query_out(service.query_by_upload(session, state, gallery, file, options))


def similar_options(
    request: Request, state: StateDep, gallery: GalleryDep
) -> service.SearchOptions:
    """The options of /similar, read as sent (documented by ``SIMILAR_PARAMETERS``)."""
    params = request.query_params
    return service.parse_options(
        state,
        gallery,
        k=params.get("k"),
        preset=params.get("preset"),
        fusion=params.get("fusion"),
        modalities=params.get("modalities"),
        far=params.get("far"),
    )


@router.post(
    "/meshes/{mesh_id}/similar",
    response_model=QueryOut,
    operation_id="similar_meshes",
    summary="Shapes most similar to an enrolled mesh",
    description="Uses the stored descriptor (nothing is recomputed); the mesh itself is left out.",
    responses=SIMILAR_ERRORS,
    openapi_extra=SIMILAR_PARAMETERS,
)
def similar(
    mesh_id: RowId,
    gallery: GalleryDep,
    session: ReadSessionDep,
    state: StateDep,
    options: Annotated[service.SearchOptions, Depends(similar_options)],
) -> QueryOut:
    return query_out(service.similar_to(session, state, gallery, mesh_id, options))


@router.get(
    "/previews/{sha256}",
    operation_id="get_query_preview",
    summary="The 3D preview (GLB) of a mesh searched with recently, by its sha256",
    response_class=Response,
    responses={
        200: {"content": {"model/gltf-binary": {}}},
        404: {"description": "No preview of these bytes (`no_preview`)"},
    },
)
def query_preview(
    sha256: Annotated[str, Path(pattern="^[0-9a-f]{64}$")],
    gallery: GalleryDep,
    session: SessionDep,
) -> Response:
    glb = service.query_preview(session, gallery, sha256)
    if glb is None:
        raise NotFoundError(
            "There is no preview of these bytes in this collection: they were not searched "
            "with here recently (the service keeps the last SHAPES_QUERY_PREVIEWS_KEPT) nor "
            "enrolled here.",
            code="no_preview",
        )
    return Response(glb, media_type="model/gltf-binary")
