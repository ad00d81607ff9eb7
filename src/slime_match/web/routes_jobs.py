"""The routes of ``slime web`` for matches: start one (a job in the worker process), list the jobs (a page
reloaded finds its running job again), follow, cancel, and read a job's matches, stage layers and files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import FileResponse

from .api_errors import ApiError, body_object, json_body
from .match_options import match_config
from .payloads import matches_payload, stages_payload
from .state import WebState

DOWNLOADS = {"matches.npz": "application/octet-stream", "summary.json": "application/json",
             "stages.npz": "application/octet-stream"}


def add_job_routes(app: FastAPI, state: WebState) -> None:
    def job_state(job) -> dict[str, Any]:
        answer = job.state()
        if answer["error"]:
            answer["error"] = state.redact(answer["error"])
        answer["notices"] = [state.redact(text) for text in answer["notices"]]
        return answer

    @app.post("/api/match")
    async def match(request: Request):
        body = body_object(await json_body(request), "image0", "image1")
        paths = [state.checked_image(body["image0"]), state.checked_image(body["image1"])]
        preset = body.get("preset", "auto")
        config = match_config(preset, body.get("options") or {}, body.get("settings") or {},
                              bool(body.get("save_stages", True)))
        key = body.get("request")
        if key is not None and (not isinstance(key, str) or not 0 < len(key) <= 64):
            raise ApiError("request must be a string of 1 to 64 characters (one per click)")
        job = state.jobs.submit(config.to_dict(), *paths, images=[body["image0"], body["image1"]], preset=preset,
                                key=key)
        return job_state(job)

    @app.get("/api/jobs")
    def jobs():
        return {"jobs": [job_state(job) for job in state.jobs.listed()]}

    @app.get("/api/jobs/{job_id}")
    def one_job(job_id: str):
        state.job_folder(job_id, done=False)
        return job_state(state.jobs.get(job_id))

    @app.post("/api/jobs/{job_id}/cancel")
    def cancel(job_id: str):
        state.job_folder(job_id, done=False)
        return job_state(state.jobs.cancel(job_id))

    @app.get("/api/jobs/{job_id}/matches")
    def job_matches(job_id: str):
        return matches_payload(state.job_folder(job_id))

    @app.get("/api/jobs/{job_id}/stages")
    def job_stages(job_id: str):
        return stages_of(state.job_folder(job_id))

    @app.get("/api/jobs/{job_id}/files/{name}")
    def job_file(job_id: str, name: str):
        return download(state.job_folder(job_id), name)


def stages_of(folder: Path) -> dict[str, Any]:
    """The stage layers of a pair folder (404 when the match kept none)."""
    if not (folder / "stages.npz").is_file():
        raise ApiError("this match kept no stages: run Slime with 'keep stages' (slime match --save-stages)", 404)
    return stages_payload(folder)


def download(folder: Path, name: str) -> FileResponse:
    """One of a pair folder's :data:`DOWNLOADS`."""
    if name not in DOWNLOADS:
        raise ApiError(f"no file {name!r}: choose {', '.join(DOWNLOADS)}", 404)
    if not (folder / name).is_file():
        raise ApiError(f"this match has no {name}", 404)
    return FileResponse(folder / name, media_type=DOWNLOADS[name], filename=name)
