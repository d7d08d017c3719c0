"""Stable JSON error details: {"detail": {"code": ..., "message": ...}} for every 4xx."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from spinefarm.protocol.errors import SpinefarmError, StorageError


class NotFound(SpinefarmError):
    code = "not_found"


class SimulatorUnavailable(SpinefarmError):
    """This server cannot re-simulate trials (an API-only install)."""

    code = "simulator_unavailable"


class RenderFailed(SpinefarmError):
    code = "render_failed"


class InvalidQuery(SpinefarmError):
    """A query value of the right type that names nothing in the run (a parameter, a size out of range)."""

    code = "invalid_query"


def known_query(request: Request) -> None:
    """Refuse a query parameter the route does not take: a misspelt `?n=5` would otherwise give the default
    answer without a word."""
    route = request.scope.get("route")
    dependant = getattr(route, "dependant", None)
    if dependant is None:
        return
    names: set[str] = set()
    todo = [dependant]
    while todo:  # the route's own query parameters and its dependencies'
        d = todo.pop()
        names.update(p.alias for p in d.query_params)
        todo.extend(d.dependencies)
    unknown = sorted(set(request.query_params) - names)
    if unknown:
        raise InvalidQuery(f"unknown query parameter for {request.url.path}", received=unknown,
                           expected=sorted(names) if names else "no query parameters")


def detail(code: str, message: str, **extra: object) -> dict[str, object]:
    return {"detail": {"code": code, "message": message, **extra}}


def _own_error(status: int) -> Callable[..., Awaitable[JSONResponse]]:
    """A handler answering one of spinefarm's errors with `status` and the error's own detail."""

    async def handler(_: Request, exc: SpinefarmError) -> JSONResponse:
        return JSONResponse(status_code=status, content={"detail": exc.to_detail()})

    return handler


def install(app: FastAPI) -> None:
    @app.exception_handler(RequestValidationError)
    async def _invalid(_: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [{"where": ".".join(str(x) for x in e.get("loc", ())), "problem": e.get("msg", ""),
                   "received": str(e.get("input"))[:80]} for e in exc.errors()]
        first = errors[0] if errors else {"where": "?", "problem": "invalid", "received": ""}
        message = f"{first['where']}: {first['problem']}; received {first['received']!r}"
        return JSONResponse(status_code=422, content=detail("invalid_query", message, errors=errors))

    # A StorageError: the file exists but cannot be read now (e.g. being replaced on resume): retry later.
    for kind, status in ((NotFound, 404), (InvalidQuery, 422), (SimulatorUnavailable, 503), (RenderFailed, 500),
                         (StorageError, 409)):
        app.add_exception_handler(kind, _own_error(status))

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        code = "not_found" if exc.status_code == 404 else f"http_{exc.status_code}"
        message = str(exc.detail)
        if exc.status_code == 404 and request.scope.get("route") is None:  # no route matched the path
            message = (f"no such endpoint; received {request.method} {request.url.path!r}; expected one of "
                       f"{', '.join(_paths(request.app))} (described at /docs)")
        # headers carry e.g. a 405's Allow
        return JSONResponse(status_code=exc.status_code, content=detail(code, message),
                            headers=getattr(exc, "headers", None))


def _paths(app: FastAPI) -> list[str]:
    """The JSON API's paths, as /docs lists them (FastAPI builds the schema once and keeps it)."""
    return list(app.openapi()["paths"])
