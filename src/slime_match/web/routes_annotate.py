"""The routes of ``slime web``'s annotation tool: fit the models of the clicked pairs, export the file the
bench reads, save a pair (with copies of its images) into the annotation folder, list and open saved pairs
and the bench's ground-truth files."""

from __future__ import annotations

from fastapi import FastAPI, Query, Request
from fastapi.responses import Response

from . import annotate, annotation_models
from .api_errors import ApiError, body_object, json_body
from .state import WebState


def add_annotation_routes(app: FastAPI, state: WebState) -> None:
    @app.post("/api/annotate/fit")
    async def annotate_fit(request: Request):
        body = body_object(await json_body(request), "pairs")
        return annotation_models.fit(annotate.read_pairs(body["pairs"]))

    @app.post("/api/annotate/export")
    async def annotate_export(request: Request):
        body = body_object(await json_body(request), "pairs", "model")
        name, text = annotate.export_text(annotate.read_pairs(body["pairs"]), body["model"])
        return Response(text, media_type="text/plain",
                        headers={"Content-Disposition": f'attachment; filename="{name}"'})

    @app.post("/api/annotate/save")
    async def annotate_save(request: Request):
        if state.annotations is None:
            raise ApiError("saving needs an annotation folder: start slime web with --annotations DIR (or "
                           "download the file instead)", 409)
        body = body_object(await json_body(request), "name", "model", "image0", "image1", "pairs")
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
