"""The ``slime web`` application: the JSON API and the page (``static/``), over the folders it was given.

Every file the API reads is named by a served folder and a path inside it (:mod:`.folders`); uploads go to a
temporary folder of the server's own; matches run in a worker process (:mod:`.jobs`). Every error is answered
as ``{"error": message}`` (:mod:`.api_errors`), and none of them stops the server. POST requests must carry
the header ``X-Slime-Web: 1``: a web page of another site cannot send it without the browser asking the
server first (which it refuses), so such a page cannot make the server match or write. The routes are in
``routes_images``, ``routes_jobs``, ``routes_runs``, ``routes_annotate`` and ``routes_geometry``.
"""

from __future__ import annotations

import os
import tempfile
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI, Request

from .. import __version__
from ..errors import SlimeMatchError
from .api_errors import add_error_handlers, answer
from .folders import Root, Roots, unique_names
from .image_checks import MAX_IMAGE_PIXELS
from .routes_annotate import add_annotation_routes
from .routes_geometry import add_geometry_routes
from .routes_images import add_image_routes
from .routes_jobs import add_job_routes
from .routes_runs import add_run_routes
from .state import WebState

MAX_UPLOAD_MB = 25.0
LOOPBACK_HOSTS = ["127.0.0.1", "localhost", "::1", "[::1]"]
CSRF_HEADER = "x-slime-web"


def create_app(images: list[str | os.PathLike] = (), runs: list[str | os.PathLike] = (),
               annotations: str | os.PathLike | None = None, max_upload_mb: float = MAX_UPLOAD_MB,
               allowed_hosts: list[str] | None = None, max_megapixels: float = MAX_IMAGE_PIXELS / 1e6) -> FastAPI:
    """The application serving ``images`` folders, ``slime pairs`` run folders ``runs`` and, when given, an
    ``annotations`` folder where the annotation tool saves pairs (it is created when missing).

    Args:
        max_upload_mb: the largest image upload accepted.
        allowed_hosts: the Host headers answered (None: any); ``slime web`` gives the loopback names when it
            listens on a loopback address, so that another site's page cannot reach it by DNS rebinding.
        max_megapixels: the largest image (in pixels, read from its header before decoding) the server takes.

    Raises:
        SlimeMatchError: a folder that does not exist, or a run folder without ``pairs.json``.
    """
    from .. import config  # noqa: F401  (torch and the pipelines load now, not on the page's first request)

    image_dirs = [Path(p) for p in images]
    run_dirs = [Path(p) for p in runs]
    if not max_upload_mb > 0:
        raise SlimeMatchError(f"the upload limit must be > 0 MB, got {max_upload_mb}")
    if not max_megapixels > 0:
        raise SlimeMatchError(f"the image limit must be > 0 MP, got {max_megapixels}")
    for path in image_dirs:
        if not path.is_dir():
            raise SlimeMatchError(f"image folder {path} does not exist")
    for path in run_dirs:
        if not (path / "pairs.json").is_file():
            raise SlimeMatchError(f"{path} is not a `slime pairs` run folder (no pairs.json in it)")
    annotations_dir = None if annotations is None else Path(annotations)
    if annotations_dir is not None:
        if annotations_dir.exists() and not annotations_dir.is_dir():
            raise SlimeMatchError(f"annotation folder {annotations_dir} is a file")
        annotations_dir.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="slime-web-"))  # uploads and jobs, removed when the server stops
    uploads = work / "uploads"
    uploads.mkdir()
    roots = [Root(name, path, "images") for name, path in zip(unique_names(image_dirs, "images"), image_dirs)]
    roots.append(Root("uploads", uploads, "uploads"))
    if annotations_dir is not None:
        roots.append(Root("annotations", annotations_dir, "annotations"))
    state = WebState(Roots(roots), dict(zip(unique_names(run_dirs, "run"), run_dirs)), annotations_dir,
                     int(max_upload_mb * 2**20), int(max_megapixels * 1e6), work)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        yield
        state.close()

    app = FastAPI(title="slime web", version=__version__, lifespan=lifespan, docs_url=None, redoc_url=None,
                  openapi_url=None)
    app.state.slime = state
    add_error_handlers(app, state.redact)
    add_image_routes(app, state)
    add_job_routes(app, state)
    add_run_routes(app, state)
    add_annotation_routes(app, state)
    add_geometry_routes(app, state)
    _add_request_checks(app, state, allowed_hosts)
    return app


def _add_request_checks(app: FastAPI, state: WebState, allowed_hosts: list[str] | None) -> None:
    """What every request passes before its route: its Host (against DNS rebinding), the page's header on
    requests that change something, an upload's announced size (before its body is read and spooled)."""

    @app.middleware("http")
    async def checks(request: Request, call_next):
        if allowed_hosts is not None:
            host = request.headers.get("host", "")
            name = host.split("]")[0] + "]" if host.startswith("[") else host.rsplit(":", 1)[0]
            if name not in allowed_hosts:
                return answer(400, f"this server answers only requests to {', '.join(allowed_hosts)}")
        if request.method not in ("GET", "HEAD", "OPTIONS") and request.headers.get(CSRF_HEADER) != "1":
            return answer(403, f"requests that change something need the header '{CSRF_HEADER}: 1' (the page "
                               "sends it; other sites' pages cannot)")
        if request.url.path == "/api/upload":
            try:
                length = int(request.headers.get("content-length", "0"))
            except ValueError:
                length = 0
            if length > state.max_upload + 2**20:  # the form's own fields take a little more than the file
                return answer(413, f"the upload is larger than the limit of {state.max_upload / 2**20:g} MiB")
        return await call_next(request)
