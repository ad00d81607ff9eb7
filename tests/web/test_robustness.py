"""``slime web`` under bad input: images refused by their header before anything decodes them (non-images, a
72-megapixel PNG of a few bytes), options this server cannot run (CUDA absent, more workers than CPUs), one
job per click, a job list, no server path in any answer, and one JSON shape for every error."""

from __future__ import annotations

import struct
import zlib

import pytest

pytest.importorskip("fastapi", reason="slime web needs the web extra (FastAPI)")
pytest.importorskip("multipart", reason="slime web's uploads need python-multipart")
from fastapi.testclient import TestClient

from slime_match.web.app import create_app
from slime_match.web.match_options import server_cpus

from .conftest import wait

POST = {"X-Slime-Web": "1"}


def png_header_only(width: int, height: int) -> bytes:
    """A PNG file that announces ``width`` x ``height`` grey pixels and holds the data of a few rows only."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    rows = zlib.compress(b"\0" * (width + 1) * 4)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", rows) + chunk(b"IEND", b""))


@pytest.fixture(scope="module")
def folder(web_images, tmp_path_factory):
    """The test images plus a 72 MP PNG of a few hundred bytes and a truncated PNG."""
    extra = tmp_path_factory.mktemp("robust")
    (extra / "bomb.png").write_bytes(png_header_only(12_000, 6_000))
    (extra / "cut.png").write_bytes((web_images / "left.png").read_bytes()[:2000])
    return extra


@pytest.fixture(scope="module")
def client(web_images, folder):
    with TestClient(create_app([web_images, folder]), raise_server_exceptions=False) as client:
        yield client


def ref(path: str, root: str = "images") -> dict:
    return {"root": root, "path": path}


def test_a_72_megapixel_png_of_a_few_bytes_is_refused_before_decoding(client, folder, monkeypatch):
    def no_decoding(*args, **kwargs):
        raise AssertionError("the server decoded an image over the pixel limit")

    monkeypatch.setattr("slime_match.web.routes_images.load_image", no_decoding)
    monkeypatch.setattr("slime_match.web.state.load_image", no_decoding)
    data = (folder / "bomb.png").read_bytes()
    assert len(data) < 2000
    upload = client.post("/api/upload", headers=POST, files={"file": ("bomb.png", data, "image/png")})
    assert upload.status_code == 413 and "12000x6000 px (72 MP), over the limit of 40 MP" in upload.json()["error"]
    shown = client.get("/api/image", params={"root": "robust0", "path": "bomb.png"})
    assert shown.status_code == 413 and "over the limit" in shown.json()["error"]
    match = client.post("/api/match", headers=POST, json={"image0": ref("bomb.png", "robust0"),
                                                           "image1": ref("left.png")})
    assert match.status_code == 413 and "robust0/bomb.png" in match.json()["error"]


@pytest.mark.parametrize("path, words", [
    ("fake.png", "not an image (its header"), ("notes.txt", "not an image file name"),
])
def test_a_non_image_of_a_folder_is_refused_when_the_match_is_asked(client, web_images, path, words):
    answer = client.post("/api/match", headers=POST, json={"image0": ref(path), "image1": ref("left.png")})
    assert answer.status_code == 415 and words in answer.json()["error"]
    assert str(web_images) not in answer.text


def test_options_this_server_cannot_run_are_refused(client):
    import torch

    body = {"image0": ref("left.png"), "image1": ref("right.png"), "preset": "slime-rootsift"}
    if not torch.cuda.is_available():
        cuda = client.post("/api/match", headers=POST, json={**body, "options": {"device": "cuda"}})
        assert cuda.status_code == 400 and "no CUDA device" in cuda.json()["error"]
    too_many = client.post("/api/match", headers=POST, json={**body, "options": {"workers": server_cpus() + 1}})
    assert too_many.status_code == 400 and f"workers must be 1 to {server_cpus()}" in too_many.json()["error"]
    assert client.get("/api/jobs").json()["jobs"] == []


def test_errors_have_one_json_shape(client, web_images):
    answers = [client.get("/api/nope"), client.get("/static/nope.js"), client.get("/api/match"),
               client.post("/api/jobs/x/cancel"), client.get("/api/image", params={"root": "images"})]
    assert [a.status_code for a in answers] == [404, 404, 405, 403, 422]
    for answer in answers:
        assert answer.headers["content-type"] == "application/json" and set(answer.json()) == {"error"}
    other = create_app([web_images], allowed_hosts=["127.0.0.1"])
    with TestClient(other, base_url="http://evil.example") as evil:
        refused = evil.get("/api/info")
        assert refused.status_code == 400 and set(refused.json()) == {"error"}


def test_one_job_per_click_a_job_list_and_no_server_path_in_a_failure(client, web_images, folder):
    body = {"image0": ref("cut.png", "robust0"), "image1": ref("left.png"), "preset": "rootsift",
            "request": "click-1"}
    first = client.post("/api/match", headers=POST, json=body).json()
    again = client.post("/api/match", headers=POST, json=body).json()  # the same click sent twice
    assert again["id"] == first["id"]
    listed = client.get("/api/jobs").json()["jobs"]
    assert [job["id"] for job in listed] == [first["id"]]
    failed = wait(client, first["id"])
    assert failed["status"] == "failed" and "robust0/cut.png" in failed["error"], failed["error"]
    for path in (str(folder), str(folder.resolve()), str(web_images)):
        assert path not in failed["error"]
    second = client.post("/api/match", headers=POST, json={**body, "image0": ref("right.png"),
                                                           "request": "click-2"}).json()
    assert [job["id"] for job in client.get("/api/jobs").json()["jobs"]] == [second["id"], first["id"]]
    assert client.post(f"/api/jobs/{second['id']}/cancel", headers=POST).json()["status"] == "cancelled"


def test_the_worker_s_warnings_reach_the_running_job_as_notices():
    import logging
    import queue

    from slime_match.web.jobs import NoticeHandler

    events, current = queue.Queue(), {"job": None}
    handler = NoticeHandler(events, current)
    logger = logging.getLogger("slime_match")
    logger.addHandler(handler)
    try:
        logger.warning("before any job")
        current["job"] = "j1"
        logger.info("not a warning")
        logger.warning("numba is compiling slime-match's loops")
    finally:
        logger.removeHandler(handler)
    assert events.get_nowait() == ("notice", "j1", "numba is compiling slime-match's loops") and events.empty()


def test_the_page_offers_the_match_options_of_the_command_line(client):
    from slime_match.choices import MATCH_OPTIONS
    from slime_match.cli.commands import build_parser

    args = build_parser().parse_args(["match", "a.png", "b.png", "-o", "out"])
    for key in MATCH_OPTIONS:  # each one a `slime match` option too
        assert hasattr(args, "slime_workers" if key == "workers" else key), key
    info = client.get("/api/info").json()
    assert info["options"] == list(MATCH_OPTIONS) and info["choices"]["views"] == ["off", "auto", "always"]
    assert info["max_workers"] == server_cpus() and isinstance(info["cuda"], bool)
