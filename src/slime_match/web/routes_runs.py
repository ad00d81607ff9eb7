"""The routes of ``slime web`` for the ``slime pairs`` run folders it was given: the runs, a run's pairs, and
a pair's matches, stage layers and files, as a job's."""

from __future__ import annotations

import json

from fastapi import FastAPI

from .api_errors import ApiError
from .payloads import matches_payload
from .routes_jobs import download, stages_of
from .state import WebState


def add_run_routes(app: FastAPI, state: WebState) -> None:
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
        return stages_of(state.run_pair(name, index)[1])

    @app.get("/api/runs/{name}/pairs/{index}/files/{file}")
    def run_pair_file(name: str, index: int, file: str):
        return download(state.run_pair(name, index)[1], file)
