"""Domain errors and the one handler that turns them into ``{"error", "detail"}``.

Services raise these; they know nothing about HTTP beyond the status each
error carries. Mesh errors from the descriptor engine map by their ``code``.
"""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import BaseRoute, Match

from worker.engine.errors import (
    FileTooLargeError,
    MeshError,
    TooManyFacesError,
    UnsupportedFormatError,
)


class DomainError(Exception):
    """An error the client can act on: HTTP ``status``, machine ``code``, a sentence."""

    status = 400
    code = "bad_request"

    def __init__(self, detail: str, *, code: str | None = None, status: int | None = None):
        super().__init__(detail)
        self.detail = detail
        if code is not None:
            self.code = code
        if status is not None:
            self.status = status


class UnauthorizedError(DomainError):
    status = 401
    code = "unauthorized"


class ForbiddenError(DomainError):
    status = 403
    code = "forbidden"


class NotFoundError(DomainError):
    status = 404
    code = "not_found"


class PayloadTooLargeError(DomainError):
    status = 413
    code = "too_large"


class UnsupportedMediaTypeError(DomainError):
    status = 415
    code = "unsupported_format"


class InvalidInputError(DomainError):
    status = 422
    code = "invalid_input"


class ConflictError(DomainError):
    status = 409
    code = "conflict"


class UnavailableError(DomainError):
    status = 503
    code = "unavailable"


log = logging.getLogger("shapes")

#: Seconds a client is asked to wait (``Retry-After``) when a dependency is down.
RETRY_AFTER_SECONDS = 5

DATABASE_DOWN = "The database is unreachable at the moment; nothing was changed. Try again shortly."
QUEUE_DOWN = (
    "The descriptor queue is unreachable at the moment; nothing was lost. Try again shortly."
)


# By code, not class: a worker's refusal reaches the API as its code and sentence only.
_MESH_ERROR_STATUS = {
    UnsupportedFormatError.code: 415,
    TooManyFacesError.code: 413,
    FileTooLargeError.code: 413,  # e.g. a gzip bomb
}


def mesh_error_status(error: MeshError) -> int:
    """HTTP status of a descriptor-engine refusal."""
    return _MESH_ERROR_STATUS.get(error.code, 422)


def _body(code: str, detail: str) -> dict[str, str]:
    return {"error": code, "detail": detail}


_HTTP_CODES = {
    400: "bad_request",
    404: "not_found",
    405: "method_not_allowed",
    413: "too_large",
    415: "unsupported_format",
    422: "invalid_input",
}


#: What FastAPI's 400 says of a body it could not read.
FASTAPI_BODY_ERROR = "There was an error parsing the body"
INVALID_JSON = "The request body is not valid JSON (UTF-8 text holding one JSON object)."


def _validation_sentence(exc: RequestValidationError) -> str:
    parts = []
    for err in exc.errors()[:3]:
        where = ".".join(str(p) for p in err.get("loc", ()) if p not in ("body", "query", "path"))
        parts.append(f"{where}: {err.get('msg', 'invalid')}" if where else err.get("msg", ""))
    return "Invalid request: " + "; ".join(parts) + "."


_METHODS = ("DELETE", "GET", "HEAD", "OPTIONS", "PATCH", "POST", "PUT")


def allowed_methods(routes: list[BaseRoute], request: Request) -> list[str]:
    """Every method some route serves at the request's path, sorted.

    Starlette answers a 405 with the ``Allow`` of the first route whose path
    matched, but one path's methods are often split over several routes
    (``GET`` and ``POST /meshes``); each method is asked of every route instead.
    """
    return [
        method
        for method in _METHODS
        if any(
            route.matches({**request.scope, "method": method})[0] == Match.FULL for route in routes
        )
    ]


def _unavailable(code: str, detail: str) -> JSONResponse:
    return JSONResponse(
        _body(code, detail), status_code=503, headers={"Retry-After": str(RETRY_AFTER_SECONDS)}
    )


def install_error_handlers(
    app: FastAPI,
    *,
    database_errors: tuple[type[Exception], ...],
    queue_errors: tuple[type[Exception], ...],
) -> None:
    """Every error answers ``{"error", "detail"}``: domain and engine errors with their
    status; an unreachable database or queue (``database_errors``, ``queue_errors``)
    503 with ``Retry-After``; anything else 500, logged."""

    @app.exception_handler(DomainError)
    async def _domain(_: Request, exc: DomainError) -> JSONResponse:
        if exc.status == 503:
            return _unavailable(exc.code, exc.detail)
        headers = {"WWW-Authenticate": "X-API-Key"} if exc.status == 401 else None
        return JSONResponse(_body(exc.code, exc.detail), status_code=exc.status, headers=headers)

    for error in database_errors:
        app.add_exception_handler(error, _database_down)
    for error in queue_errors:
        app.add_exception_handler(error, _queue_down)

    @app.exception_handler(Exception)
    async def _internal(request: Request, exc: Exception) -> JSONResponse:
        # Starlette logs the traceback too, after this answer is sent.
        log.error("%s %s failed: %r", request.method, request.url.path, exc)
        return JSONResponse(
            _body(
                "internal_error",
                "The service failed on this request (the operator finds it in the log); "
                "try again, or report it.",
            ),
            status_code=500,
        )

    @app.exception_handler(MeshError)
    async def _mesh(_: Request, exc: MeshError) -> JSONResponse:
        return JSONResponse(_body(exc.code, exc.message), status_code=mesh_error_status(exc))

    @app.exception_handler(RequestValidationError)
    async def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        if any(err.get("type") == "json_invalid" for err in exc.errors()):
            return JSONResponse(_body("invalid_json", INVALID_JSON), status_code=422)
        return JSONResponse(_body("invalid_input", _validation_sentence(exc)), status_code=422)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        if exc.status_code == 400 and exc.detail == FASTAPI_BODY_ERROR:
            # A JSON body FastAPI could not even decode (bytes that are not UTF-8): the
            # same answer as one that is not JSON (json_invalid), as the schema says.
            return JSONResponse(_body("invalid_json", INVALID_JSON), status_code=422)
        code = _HTTP_CODES.get(exc.status_code, "error")
        detail = exc.detail if isinstance(exc.detail, str) else "The request failed."
        if exc.status_code == 404 and detail == "Not Found":
            detail = "There is nothing at this address."
        if not detail.endswith("."):
            detail += "."
        headers = dict(exc.headers or {})
        if exc.status_code == 405:
            headers["Allow"] = ", ".join(allowed_methods(app.router.routes, request))
        return JSONResponse(_body(code, detail), status_code=exc.status_code, headers=headers)


async def _database_down(request: Request, exc: Exception) -> JSONResponse:
    log.warning("%s %s: database unreachable: %r", request.method, request.url.path, exc)
    return _unavailable("database_unavailable", DATABASE_DOWN)


async def _queue_down(request: Request, exc: Exception) -> JSONResponse:
    log.warning("%s %s: queue unreachable: %r", request.method, request.url.path, exc)
    return _unavailable("queue_unavailable", QUEUE_DOWN)
