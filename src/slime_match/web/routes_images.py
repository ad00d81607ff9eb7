"""The routes of ``slime web`` for what it serves and takes in: the page, ``/api/info``, the image folders,
one image as the matcher sees it, and uploads (size-limited, their pixel count read from the header before
anything decodes them)."""

from __future__ import annotations

import uuid
from importlib import resources
from pathlib import Path
from typing import Any

from fastapi import FastAPI, File, Query, UploadFile
from fastapi.responses import HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

from .. import __version__
from ..errors import SlimeMatchError
from ..io import IMAGE_EXTS, load_image
from .api_errors import ApiError
from .image_checks import DECODING, image_size
from .match_options import match_choices
from .state import WebState

MAX_UPLOADS = 200  # uploaded images kept; the oldest go first


def add_image_routes(app: FastAPI, state: WebState) -> None:
    static = resources.files("slime_match.web") / "static"
    app.mount("/static", StaticFiles(directory=str(static)), name="static")

    @app.get("/", response_class=HTMLResponse)
    def index():
        return HTMLResponse((static / "index.html").read_text(encoding="utf-8"),
                            headers={"Cache-Control": "no-store"})

    @app.get("/api/info")
    def info():
        from ..choices import METHOD_CHOICES

        return {"version": __version__,
                "folders": [{"name": r.name, "kind": r.kind} for r in state.roots],
                "runs": list(state.runs),
                "presets": list(METHOD_CHOICES),  # "auto" first: the default
                **match_choices(),
                "max_upload_mb": round(state.max_upload / 2**20, 2),
                "max_megapixels": state.max_pixels / 1e6,
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
        data, media = state.encoded(file, f"{root}/{path}")
        return Response(data, media_type=media, headers={"Cache-Control": "private, max-age=60"})

    @app.post("/api/upload")
    async def upload(file: UploadFile = File(...)):  # noqa: B008  (FastAPI's way to declare a form file)
        return await _store_upload(state, file)


async def _store_upload(state: WebState, file: UploadFile) -> dict[str, Any]:
    """Keep an uploaded image in the uploads folder: size-limited, its pixel count read from its header, then
    decoded as the matcher decodes it (one decoding at a time) before it is kept."""
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
    image_size(data, name, state.max_pixels)
    folder = state.roots.get("uploads").path
    stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in Path(name).stem)[:60] or "image"
    target = folder / f"{uuid.uuid4().hex[:8]}-{stem}{suffix}"
    target.write_bytes(data)
    try:
        with DECODING:
            height, width = load_image(target).shape[:2]  # as the matcher reads it (EXIF orientation, 16-bit...)
    except SlimeMatchError as error:
        target.unlink(missing_ok=True)
        raise ApiError(f"{name!r} is not a usable image: {error}".replace(str(target), name), 415) from None
    kept = sorted(folder.iterdir(), key=lambda p: p.stat().st_mtime_ns)
    for old in kept[:max(0, len(kept) - MAX_UPLOADS)]:
        old.unlink(missing_ok=True)
    return {"root": "uploads", "path": target.name, "name": name, "width": width, "height": height}
