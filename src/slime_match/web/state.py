"""What the routes of ``slime web`` share: the served folders, the runs, the jobs, the limits, the images
encoded for the browser, and the redaction of the server's own paths out of what it answers."""

from __future__ import annotations

import json
import shutil
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..io import load_image
from .api_errors import ApiError
from .folders import Roots
from .image_checks import DECODING, image_size
from .jobs import JobRunner

ENCODED_KEPT = 8  # images kept encoded for the browser


class WebState:
    """The server's state.

    Attributes:
        roots: the served folders; runs: run folders by name; annotations: the annotation folder or None;
        max_upload: bytes; max_pixels: the largest image accepted (px); work: the server's temporary folder.
    """

    def __init__(self, roots: Roots, runs: dict[str, Path], annotations: Path | None, max_upload: int,
                 max_pixels: int, work: Path) -> None:
        self.roots, self.runs, self.annotations, self.work = roots, runs, annotations, work
        self.max_upload, self.max_pixels = max_upload, max_pixels
        self.jobs = JobRunner(work / "jobs")
        self._encoded: OrderedDict[tuple, tuple[bytes, str]] = OrderedDict()
        self._lock = threading.Lock()
        # the server's paths, longest first, and what an answer names them
        places = [(str(p), root.name) for root in roots for p in {root.path, root.path.resolve()}]
        places += [(str(p), "(server)") for p in {work, work.resolve()}]
        places += [(str(p), f"run {name}") for name, path in runs.items() for p in {path, path.resolve()}]
        self._places = sorted(places, key=lambda item: -len(item[0]))

    def close(self) -> None:
        self.jobs.close()
        shutil.rmtree(self.work, ignore_errors=True)

    def redact(self, text: str) -> str:
        """``text`` with the server's folders named as the API names them (a served folder by its name)."""
        for path, name in self._places:
            text = text.replace(path, name)
        return text

    def checked_image(self, ref: Any) -> Path:
        """The file of an image reference ``{"root", "path"}``, refused (ApiError) unless its header shows an
        image within the limits."""
        path = self.roots.file(ref)
        image_size(path, f"{ref['root']}/{ref['path']}", self.max_pixels)
        return path

    def encoded(self, path: Path, name: str) -> tuple[bytes, str]:
        """The image as the matcher sees it (upright by its EXIF tag, RGB), encoded for the browser: PNG, or
        JPEG above 2 MP; the last few are kept. Its size is checked before it is decoded."""
        stat = path.stat()
        key = (str(path), stat.st_mtime_ns, stat.st_size)
        with self._lock:
            if key in self._encoded:
                self._encoded.move_to_end(key)
                return self._encoded[key]
        image_size(path, name, self.max_pixels)
        with DECODING:
            image = load_image(path)
            pixels = np.clip(image * 255.0 + 0.5, 0, 255).astype(np.uint8)[:, :, ::-1]
            del image
            big = pixels.shape[0] * pixels.shape[1] > 2_000_000
            ok, data = cv2.imencode(".jpg" if big else ".png", pixels, [cv2.IMWRITE_JPEG_QUALITY, 92] if big else [])
        if not ok:
            raise ApiError(f"cannot encode {name} for the browser", 500)
        value = (data.tobytes(), "image/jpeg" if big else "image/png")
        with self._lock:
            self._encoded[key] = value
            while len(self._encoded) > ENCODED_KEPT:
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
            raise ApiError(f"job {job_id} is {job.status}" + (f": {self.redact(job.error)}" if job.error else ""),
                           409)
        return job.folder
