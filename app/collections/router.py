"""HTTP layer of /collections: create, list, read and delete collections."""

from __future__ import annotations

import warnings
from typing import Annotated, Any

from fastapi import APIRouter, Depends, FastAPI, Path, Response, status

from ..deps import (
    ADMIN_ACCESS,
    READ_ACCESS,
    SERVICE_ADMIN,
    GrantDep,
    ReadSessionDep,
    SessionDep,
    StateDep,
    collection_parameter,
)
from ..links import NAME_PATTERN, SCOPED_PREFIX
from ..models import Scope, Units
from ..schemas import ACCESS_RESPONSES, ERROR_RESPONSES
from . import service
from .schemas import CollectionIn, CollectionLinks, CollectionList, CollectionOut, FusionPin

router = APIRouter(
    prefix="/collections", tags=["collections"], responses=ERROR_RESPONSES | ACCESS_RESPONSES
)

Name = Annotated[str, Path(pattern=NAME_PATTERN, description="the collection's name")]
# OpenAPI links from a new collection to its own operations (clients and stateful
# fuzzers follow them).
_NAME = {"collection": "$response.body#/name"}
COLLECTION_LINKS = {
    "GetCollection": {
        "operationId": "get_collection",
        "parameters": {"name": "$response.body#/name"},
    },
    "EnrollMesh": {"operationId": "collection_enroll_mesh", "parameters": _NAME},
    "ListMeshes": {"operationId": "collection_list_meshes", "parameters": _NAME},
    "GetCalibration": {"operationId": "collection_get_calibration", "parameters": _NAME},
    "DeleteCollection": {
        "operationId": "delete_collection",
        "parameters": {"name": "$response.body#/name"},
    },
}
CREATE_ERRORS: dict[int | str, dict[str, Any]] = {
    409: {"description": "The name is taken (`collection_exists`)"},
    422: {"description": "Bad name (`invalid_name`) or preset (`unknown_preset`)"},
}
NOT_FOUND: dict[int | str, dict[str, Any]] = {
    404: {"description": "No such collection (`collection_not_found`)"},
}
#: What every operation under /collections/{collection}/ may answer besides its own.
NO_COLLECTION: dict[int | str, dict[str, Any]] = {
    404: {"description": "No such collection (`collection_not_found`), or no such resource"},
}


def collection_out(view: service.CollectionView) -> CollectionOut:
    base = f"/collections/{view.row.name}"
    return CollectionOut(
        name=view.row.name,
        units=Units(view.row.units),
        preset=view.preset,
        preset_version=view.preset_version,
        fusion_weights=view.row.fusion_weights,
        meshes=view.meshes,
        ready=view.ready,
        created_at=view.row.created_at,
        links=CollectionLinks(
            self=base,
            meshes=f"{base}/meshes",
            query=f"{base}/query",
            calibration=f"{base}/calibration",
        ),
    )


@router.post(
    "",
    dependencies=SERVICE_ADMIN,
    status_code=status.HTTP_201_CREATED,
    response_model=CollectionOut,
    operation_id="create_collection",
    summary="Create a collection",
    description=(
        "A new, empty gallery with its own meshes, index, calibration, preset and units; "
        "its endpoints are under `/collections/{name}/` (`meshes`, `query`, `verify`, "
        "`calibration`, ...). The same bytes may be enrolled in several collections.\n\n"
        '`curl -H \'Content-Type: application/json\' -d \'{"name": "casts", "units": '
        '"metric"}\' http://127.0.0.1:8000/collections`'
    ),
    responses=CREATE_ERRORS | {201: {"description": "Created, empty", "links": COLLECTION_LINKS}},
)
def create_collection(
    body: CollectionIn, session: SessionDep, state: StateDep, response: Response
) -> CollectionOut:
    view = service.create(session, state, name=body.name, units=body.units, preset=body.preset)
    response.headers["Location"] = f"/collections/{view.row.name}"
    return collection_out(view)


@router.get(
    "",
    response_model=CollectionList,
    operation_id="list_collections",
    summary="List collections (those the request's key may read)",
)
def list_collections(session: ReadSessionDep, state: StateDep, grant: GrantDep) -> CollectionList:
    views = service.list_all(session, state)
    readable = [v for v in views if grant is None or grant.allows(v.row.id, Scope.read)]
    return CollectionList(items=[collection_out(v) for v in readable])


@router.get(
    "/{name}",
    response_model=CollectionOut,
    dependencies=READ_ACCESS,
    operation_id="get_collection",
    summary="One collection",
    responses=NOT_FOUND,
)
def get_collection(name: Name, session: ReadSessionDep, state: StateDep) -> CollectionOut:
    return collection_out(service.get(session, state, name))


@router.put(
    "/{name}/fusion",
    dependencies=ADMIN_ACCESS,
    response_model=CollectionOut,
    operation_id="pin_collection_fusion",
    summary="Pin the collection's fusion weights, or unpin them",
    description=(
        "Pinned weights rank and calibrate the collection's searches instead of the ones it "
        'learns from its labels (or the preset\'s); `{"weights": null}` unpins them. '
        "`GET /collections/{name}/calibration` shows the weights in use and where they came "
        "from.\n\n"
        '`curl -X PUT -H \'Content-Type: application/json\' -d \'{"weights": {"gdm": 0, '
        '"ddt": 0.25, "spectrum": 1}}\' http://127.0.0.1:8000/collections/casts/fusion`'
    ),
    responses=NOT_FOUND,
)
def pin_collection_fusion(
    name: Name, body: FusionPin, session: SessionDep, state: StateDep
) -> CollectionOut:
    weights = None if body.weights is None else {str(m): w for m, w in body.weights.items()}
    return collection_out(service.pin_fusion(session, state, name, weights))


@router.delete(
    "/{name}",
    dependencies=ADMIN_ACCESS,
    status_code=status.HTTP_204_NO_CONTENT,
    operation_id="delete_collection",
    summary="Delete a collection with all its meshes",
    responses=NOT_FOUND
    | {409: {"description": "The default collection stays (`default_collection`)"}},
)
def delete_collection(name: Name, session: SessionDep, state: StateDep) -> Response:
    service.delete(session, state, name)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


def include_scoped(app: FastAPI, routers: tuple[APIRouter, ...]) -> None:
    """Each router's routes again under ``/collections/{collection}/`` (the routes without
    it work on the default collection); :func:`document_scoped` names their operations."""
    for router in routers:
        app.include_router(
            router,
            prefix=SCOPED_PREFIX,
            dependencies=[Depends(collection_parameter)],
            responses=NO_COLLECTION,
        )


def openapi_with_scoped(app: FastAPI) -> dict[str, Any]:
    """FastAPI's schema of ``app``, with the operations under ``/collections/{collection}/``
    renamed ``collection_<operation id>`` (FastAPI gives a router's routes the same ids
    wherever it is included, and warns of it; renamed here) and their links pointing at
    the collection's own operations, given the same collection."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Duplicate Operation ID")
        openapi = FastAPI.openapi(app)
    scoped = [
        (path, operations)
        for path, operations in openapi.get("paths", {}).items()
        if path.startswith(SCOPED_PREFIX + "/")
    ]
    renamed = set()
    for _, operations in scoped:
        for operation in operations.values():
            operation["operationId"] = f"collection_{operation['operationId']}"
            renamed.add(operation["operationId"])
    for _, operations in scoped:
        for operation in operations.values():
            for response in operation.get("responses", {}).values():
                if "links" in response:
                    response["links"] = {
                        name: _scoped_link(link, renamed)
                        for name, link in response["links"].items()
                    }
    return openapi


def _scoped_link(link: dict[str, Any], scoped: set[str]) -> dict[str, Any]:
    target = f"collection_{link.get('operationId')}"
    if target not in scoped:  # e.g. a job, which is not a collection's resource
        return link
    parameters = {"collection": "$request.path.collection", **link.get("parameters", {})}
    return {**link, "operationId": target, "parameters": parameters}
