"""HTTP layer of /meshes: parse, call the service, shape the response."""

from __future__ import annotations

from typing import Annotated, Any
from urllib.parse import quote

from fastapi import APIRouter, Query, Response, status
from fastapi.responses import FileResponse

from ..deps import (
    READ_ACCESS,
    WRITE_ACCESS,
    GalleryDep,
    MultipartDep,
    RowId,
    SessionDep,
    StateDep,
    require_file,
)
from ..descriptors import enrolled_mesh
from ..errors import InvalidInputError
from ..links import collection_path
from ..models import Descriptor, Mesh, MeshStatus
from ..repositories.meshes import Order
from ..schemas import (
    ACCESS_RESPONSES,
    ERROR_RESPONSES,
    FILE_RESPONSES,
    MESH_FILE,
    TEXT_PATTERN,
    multipart_body,
    or_blank,
)
from . import service
from .schemas import DescriptorInfo, Links, MeshOut, MeshPage
from .service import MAX_NAME

# A mesh id is never reused and its preview never changes: browsers may keep it.
CACHE_FOREVER = {"Cache-Control": "private, max-age=86400, immutable"}

router = APIRouter(
    prefix="/meshes",
    tags=["meshes"],
    dependencies=READ_ACCESS,
    responses=ERROR_RESPONSES | ACCESS_RESPONSES,
)

Responses = dict[int | str, dict[str, Any]]
ERRORS: Responses = {
    404: {"description": 'Unknown id: `{"error": "not_found", "detail": ...}`'},
}
PREVIEW_ERRORS: Responses = {
    404: {"description": "Unknown id, or no preview (`no_preview`: the mesh failed)"},
    409: {"description": "Queued or being described (`mesh_not_ready`)"},
}
UPLOAD_ERRORS: Responses = FILE_RESPONSES | {
    409: {"description": "Same bytes enrolled as another format (`same_bytes_other_format`)"},
    422: {"description": "No file, empty file, or bad metadata"},
}


# OpenAPI links from a response that is one mesh to every operation taking its id, and
# to its job (clients and stateful fuzzers follow them).
_MESH_ID = {"mesh_id": "$response.body#/id"}
JOB_LINK = {
    "GetJob": {"operationId": "get_job", "parameters": {"job_id": "$response.body#/job_id"}}
}
MESH_LINKS = {
    "GetMesh": {"operationId": "get_mesh", "parameters": _MESH_ID},
    "GetMeshFile": {"operationId": "get_mesh_file", "parameters": _MESH_ID},
    "GetMeshPreview": {"operationId": "get_mesh_preview", "parameters": _MESH_ID},
    "GetMeshThumbnail": {"operationId": "get_mesh_thumbnail", "parameters": _MESH_ID},
    "DeleteMesh": {"operationId": "delete_mesh", "parameters": _MESH_ID},
    "SimilarMeshes": {"operationId": "similar_meshes", "parameters": _MESH_ID},
} | JOB_LINK

UPLOAD_BODY = multipart_body(
    {
        "file": MESH_FILE,
        "name": {
            "type": "string",
            "maxLength": MAX_NAME,
            "pattern": TEXT_PATTERN,
            "description": "default: the file name",
        },
        "label": {
            "type": "string",
            "maxLength": MAX_NAME,
            "pattern": TEXT_PATTERN,
            "description": "class, e.g. 'wolf'",
        },
        "metadata": or_blank(
            {
                "type": "object",
                "description": "any JSON object, kept with the mesh",
                "example": {"source": "TOSCA"},
            }
        ),
    },
    required=("file",),
)


def mesh_out(mesh: Mesh, descriptor: Descriptor | None, collection: str) -> MeshOut:
    job = mesh.jobs[-1] if mesh.jobs else None
    failed = mesh.status == MeshStatus.failed.value
    base = f"{collection_path(collection)}/meshes/{mesh.id}"
    return MeshOut(
        id=mesh.id,
        collection=collection,
        name=mesh.name,
        label=mesh.label,
        metadata=mesh.meta or {},
        filename=mesh.filename,
        size_bytes=mesh.size_bytes,
        sha256=mesh.sha256,
        status=MeshStatus(mesh.status),
        error=mesh.error_code if failed else None,
        detail=mesh.error_detail if failed else None,
        descriptor=None
        if descriptor is None
        else DescriptorInfo(
            preset=descriptor.preset,
            preset_version=descriptor.preset_version,
            input_vertices=descriptor.input_vertices,
            input_faces=descriptor.input_faces,
            vertices=descriptor.vertices,
            timings=descriptor.timings,
            kept_area_fraction=descriptor.kept_area_fraction,
            input_points=descriptor.input_points,
            input_grid=descriptor.input_grid,
            input_support=descriptor.input_support,
            input_hidden=descriptor.input_hidden,
            facing_share=descriptor.facing_share,
            smoothed=descriptor.smoothed,
        ),
        job_id=job.id if job else None,
        created_at=mesh.created_at,
        updated_at=mesh.updated_at,
        links=Links(
            self=base,
            file=f"{base}/file",
            job=f"/jobs/{job.id}" if job else None,
            similar=f"{base}/similar",
            preview=f"{base}/preview",
            thumbnail=f"{base}/thumbnail",
        ),
    )


@router.post(
    "",
    dependencies=WRITE_ACCESS,
    status_code=status.HTTP_202_ACCEPTED,
    response_model=MeshOut,
    operation_id="enroll_mesh",
    summary="Enroll a mesh",
    description=(
        "Stores the upload (content-addressed), creates the mesh and queues its descriptor "
        "job: **202** with status `queued`. The same bytes again answer **200** with the "
        "existing mesh, or **202** when this queued it again (it had failed for a reason "
        "that says nothing about the file, such as `describe_crashed` or `worker_lost`, or "
        "its job was lost). While the queue is down an upload is still stored and answered; "
        "it is queued once the queue is back. Poll `GET /meshes/{id}` until `ready` (or "
        "`failed`, with `detail`).\n\n"
        "`curl -F file=@wolf0.off.gz -F label=wolf http://127.0.0.1:8000/meshes`"
    ),
    responses=Responses(
        {
            200: {
                "description": "Already enrolled (same sha256), nothing queued",
                "model": MeshOut,
                "links": MESH_LINKS,
            },
            202: {
                "description": "Enrolled (or enrolled before and queued again), descriptor "
                "job queued",
                "links": MESH_LINKS,
            },
        }
    )
    | UPLOAD_ERRORS,
    openapi_extra=UPLOAD_BODY,
)
def enroll(
    gallery: GalleryDep,
    upload: MultipartDep,
    session: SessionDep,
    state: StateDep,
    response: Response,
) -> MeshOut:
    file = require_file(upload)
    unknown = set(upload.fields) - {"name", "label", "metadata"}
    if unknown:
        raise InvalidInputError(
            f"Unknown form fields: {', '.join(sorted(unknown))}; "
            "use file, name, label and metadata.",
            code="unknown_field",
        )
    mesh, queued = service.enroll(
        session,
        state,
        gallery,
        file,
        name=upload.fields.get("name"),
        label=upload.fields.get("label"),
        metadata=upload.fields.get("metadata"),
    )
    response.status_code = status.HTTP_202_ACCEPTED if queued else status.HTTP_200_OK
    response.headers["Location"] = f"{collection_path(gallery.name)}/meshes/{mesh.id}"
    return mesh_out(mesh, service.descriptor_of(session, gallery, mesh), gallery.name)


@router.get("", response_model=MeshPage, operation_id="list_meshes", summary="List meshes")
def list_meshes(
    gallery: GalleryDep,
    session: SessionDep,
    state: StateDep,
    label: Annotated[
        str | None,
        # Documented, and checked by the service with its own sentence (invalid_text).
        Query(description="only this class", json_schema_extra={"pattern": TEXT_PATTERN}),
    ] = None,
    status_: Annotated[MeshStatus | None, Query(alias="status")] = None,
    offset: Annotated[int, Query(ge=0, le=2**63 - 1)] = 0,  # SQLite: 64-bit
    limit: Annotated[int, Query(ge=1, le=1000)] = 50,
    sort: Annotated[
        Order,
        Query(description="the order: enrollment (oldest or newest first), name, label, status"),
    ] = "oldest",
) -> MeshPage:
    page = service.list_page(
        session,
        state,
        gallery,
        label=label,
        status=status_,
        offset=offset,
        limit=limit,
        order=sort,
    )
    return MeshPage(
        items=[mesh_out(m, d, gallery.name) for m, d in page.items],
        total=page.total,
        offset=page.offset,
        limit=page.limit,
    )


@router.get(
    "/{mesh_id}",
    response_model=MeshOut,
    operation_id="get_mesh",
    summary="One mesh",
    responses=ERRORS | {200: {"description": "The mesh", "links": JOB_LINK}},
)
def get_mesh(mesh_id: RowId, gallery: GalleryDep, session: SessionDep) -> MeshOut:
    mesh = enrolled_mesh(session, gallery, mesh_id)
    return mesh_out(mesh, service.descriptor_of(session, gallery, mesh), gallery.name)


def _attachment(filename: str) -> str:
    """The Content-Disposition of a download, as Starlette's FileResponse writes it."""
    quoted = quote(filename)
    if quoted != filename:
        return f"attachment; filename*=utf-8''{quoted}"
    return f'attachment; filename="{filename}"'


@router.get(
    "/{mesh_id}/file",
    operation_id="get_mesh_file",
    summary="The original upload, byte for byte",
    response_class=FileResponse,
    responses=ERRORS,
)
def get_file(mesh_id: RowId, gallery: GalleryDep, session: SessionDep, state: StateDep) -> Response:
    mesh, file = service.original_file(session, state, gallery, mesh_id)
    if isinstance(file, bytes):  # kept in the database
        return Response(
            file,
            media_type="application/octet-stream",
            headers={"Content-Disposition": _attachment(mesh.filename)},
        )
    return FileResponse(file, media_type="application/octet-stream", filename=mesh.filename)


@router.get(
    "/{mesh_id}/preview",
    operation_id="get_mesh_preview",
    summary="A small 3D preview (binary glTF, a few thousand triangles, unit size)",
    response_class=Response,
    responses=PREVIEW_ERRORS | {200: {"content": {"model/gltf-binary": {}}}},
)
def get_preview(mesh_id: RowId, gallery: GalleryDep, session: SessionDep) -> Response:
    stored = service.preview(session, gallery, mesh_id)
    return Response(stored.glb, media_type="model/gltf-binary", headers=CACHE_FOREVER)


@router.get(
    "/{mesh_id}/thumbnail",
    operation_id="get_mesh_thumbnail",
    summary="A 256 x 256 PNG thumbnail",
    response_class=Response,
    responses=PREVIEW_ERRORS | {200: {"content": {"image/png": {}}}},
)
def get_thumbnail(mesh_id: RowId, gallery: GalleryDep, session: SessionDep) -> Response:
    stored = service.preview(session, gallery, mesh_id)
    return Response(stored.png, media_type="image/png", headers=CACHE_FOREVER)


@router.delete(
    "/{mesh_id}",
    dependencies=WRITE_ACCESS,
    status_code=status.HTTP_204_NO_CONTENT,
    operation_id="delete_mesh",
    summary="Delete a mesh (leaves the index at once)",
    responses=ERRORS,
)
def delete_mesh(
    mesh_id: RowId, gallery: GalleryDep, session: SessionDep, state: StateDep
) -> Response:
    service.delete(session, state, gallery, mesh_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
