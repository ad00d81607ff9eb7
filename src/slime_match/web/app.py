"""The ``slime web`` application: the JSON API and the page (``static/``), over the folders it was given.

Every file the API reads is named by a served folder and a path inside it (:mod:`.folders`); uploads go to a
temporary folder of the server's own; matches run in a worker process (:mod:`.jobs`). Errors are answered as
``{"error": message}`` with a 4xx status (5xx for a fault of the server), and none of them stops the server.
POST requests must carry the header ``X-Slime-Web: 1``: a web page of another site cannot send it without the
browser asking the server first (which it refuses), so such a page cannot make the server match or write.
"""

from __future__ import annotations

import io
import json
import logging
import os
import shutil
import tempfile
import threading
import uuid
from collections import OrderedDict
from contextlib import asynccontextmanager
from importlib import resources
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from fastapi import FastAPI, File, HTTPException, Query, Request, UploadFile
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import ClientDisconnect

from .. import __version__
from ..errors import SlimeMatchError
from ..io import IMAGE_EXTS, load_image
from . import annotate, annotation_models
from .folders import FolderError, Root, Roots, unique_names
from .jobs import JobRunner
from .payloads import matches_payload, stages_payload

logger = logging.getLogger("slime_match")

MAX_UPLOAD_MB = 25.0
MAX_UPLOADS = 200  # uploaded images kept; the oldest go first
MAX_IMAGE_PIXELS = 80_000_000  # larger images are refused before decoding (a decompression bomb)
LOOPBACK_HOSTS = ["127.0.0.1", "localhost", "::1", "[::1]"]
CSRF_HEADER = "x-slime-web"
DOWNLOADS = {"matches.npz": "application/octet-stream", "summary.json": "application/json",
             "stages.npz": "application/octet-stream"}
# the options the page may set (flat names of make_config); paths such as weights_dir stay the server's
MATCH_OPTIONS = ("base", "descriptor", "shape", "orientation", "upright", "ransac", "threshold", "seed", "device",
                 "min_side", "max_side", "scales", "detection", "tile_test", "magnification", "workers")


class ApiError(Exception):
    """A refused request: ``message`` for the user, ``status`` the HTTP status."""

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


def create_app(images: list[str | os.PathLike] = (), runs: list[str | os.PathLike] = (),
               annotations: str | os.PathLike | None = None, max_upload_mb: float = MAX_UPLOAD_MB,
               allowed_hosts: list[str] | None = None) -> FastAPI:
    """The application serving ``images`` folders, ``slime pairs`` run folders ``runs`` and, when given, an
    ``annotations`` folder where the annotation tool saves pairs (it is created when missing).

    Args:
        max_upload_mb: the largest image upload accepted.
        allowed_hosts: the Host headers answered (None: any); ``slime web`` gives the loopback names when it
            listens on a loopback address, so that another site's page cannot reach it by DNS rebinding.

    Raises:
        SlimeMatchError: a folder that does not exist, or a run folder without ``pairs.json``.
    """
    from .. import config  # noqa: F401  (torch and the pipelines load now, not on the page's first request)

    image_dirs = [Path(p) for p in images]
    run_dirs = [Path(p) for p in runs]
    if not max_upload_mb > 0:
        raise SlimeMatchError(f"the upload limit must be > 0 MB, got {max_upload_mb}")
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
    state = _State(Roots(roots), dict(zip(unique_names(run_dirs, "run"), run_dirs)), annotations_dir,
                   int(max_upload_mb * 2**20), work)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        yield
        state.close()

    app = FastAPI(title="slime web", version=__version__, lifespan=lifespan, docs_url=None, redoc_url=None,
                  openapi_url=None)
    app.state.slime = state
    if allowed_hosts is not None:
        app.add_middleware(TrustedHostMiddleware, allowed_hosts=allowed_hosts)
    _add_error_handlers(app)
    _add_routes(app, state)

    @app.middleware("http")
    async def upload_size(request: Request, call_next):  # before the body is read (and spooled to disk)
        if request.url.path == "/api/upload":
            try:
                length = int(request.headers.get("content-length", "0"))
            except ValueError:
                length = 0
            if length > state.max_upload + 2**20:  # the form's own fields take a little more than the file
                return JSONResponse({"error": f"the upload is larger than the limit of "
                                              f"{state.max_upload / 2**20:g} MiB"}, status_code=413)
        return await call_next(request)

    return app


class _State:
    """What the routes share: folders, runs, jobs, the upload and image caches."""

    def __init__(self, roots: Roots, runs: dict[str, Path], annotations: Path | None, max_upload: int,
                 work: Path) -> None:
        self.roots, self.runs, self.annotations, self.max_upload, self.work = roots, runs, annotations, max_upload, work
        self.jobs = JobRunner(work / "jobs")
        self._encoded: OrderedDict[tuple, tuple[bytes, str]] = OrderedDict()
        self._lock = threading.Lock()

    def close(self) -> None:
        self.jobs.close()
        shutil.rmtree(self.work, ignore_errors=True)

    def encoded(self, path: Path) -> tuple[bytes, str]:
        """The image as the matcher sees it (upright by its EXIF tag, RGB), encoded for the browser: PNG, or
        JPEG above 2 MP; the last few are kept."""
        stat = path.stat()
        key = (str(path), stat.st_mtime_ns, stat.st_size)
        with self._lock:
            if key in self._encoded:
                self._encoded.move_to_end(key)
                return self._encoded[key]
        image = load_image(path)
        pixels = np.clip(image * 255.0 + 0.5, 0, 255).astype(np.uint8)[:, :, ::-1]
        big = pixels.shape[0] * pixels.shape[1] > 2_000_000
        ok, data = cv2.imencode(".jpg" if big else ".png", pixels, [cv2.IMWRITE_JPEG_QUALITY, 92] if big else [])
        if not ok:
            raise ApiError(f"cannot encode {path.name} for the browser", 500)
        value = (data.tobytes(), "image/jpeg" if big else "image/png")
        with self._lock:
            self._encoded[key] = value
            while len(self._encoded) > 8:
                self._encoded.popitem(last=False)
        return value

    def run(self, name: str) -> Path:
        if name not in self.runs:
            raise ApiError(f"unknown run {name!r}: the server serves {', '.join(self.runs) or 'no run'} "
                           "(start it with --run RUNDIR)", 404)
        return self.runs[name]

    def run_index(self, name: str) -> list[dict[str, Any]]:
        folder = self.run(name)
        try:
            records = json.loads((folder / "pairs.json").read_text()).get("pairs", [])
        except (OSError, ValueError, AttributeError) as error:
            raise ApiError(f"cannot read the run's pairs.json: {error}", 500) from None
        return [r for r in records if isinstance(r, dict)]

    def run_pair(self, name: str, index: int) -> tuple[dict[str, Any], Path]:
        records = self.run_index(name)
        if not 0 <= index < len(records):
            raise ApiError(f"run {name!r} has {len(records)} pairs: no pair {index}", 404)
        record, base = records[index], self.run(name).resolve()
        folder = (base / str(record.get("folder", ""))).resolve()
        if not folder.is_relative_to(base) or folder == base:
            raise ApiError(f"pair {index} of run {name!r} names a folder outside the run", 403)
        return record, folder

    def job_folder(self, job_id: str, done: bool = True) -> Path:
        job = self.jobs.get(job_id)
        if job is None:
            raise ApiError(f"unknown job {job_id!r} (the server keeps the last jobs only)", 404)
        if done and job.status != "done":
            raise ApiError(f"job {job_id} is {job.status}" + (f": {job.error}" if job.error else ""), 409)
        return job.folder


def _add_error_handlers(app: FastAPI) -> None:
    def answer(status: int, message: str) -> JSONResponse:
        return JSONResponse({"error": message}, status_code=status)

    @app.exception_handler(ApiError)
    async def api_error(request: Request, error: ApiError):
        return answer(error.status, str(error))

    @app.exception_handler(FolderError)
    async def folder_error(request: Request, error: FolderError):
        return answer(error.status, str(error))

    @app.exception_handler(SlimeMatchError)
    async def slime_error(request: Request, error: SlimeMatchError):
        return answer(400, str(error))

    @app.exception_handler(HTTPException)
    async def http_error(request: Request, error: HTTPException):
        return answer(error.status_code, str(error.detail))

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
        return answer(500, f"the server failed on this request ({type(error).__name__}: {error}); it keeps running")

    @app.middleware("http")
    async def post_header(request: Request, call_next):
        if request.method not in ("GET", "HEAD", "OPTIONS") and request.headers.get(CSRF_HEADER) != "1":
            return answer(403, f"requests that change something need the header '{CSRF_HEADER}: 1' (the page "
                               "sends it; other sites' pages cannot)")
        return await call_next(request)


def _body_object(body: Any, *keys: str) -> dict[str, Any]:
    if not isinstance(body, dict):
        raise ApiError("the request body must be a JSON object")
    missing = [key for key in keys if key not in body]
    if missing:
        raise ApiError(f"missing {', '.join(missing)} in the request")
    return body


async def _json(request: Request) -> Any:
    try:
        return await request.json()
    except (ValueError, UnicodeDecodeError):
        raise ApiError("the request body is not JSON") from None
    except ClientDisconnect:  # the page went away mid-request (a reload): nobody to answer, nothing to log
        raise ApiError("the request was cut off", 400) from None


def _add_routes(app: FastAPI, state: _State) -> None:
    static = resources.files("slime_match.web") / "static"
    app.mount("/static", StaticFiles(directory=str(static)), name="static")

    @app.get("/", response_class=HTMLResponse)
    def index():
        return HTMLResponse((static / "index.html").read_text(encoding="utf-8"),
                            headers={"Cache-Control": "no-store"})

    @app.get("/api/info")
    def info():
        from ..choices import DESCRIPTOR_CHOICES, DEVICES, RANSAC_CHOICES
        from ..config import PRESETS

        return {"version": __version__,
                "folders": [{"name": r.name, "kind": r.kind} for r in state.roots],
                "runs": list(state.runs),
                "presets": list(PRESETS),
                "choices": {"ransac": list(RANSAC_CHOICES), "descriptor": list(DESCRIPTOR_CHOICES),
                            "device": list(DEVICES)},
                "max_upload_mb": round(state.max_upload / 2**20, 2),
                "annotations": state.annotations is not None}

    @app.get("/api/images")
    def list_images(root: str = Query(...)):
        folder = state.roots.get(root)
        names, truncated = folder.images()
        return {"root": root, "images": names, "truncated": truncated}

    @app.get("/api/image")
    def image(root: str = Query(...), path: str = Query(...)):
        file = state.roots.get(root).resolve(path)
        if file.suffix.lower() not in IMAGE_EXTS:
            raise ApiError(f"{path!r} is not an image file ({', '.join(IMAGE_EXTS)})")
        data, media = state.encoded(file)
        return Response(data, media_type=media, headers={"Cache-Control": "private, max-age=60"})

    @app.post("/api/upload")
    async def upload(file: UploadFile = File(...)):  # noqa: B008  (FastAPI's way to declare a form file)
        return await _store_upload(state, file)

    @app.post("/api/match")
    async def match(request: Request):
        body = _body_object(await _json(request), "image0", "image1")
        paths = [state.roots.file(body["image0"]), state.roots.file(body["image1"])]
        preset = body.get("preset", "slime")
        config = _match_config(preset, body.get("options") or {}, body.get("settings") or {},
                               bool(body.get("save_stages", True)))
        job = state.jobs.submit(config.to_dict(), *paths, images=[body["image0"], body["image1"]], preset=preset)
        return job.state()

    @app.get("/api/jobs/{job_id}")
    def job_state(job_id: str):
        state.job_folder(job_id, done=False)
        return state.jobs.get(job_id).state()

    @app.post("/api/jobs/{job_id}/cancel")
    def cancel(job_id: str):
        state.job_folder(job_id, done=False)
        return state.jobs.cancel(job_id).state()

    @app.get("/api/jobs/{job_id}/matches")
    def job_matches(job_id: str):
        return matches_payload(state.job_folder(job_id))

    @app.get("/api/jobs/{job_id}/stages")
    def job_stages(job_id: str):
        return _stages(state.job_folder(job_id))

    @app.get("/api/jobs/{job_id}/files/{name}")
    def job_file(job_id: str, name: str):
        return _download(state.job_folder(job_id), name)

    @app.get("/api/runs")
    def runs():
        out = []
        for name in state.runs:
            records = state.run_index(name)
            status = {s: sum(r.get("status") == s for r in records) for s in ("done", "skipped", "failed")}
            out.append({"name": name, "pairs": len(records), **status})
        return {"runs": out}

    @app.get("/api/runs/{name}")
    def run(name: str):
        records = state.run_index(name)
        config = {}
        run_file = state.run(name) / "run.json"
        if run_file.is_file():
            try:
                config = json.loads(run_file.read_text()).get("config", {})
            except (OSError, ValueError, AttributeError):
                config = {}
        pairs = []
        for index, record in enumerate(records):
            pairs.append({"index": index, **{k: record.get(k) for k in ("image0", "image1", "status", "matches",
                                                                        "seconds", "error", "folder")}})
        return {"name": name, "pairs": pairs, "method": config.get("method"), "config": config}

    @app.get("/api/runs/{name}/pairs/{index}")
    def run_pair(name: str, index: int):
        record, folder = state.run_pair(name, index)
        if record.get("status") == "failed":
            raise ApiError(f"pair {index} failed in the run: {record.get('error', 'no error recorded')}", 409)
        if not (folder / "matches.npz").is_file():
            raise ApiError(f"pair {index} of run {name!r} has no matches.npz (status {record.get('status')})", 404)
        payload = matches_payload(folder)
        images = [state.roots.find(str(record.get(key, ""))) for key in ("image0", "image1")]
        payload["images"] = images
        payload["names"] = [record.get("image0"), record.get("image1")]
        if None in images:
            payload["images_missing"] = ("the run's images are not under the served image folders: start slime "
                                         "web with --images set to the folder the run was matched from")
        return payload

    @app.get("/api/runs/{name}/pairs/{index}/stages")
    def run_pair_stages(name: str, index: int):
        return _stages(state.run_pair(name, index)[1])

    @app.get("/api/runs/{name}/pairs/{index}/files/{file}")
    def run_pair_file(name: str, index: int, file: str):
        return _download(state.run_pair(name, index)[1], file)

    @app.post("/api/annotate/fit")
    async def annotate_fit(request: Request):
        body = _body_object(await _json(request), "pairs")
        return annotation_models.fit(annotate.read_pairs(body["pairs"]))

    @app.post("/api/annotate/export")
    async def annotate_export(request: Request):
        body = _body_object(await _json(request), "pairs", "model")
        name, text = annotate.export_text(annotate.read_pairs(body["pairs"]), body["model"])
        return Response(text, media_type="text/plain",
                        headers={"Content-Disposition": f'attachment; filename="{name}"'})

    @app.post("/api/annotate/save")
    async def annotate_save(request: Request):
        if state.annotations is None:
            raise ApiError("saving needs an annotation folder: start slime web with --annotations DIR (or "
                           "download the file instead)", 409)
        body = _body_object(await _json(request), "name", "model", "image0", "image1", "pairs")
        image0, image1 = state.roots.file(body["image0"]), state.roots.file(body["image1"])
        written = annotate.save(state.annotations, body["name"], body["model"], image0, image1,
                                annotate.read_pairs(body["pairs"]), overwrite=bool(body.get("overwrite")))
        return {**written, "folder": "annotations"}

    @app.get("/api/annotate/saved")
    def annotate_saved():
        if state.annotations is None:
            return {"annotations": [], "folder": None}
        return {"annotations": annotate.saved(state.annotations), "folder": "annotations"}

    @app.get("/api/annotate/open")
    def annotate_open(root: str = Query(...), path: str = Query(...)):
        opened = annotate.open_file(state.roots.get(root).resolve(path))
        refs = [state.roots.reference(opened[key]) for key in ("image0", "image1")]
        return {**opened, "image0": refs[0], "image1": refs[1]}


def _stages(folder: Path) -> dict[str, Any]:
    if not (folder / "stages.npz").is_file():
        raise ApiError("this match kept no stages: run Slime with 'keep stages' (slime match --save-stages)", 404)
    return stages_payload(folder)


def _download(folder: Path, name: str) -> FileResponse:
    if name not in DOWNLOADS:
        raise ApiError(f"no file {name!r}: choose {', '.join(DOWNLOADS)}", 404)
    if not (folder / name).is_file():
        raise ApiError(f"this match has no {name}", 404)
    return FileResponse(folder / name, media_type=DOWNLOADS[name], filename=name)


def _match_config(preset: Any, options: Any, settings: Any, save_stages: bool):
    """The MatchConfig of a preset and the page's options (ConfigError, answered 400, for bad ones)."""
    from ..config import make_config

    if not isinstance(preset, str):
        raise ApiError("preset must be a preset name")
    if not isinstance(options, dict) or not isinstance(settings, dict):
        raise ApiError("options and settings must be JSON objects")
    unknown = sorted(set(options) - set(MATCH_OPTIONS))
    if unknown:
        raise ApiError(f"unknown or refused option(s) {', '.join(unknown)}: the page may set "
                       f"{', '.join(MATCH_OPTIONS)} and settings by dotted path")
    refused = [key for key in settings if not isinstance(key, str) or "weights_dir" in key]
    if refused:
        raise ApiError(f"setting(s) {', '.join(map(str, refused))} may not be set from the page")
    given = {key: value for key, value in {**options, **settings}.items() if value not in (None, "")}
    given = {key: (value if isinstance(value, (bool, int, float)) else str(value)) for key, value in given.items()}
    config = make_config(preset, **given)
    if save_stages and config.method == "slime":
        config.slime.keep_stages = True
    return config


async def _store_upload(state: _State, file: UploadFile) -> dict[str, Any]:
    """Keep an uploaded image (size-limited, decoded to check it) in the uploads folder."""
    name = Path(file.filename or "image").name
    suffix = Path(name).suffix.lower()
    if suffix not in IMAGE_EXTS:
        raise ApiError(f"{name!r} is not an image file name: expected one of {', '.join(IMAGE_EXTS)}", 415)
    chunks, size = [], 0
    while chunk := await file.read(1 << 20):
        size += len(chunk)
        if size > state.max_upload:
            raise ApiError(f"{name!r} is larger than the upload limit of {state.max_upload / 2**20:g} MiB", 413)
        chunks.append(chunk)
    data = b"".join(chunks)
    if not data:
        raise ApiError(f"{name!r} is empty", 400)
    _check_image_bytes(name, data)
    folder = state.roots.get("uploads").path
    stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in Path(name).stem)[:60] or "image"
    target = folder / f"{uuid.uuid4().hex[:8]}-{stem}{suffix}"
    target.write_bytes(data)
    try:
        image = load_image(target)  # what the matcher will read (EXIF orientation, 16-bit...)
    except SlimeMatchError as error:
        target.unlink(missing_ok=True)
        raise ApiError(f"{name!r} is not a usable image: {error}".replace(str(target), name), 415) from None
    kept = sorted(folder.iterdir(), key=lambda p: p.stat().st_mtime_ns)
    for old in kept[:max(0, len(kept) - MAX_UPLOADS)]:
        old.unlink(missing_ok=True)
    return {"root": "uploads", "path": target.name, "name": name, "width": int(image.shape[1]),
            "height": int(image.shape[0])}


def _check_image_bytes(name: str, data: bytes) -> None:
    """Refuse bytes that no image decoder reads, and images too large to decode safely (their size is read
    from the header, before decoding)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as opened:
            width, height = opened.size
    except Image.DecompressionBombError:
        raise ApiError(f"{name!r} is too large an image to decode safely", 413) from None
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError):
        width = height = None  # a format Pillow does not read: OpenCV decides below
    if width is None:
        if cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) is None:
            raise ApiError(f"{name!r} is not an image (no decoder reads it)", 415)
        return
    if width * height > MAX_IMAGE_PIXELS:
        raise ApiError(f"{name!r} has {width}x{height} px, over the limit of {MAX_IMAGE_PIXELS // 10**6} MP", 413)
