"""The one shape of every error ``slime web`` answers, ``{"error": message}`` with a 4xx status (5xx for a
fault of the server), whatever raised it: a refused request, a path outside the folders, a bad option, an
unknown route, a request the framework could not read, an unexpected fault (logged, never stopping the
server). Messages name files by their served folder and relative path, never by the server's paths."""

from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException
from starlette.requests import ClientDisconnect

from ..errors import SlimeMatchError
from .folders import FolderError

logger = logging.getLogger("slime_match")


class ApiError(Exception):
    """A refused request: ``message`` for the user, ``status`` the HTTP status."""

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


def answer(status: int, message: str) -> JSONResponse:
    """The error response: ``{"error": message}`` with ``status``."""
    return JSONResponse({"error": message}, status_code=status)


def add_error_handlers(app: FastAPI, redact) -> None:
    """Answer every error as :func:`answer`; ``redact(text)`` takes the server's paths out of a message."""

    @app.exception_handler(ApiError)
    async def api_error(request: Request, error: ApiError):
        return answer(error.status, redact(str(error)))

    @app.exception_handler(FolderError)
    async def folder_error(request: Request, error: FolderError):
        return answer(error.status, redact(str(error)))

    @app.exception_handler(SlimeMatchError)
    async def slime_error(request: Request, error: SlimeMatchError):
        return answer(400, redact(str(error)))

    @app.exception_handler(HTTPException)  # the framework's own: unknown routes, static files, methods
    async def http_error(request: Request, error: HTTPException):
        message = str(error.detail)
        if error.status_code == 404 and message == "Not Found":
            message = f"no such page or API route: {request.url.path}"
        return answer(error.status_code, message)

    @app.exception_handler(RequestValidationError)
    async def validation_error(request: Request, error: RequestValidationError):
        parts = []
        for item in error.errors():
            where = ".".join(str(p) for p in item.get("loc", ()) if p not in ("body", "query"))
            parts.append(f"{where}: {item.get('msg')}" if where else str(item.get("msg")))
        return answer(422, "bad request: " + "; ".join(parts))

    @app.exception_handler(Exception)
    async def server_fault(request: Request, error: Exception):
        logger.exception("slime web: %s %s failed", request.method, request.url.path)
        return answer(500, redact(f"the server failed on this request ({type(error).__name__}: {error}); it keeps "
                                  "running"))


def body_object(body: Any, *keys: str) -> dict[str, Any]:
    """``body`` when it is a JSON object holding ``keys``, else ApiError."""
    if not isinstance(body, dict):
        raise ApiError("the request body must be a JSON object")
    missing = [key for key in keys if key not in body]
    if missing:
        raise ApiError(f"missing {', '.join(missing)} in the request")
    return body


async def json_body(request: Request) -> Any:
    """The request's JSON body (ApiError when it is not JSON or was cut off)."""
    try:
        return await request.json()
    except (ValueError, UnicodeDecodeError):
        raise ApiError("the request body is not JSON") from None
    except ClientDisconnect:  # the page went away mid-request (a reload): nobody to answer, nothing to log
        raise ApiError("the request was cut off", 400) from None
