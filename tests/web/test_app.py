"""The API of ``slime web`` through FastAPI's test client: every endpoint, with bad input too (files outside
the folders, non-image uploads, unknown runs and jobs), and the annotation files as ``slime bench`` reads them."""

from __future__ import annotations

import errno
import io
import json
import os

import cv2
import numpy as np
import pytest

pytest.importorskip("fastapi", reason="slime web needs the web extra (FastAPI)")
pytest.importorskip("multipart", reason="slime web's uploads need python-multipart")
from fastapi.testclient import TestClient

from slime_match.cli import main
from slime_match.eval.datasets.planar import read_planar
from slime_match.eval.datasets.wxbs import read_wxbs
from slime_match.web import is_loopback
from slime_match.web.app import create_app

from .conftest import MANY, PLANAR_H, SECOND_H, wait

POST = {"X-Slime-Web": "1"}


@pytest.fixture(scope="module")
def annotations(tmp_path_factory):
    return tmp_path_factory.mktemp("annotations")


@pytest.fixture(scope="module")
def client(web_images, web_run, annotations):
    with TestClient(create_app([web_images], [web_run], annotations, max_upload_mb=1)) as client:
        yield client


def ref(path: str, root: str = "images") -> dict:
    return {"root": root, "path": path}


def png_bytes(width: int = 64, height: int = 48) -> bytes:
    image = np.random.default_rng(1).integers(0, 255, (height, width, 3), dtype=np.uint8)
    return cv2.imencode(".png", image)[1].tobytes()


def planar_pairs(n: int, noise: float = 0.0, off_plane: int = 0) -> list[dict]:
    """n pairs of the planar pair; the last ``off_plane`` of them on a second plane (SECOND_H)."""
    rng = np.random.default_rng(3)
    x0 = rng.uniform([30, 30], [370, 270], (n, 2))
    x1 = np.c_[x0, np.ones(n)] @ PLANAR_H.T
    if off_plane:
        x1[n - off_plane:] = np.c_[x0[n - off_plane:], np.ones(off_plane)] @ SECOND_H.T
    x1 = x1[:, :2] / x1[:, 2:] + rng.normal(0, noise, (n, 2))
    return [{"x0": a[0], "y0": a[1], "x1": b[0], "y1": b[1], "set": 0, "occluded": False} for a, b in zip(x0, x1)]


def transfer_gap(H: np.ndarray, truth: np.ndarray) -> float:
    """The largest distance (px) between where H and ``truth`` send the corners and the centre of plane0."""
    x = np.array([[0, 0, 1], [399, 0, 1], [0, 299, 1], [399, 299, 1], [200, 150, 1]], float)
    a, b = x @ H.T, x @ truth.T
    return float(np.max(np.linalg.norm(a[:, :2] / a[:, 2:] - b[:, :2] / b[:, 2:], axis=1)))


# ---------------------------------------------------------------------------------------------- page, folders


def test_page_and_static_files(client):
    page = client.get("/")
    assert page.status_code == 200 and "<canvas" in page.text and "/static/app.js" in page.text
    assert "http://" not in page.text and "https://" not in page.text  # nothing from the network
    for name in ("core.js", "viewer.js", "jobs.js", "tools.js", "annotation-store.js", "annotate.js", "app.js",
                 "style.css"):
        assert client.get(f"/static/{name}").status_code == 200
    assert client.get("/static/../app.py").status_code == 404


def test_info_lists_folders_runs_and_presets(client):
    info = client.get("/api/info").json()
    assert [f["name"] for f in info["folders"]] == ["images", "uploads", "annotations"]
    assert info["runs"] == ["run"] and "slime" in info["presets"] and "fundamental" in info["choices"]["ransac"]
    assert info["annotations"] is True and info["max_upload_mb"] == 1


def test_images_listed_and_served_upright_as_png(client, web_images):
    listed = client.get("/api/images", params={"root": "images"}).json()
    assert listed["images"] == ["fake.png", "left.png", "plane0.png", "plane1.png", "right.png", "sub/left.png"]
    served = client.get("/api/image", params={"root": "images", "path": "sub/left.png"})
    assert served.status_code == 200 and served.headers["content-type"] == "image/png"
    decoded = cv2.imdecode(np.frombuffer(served.content, np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(decoded, cv2.imread(str(web_images / "left.png")))


@pytest.mark.parametrize("path, status", [
    ("../run/pairs.json", 403), ("../../../../../../etc/passwd", 403), ("/etc/passwd", 403),
    ("sub/../../run/pairs.json", 403), ("nothere.png", 404), ("", 400), ("notes.txt", 400), ("fake.png", 415),
])
def test_image_paths_outside_or_bad_are_refused(client, path, status):
    answer = client.get("/api/image", params={"root": "images", "path": path})
    assert answer.status_code == status
    assert answer.json()["error"]


def test_a_link_out_of_a_folder_is_refused(client, web_images, tmp_path):
    secret = tmp_path / "secret.png"
    secret.write_bytes(png_bytes())
    os.symlink(secret, web_images / "link.png")
    try:
        answer = client.get("/api/image", params={"root": "images", "path": "link.png"})
        assert answer.status_code == 403 and "outside" in answer.json()["error"]
    finally:
        (web_images / "link.png").unlink()


def test_unknown_folder_and_missing_parameters(client):
    assert client.get("/api/images", params={"root": "etc"}).status_code == 404
    missing = client.get("/api/image", params={"root": "images"})
    assert missing.status_code == 422 and "path" in missing.json()["error"]


# ---------------------------------------------------------------------------------------------- uploads


def test_upload_an_image_then_serve_it(client):
    answer = client.post("/api/upload", headers=POST, files={"file": ("my photo.png", png_bytes(), "image/png")})
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["root"] == "uploads" and body["width"] == 64 and body["height"] == 48
    assert body["path"].endswith("my_photo.png") and "/" not in body["path"]
    assert client.get("/api/image", params={"root": "uploads", "path": body["path"]}).status_code == 200
    assert body["path"] in client.get("/api/images", params={"root": "uploads"}).json()["images"]


@pytest.mark.parametrize("name, data, status, words", [
    ("notes.txt", b"hello", 415, "not an image file name"),
    ("fake.png", b"this is no image", 415, "not an image"),
    ("empty.png", b"", 400, "empty"),
    ("tiny.png", png_bytes(20, 20), 415, "smaller than 32 px"),
    ("big.png", os.urandom(1_200_000), 413, "upload limit"),
    ("../../escape.png", b"x", 415, "not an image"),
])
def test_bad_uploads_are_refused(client, name, data, status, words):
    answer = client.post("/api/upload", headers=POST, files={"file": (name, data, "image/png")})
    assert answer.status_code == status, answer.text
    assert words in answer.json()["error"]


def test_an_upload_too_large_is_refused_before_it_is_read(client):
    answer = client.post("/api/upload", headers={**POST, "Content-Length": str(50 * 2**20)}, content=b"x" * 100)
    assert answer.status_code == 413 and "limit" in answer.json()["error"]


def test_changes_need_the_page_header(client):
    answer = client.post("/api/upload", files={"file": ("a.png", png_bytes(), "image/png")})
    assert answer.status_code == 403 and "x-slime-web" in answer.json()["error"]
    assert client.post("/api/match", json={}).status_code == 403


def test_other_hosts_are_refused_when_asked(web_images):
    app = create_app([web_images], allowed_hosts=["127.0.0.1", "localhost"])
    with TestClient(app, base_url="http://evil.example") as other:
        assert other.get("/api/info").status_code == 400
    with TestClient(app, base_url="http://127.0.0.1:8000") as local:
        assert local.get("/api/info").status_code == 200


# ---------------------------------------------------------------------------------------------- match jobs


@pytest.mark.parametrize("body, status, words", [
    ({"image0": ref("left.png")}, 400, "missing image1"),
    ({"image0": ref("left.png"), "image1": ref("../run/pairs.json")}, 403, "outside"),
    ({"image0": ref("left.png"), "image1": ref("right.png"), "preset": "nope"}, 400, "unknown method/preset"),
    ({"image0": ref("left.png"), "image1": ref("right.png"), "options": {"weights_dir": "/tmp"}}, 400, "refused"),
    ({"image0": ref("left.png"), "image1": ref("right.png"), "settings": {"base.weights_dir": "/"}}, 400,
     "may not be set"),
    ({"image0": ref("left.png"), "image1": ref("right.png"), "options": {"ransac": "bogus"}}, 400, "ransac"),
    ([1, 2], 400, "JSON object"),
])
def test_bad_match_requests(client, body, status, words):
    answer = client.post("/api/match", headers=POST, json=body)
    assert answer.status_code == status, answer.text
    assert words in answer.json()["error"]


def test_match_body_that_is_not_json(client):
    answer = client.post("/api/match", headers={**POST, "Content-Type": "application/json"}, content=b"{nope")
    assert answer.status_code == 400 and "not JSON" in answer.json()["error"]


def test_match_job_runs_in_the_worker_with_stage_progress(client):
    body = {"image0": ref("left.png"), "image1": ref("right.png"), "preset": "rootsift",
            "options": {"ransac": "fundamental", "threshold": "3"}}
    job = client.post("/api/match", headers=POST, json=body).json()
    assert job["status"] in ("queued", "running")
    state = wait(client, job["id"])
    assert state["status"] == "done", state
    names = [s["name"] for s in state["stages"]]
    assert {"load", "features", "matching", "ransac"} <= set(names)
    assert all(s["seconds"] is not None for s in state["stages"])
    matches = client.get(f"/api/jobs/{job['id']}/matches").json()
    assert matches["count"] == state["counts"]["matches"] > 50
    assert len(matches["keypoints0"]) == len(matches["inliers"]) == matches["count"]
    assert matches["kind"] == "fundamental" and np.shape(matches["model"]) == (3, 3)
    npz = client.get(f"/api/jobs/{job['id']}/files/matches.npz")
    with np.load(io.BytesIO(npz.content)) as data:
        assert data["keypoints0"].shape == (matches["count"], 2) and "F" in data
    summary = client.get(f"/api/jobs/{job['id']}/files/summary.json").json()
    assert summary["method"] == "rootsift"
    assert client.get(f"/api/jobs/{job['id']}/files/stages.npz").status_code == 404  # a base pipeline alone
    assert "no stages" in client.get(f"/api/jobs/{job['id']}/stages").json()["error"]
    assert client.get(f"/api/jobs/{job['id']}/files/run.py").status_code == 404


def test_cancel_a_job_and_the_next_one_still_runs(client):
    body = {"image0": ref("plane0.png"), "image1": ref("plane1.png"), "preset": "rootsift"}
    first = client.post("/api/match", headers=POST, json=body).json()
    cancelled = client.post(f"/api/jobs/{first['id']}/cancel", headers=POST).json()
    assert cancelled["status"] == "cancelled"
    assert client.get(f"/api/jobs/{first['id']}/matches").status_code == 409
    second = client.post("/api/match", headers=POST, json=body).json()
    assert wait(client, second["id"])["status"] == "done"


def test_a_failing_match_is_reported_and_the_server_goes_on(client, web_images):
    body = {"image0": ref("left.png"), "image1": ref("left.png"), "preset": "rootsift",
            "options": {"max_side": "40"}}  # the 370x250 image would shrink under 32 px
    state = wait(client, client.post("/api/match", headers=POST, json=body).json()["id"])
    assert state["status"] == "failed" and "32 px" in state["error"]
    assert client.get("/api/info").status_code == 200


def test_a_worker_that_dies_fails_its_job_alone(client):
    body = {"image0": ref("left.png"), "image1": ref("right.png"), "preset": "rootsift"}
    job = client.post("/api/match", headers=POST, json=body).json()
    runner = client.app.state.slime.jobs
    with runner._lock:
        process = runner._process
    os.kill(process.pid, 9)  # as the kernel's out-of-memory killer would
    state = wait(client, job["id"])
    assert state["status"] == "failed" and "worker stopped" in state["error"]
    assert wait(client, client.post("/api/match", headers=POST, json=body).json()["id"])["status"] == "done"


class _NoProcesses:
    """A multiprocessing context whose processes fail to start, as on a system out of processes."""

    def __init__(self, context):
        self.Queue = context.Queue
        self._context = context

    def Process(self, **kwargs):
        process = self._context.Process(**kwargs)

        def start():
            raise OSError(errno.EAGAIN, os.strerror(errno.EAGAIN))

        process.start = start
        return process


def test_a_worker_that_cannot_start_fails_the_queued_job_and_the_next_match_starts_one(client, monkeypatch):
    body = {"image0": ref("left.png"), "image1": ref("right.png"), "preset": "rootsift"}
    runner = client.app.state.slime.jobs
    with runner._lock:
        runner._kill_worker()
    monkeypatch.setattr(runner, "_context", _NoProcesses(runner._context))
    job = client.post("/api/match", headers=POST, json=body).json()
    state = wait(client, job["id"])
    assert state["status"] == "failed", state
    assert state["error"] == (f"the matching worker could not start ({os.strerror(errno.EAGAIN)}); the next match "
                              "tries again")
    assert runner._process is None and runner._tasks is None and runner._events is None
    monkeypatch.undo()
    assert wait(client, client.post("/api/match", headers=POST, json=body).json()["id"])["status"] == "done"


def test_a_fault_of_the_server_is_answered_as_json(web_images, web_run, monkeypatch):
    def broken(folder):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr("slime_match.web.routes_runs.matches_payload", broken)
    with TestClient(create_app([web_images], [web_run]), raise_server_exceptions=False) as other:
        answer = other.get("/api/runs/run/pairs/0")
        assert answer.status_code == 500 and "disk on fire" in answer.json()["error"]
        assert other.get("/api/info").status_code == 200


def test_unknown_job(client):
    for url in ("/api/jobs/nope", "/api/jobs/nope/matches", "/api/jobs/nope/stages", "/api/jobs/nope/files/matches.npz"):
        answer = client.get(url)
        assert answer.status_code == 404 and "unknown job" in answer.json()["error"]
    assert client.post("/api/jobs/nope/cancel", headers=POST).status_code == 404


def test_stage_files_of_earlier_versions_show_image_0s_views(tmp_path):
    """Stage files written before each image's blocks were recorded name image 0's views ``planes_view``."""
    from slime_match.io import save_npz
    from slime_match.web.payloads import stages_payload

    from .conftest import synthetic_stages

    stages = synthetic_stages(np.random.default_rng(0))
    stages["planes_view"] = stages.pop("planes_view0")
    for key in ("planes_corners1", "planes_view1"):
        del stages[key]
    save_npz(tmp_path / "stages.npz", **stages)
    planes = stages_payload(tmp_path)["layers"]["planes"]
    assert planes["views0"][3] == [4.0, 18.0] and "corners1" not in planes and "views1" not in planes


def test_the_decisions_of_a_run_read_as_lines():
    from slime_match.web.payloads import decision_lines

    views = {"mode": "auto", "images": "both", "tilts": [2.0], "views": 10, "decision": "kept",
             "reason": "image 1's views: enough matches consistent with the planes' epipolar geometry (F^theta): "
                       "150 >= 100",
             "tried": [{"image": 0, "tilt": 2.0, "views": 5, "planes": 3, "support": 20, "ftheta_matches": 0,
                        "ftheta_by_angle": {}, "screens": {"0": 12, "36": 22, "72": 3, "108": 0, "144": 1},
                        "probes": {"0": 14, "36": 30}, "paired": 1},
                       {"image": 1, "tilt": 2.0, "views": 5, "planes": 9, "support": 150, "on_views": 145,
                        "ftheta_matches": 140,
                        "ftheta_by_angle": {"0": 100, "36": 40}}]}
    fallback = {"reason": "Slime on aliked-lg (upright by design) found no match; Slime on hz+ found 680"}
    lines = decision_lines({"method": "slime-aliked (its weights are cached)", "rotation_fallback": fallback,
                            "views": views, "vote": "consensus",
                            "vote_reason": "3 homographies share F", "detection": "scale", "block_matching": "levels",
                            "pool": "disk-lg: 84 block planes pooled with the base's 49",
                            "global_dtm": "image 0's own frame"})
    assert lines == [
        "method: slime-aliked (its weights are cached)",
        "rotation fallback: Slime on aliked-lg (upright by design) found no match; Slime on hz+ found 680",
        ("simulated views (auto, of both images): kept: image 1's views: enough matches consistent with the "
         "planes' epipolar geometry (F^theta): 150 >= 100"),
        ("  image 0, tilt 2: 5 views (1 paired after their probes; best screen 22 consistent matches at 36 deg, "
         "best probe 30 consistent matches at 36 deg), 3 planes, F^theta with them 20, 0 matches kept in F^theta"),
        ("  image 1, tilt 2: 5 views, 9 planes, F^theta with them 150 (145 on the views' planes), 140 matches kept "
         "in F^theta (100 at 0 deg, 40 at 36 deg)"),
        "epipolar vote: consensus (3 homographies share F)",
        "blocks: scale detection, matched by levels",
        "pooled base: disk-lg: 84 block planes pooled with the base's 49",
        "final DTM: image 0's own frame",
    ]
    assert decision_lines({}) == []


# ---------------------------------------------------------------------------------------------- runs


def test_runs_and_their_pairs(client):
    runs = client.get("/api/runs").json()["runs"]
    assert runs == [{"name": "run", "pairs": 4, "done": 3, "skipped": 0, "failed": 1}]
    run = client.get("/api/runs/run").json()
    assert run["method"] == "slime" and [p["status"] for p in run["pairs"]] == ["done", "done", "failed", "done"]
    pair = client.get("/api/runs/run/pairs/0").json()
    assert pair["count"] == MANY and pair["images"] == [ref("left.png"), ref("right.png")]
    assert pair["kind"] == "fundamental" and sum(pair["inliers"]) > MANY // 2 and pair["has_stages"]
    stages = client.get("/api/runs/run/pairs/0/stages").json()
    assert list(stages["layers"]) == ["blocks", "tiles", "planes", "superset", "fbar", "ftheta", "tile_matches",
                                      "final"]
    planes = stages["layers"]["planes"]
    assert planes["label"][:3] == [0, 0, 0] and len(planes["H"]) == 4 and planes["block_pairs"][3] == [7, 1]
    assert planes["views0"][3] == [4.0, 18.0] and planes["corners0"][3][1] == [200.0, 60.0]
    assert planes["views1"][3] == [1.0, 0.0] and planes["corners1"][3][0] == [0.0, 0.0]
    assert stages["layers"]["fbar"]["sets"] == 2 and stages["counts"] == {"matches": MANY}
    assert client.get("/api/runs/run/pairs/0/files/matches.npz").status_code == 200
    assert client.get("/api/runs/run/pairs/1/stages").status_code == 404


@pytest.mark.parametrize("url, status, words", [
    ("/api/runs/other", 404, "unknown run"),
    ("/api/runs/other/pairs/0", 404, "unknown run"),
    ("/api/runs/run/pairs/9", 404, "no pair 9"),
    ("/api/runs/run/pairs/2", 409, "failed in the run"),
    ("/api/runs/run/pairs/3", 403, "outside the run"),
    ("/api/runs/run/pairs/3/files/matches.npz", 403, "outside the run"),
    ("/api/runs/run/pairs/0/files/pairs.json", 404, "no file"),
])
def test_bad_run_requests(client, url, status, words):
    answer = client.get(url)
    assert answer.status_code == status and words in answer.json()["error"]


def test_run_images_not_served_are_reported(web_run, tmp_path):
    with TestClient(create_app([tmp_path], [web_run])) as other:
        pair = other.get("/api/runs/run/pairs/1").json()
        assert pair["images"] == [None, None] and "--images" in pair["images_missing"]


def test_missing_folders_stop_before_serving(tmp_path, capsys):
    assert main(["web", "--images", str(tmp_path / "none")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["web", "--run", str(tmp_path)]) == 2
    assert "pairs.json" in capsys.readouterr().err
    assert main(["web", "--max-upload-mb", "0"]) == 2
    assert "upload limit" in capsys.readouterr().err
    assert main(["web", "--max-megapixels", "0"]) == 2
    assert "image limit" in capsys.readouterr().err
    (tmp_path / "file").write_text("")
    assert main(["web", "--annotations", str(tmp_path / "file")]) == 2
    assert "is a file" in capsys.readouterr().err


def test_loopback_names():
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and is_loopback("::1")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.2") and not is_loopback("example.com")


# ---------------------------------------------------------------------------------------------- annotation


def test_fit_shows_h_from_4_pairs_and_f_from_8(client):
    three = client.post("/api/annotate/fit", headers=POST, json={"pairs": planar_pairs(3)}).json()
    assert three["H"] is None and three["F"] is None and three["residual_H"] == [None] * 3
    four = client.post("/api/annotate/fit", headers=POST, json={"pairs": planar_pairs(4)}).json()
    H = np.array(four["H"])
    assert np.allclose(H / H[2, 2], PLANAR_H, atol=1e-6) and four["F"] is None
    pairs = planar_pairs(12, noise=0.3, off_plane=4)
    pairs[8]["set"] = pairs[9]["set"] = 2
    pairs[10]["set"] = pairs[11]["set"] = 1
    pairs.append({"x0": 5.0, "y0": 6.0, "x1": None, "y1": None, "set": 0, "occluded": True})
    fitted = client.post("/api/annotate/fit", headers=POST, json={"pairs": pairs}).json()
    assert fitted["visible"] == 12 and fitted["F"] is not None
    assert fitted["set_H"]["1"] is None and fitted["set_H"]["0"] is not None  # set 1 has 2 pairs
    assert max(r for r in fitted["residual_H"][:8]) < 1.5 and fitted["residual_H"][8:] == [None] * 5
    assert max(r for r in fitted["residual_F"][:12]) < 1.5 and fitted["residual_F"][12] is None


@pytest.mark.parametrize("pairs, words", [
    ("x", "must be a list"),
    ([{"x0": 1, "y0": 2}], "must be numbers"),
    ([{"x0": 1, "y0": 2, "x1": "a", "y1": 3}], "must be numbers"),
    ([{"x0": 1, "y0": float("nan"), "x1": 2, "y1": 3}], "not valid JSON"),
    ([{"x0": None, "y0": None, "x1": None, "y1": None, "occluded": True}], "point of one image"),
])
def test_bad_annotations(client, pairs, words):
    try:
        answer = client.post("/api/annotate/fit", headers=POST, json={"pairs": pairs})
    except ValueError as error:  # the client refuses to send NaN, which JSON cannot hold
        assert words in str(error) or "JSON" in str(error)
        return
    assert answer.status_code == 400 and words in answer.json()["error"]


def test_export_as_the_bench_reads(client, tmp_path):
    few = client.post("/api/annotate/export", headers=POST, json={"pairs": planar_pairs(6), "model": "F"})
    assert few.status_code == 400 and "F needs 8 pairs, there are 6" in few.json()["error"]
    corrs = client.post("/api/annotate/export", headers=POST, json={"pairs": planar_pairs(9, off_plane=3),
                                                                     "model": "F"})
    assert 'filename="corrs.txt"' in corrs.headers["content-disposition"]
    assert np.loadtxt(io.StringIO(corrs.text)).shape == (9, 4)
    hfile = client.post("/api/annotate/export", headers=POST, json={"pairs": planar_pairs(5), "model": "H"})
    assert np.allclose(np.loadtxt(io.StringIO(hfile.text)), PLANAR_H, atol=1e-6)
    assert client.post("/api/annotate/export", headers=POST, json={"pairs": [], "model": "X"}).status_code == 400


def test_save_open_round_trip_through_the_bench_readers(client, annotations):
    pairs = planar_pairs(10, noise=0.05, off_plane=3)
    pairs.append({"x0": 40.0, "y0": 50.0, "x1": None, "y1": None, "set": 0, "occluded": True})
    body = {"name": "astro", "image0": ref("plane0.png"), "image1": ref("plane1.png"), "pairs": pairs}
    saved = client.post("/api/annotate/save", headers=POST, json={**body, "model": "F"}).json()
    assert saved["kind"] == "wxbs" and "wxbs/astro/corrs.txt" in saved["files"]
    [wxbs] = read_wxbs(annotations / "wxbs")
    assert wxbs.name == "astro" and wxbs.corrs.shape == (10, 4) and wxbs.image0.name == "01.png"
    assert np.allclose(wxbs.corrs, [[p["x0"], p["y0"], p["x1"], p["y1"]] for p in pairs[:10]], atol=1e-3)
    again = client.post("/api/annotate/save", headers=POST, json={**body, "model": "F"})
    assert again.status_code == 400 and "exists" in again.json()["error"]
    assert client.post("/api/annotate/save", headers=POST, json={**body, "model": "F", "overwrite": True}).status_code == 200

    coplanar = planar_pairs(10, noise=0.05) + pairs[10:]
    planar = client.post("/api/annotate/save", headers=POST, json={**body, "model": "H", "pairs": coplanar}).json()
    assert planar["kind"] == "planar" and "planar/astro_H12.txt" in planar["files"]
    [pair] = read_planar(annotations / "planar")
    assert pair.name == "astro/1-2" and transfer_gap(pair.H, PLANAR_H) < 1.0

    listed = client.get("/api/annotate/saved").json()["annotations"]
    assert [(a["kind"], a["name"]) for a in listed] == [("wxbs", "astro"), ("planar", "astro")]
    opened = client.get("/api/annotate/open", params={"root": "annotations", "path": "wxbs/astro/corrs.txt"}).json()
    assert opened["kind"] == "wxbs" and len(opened["pairs"]) == 11 and opened["pairs"][10]["occluded"]
    assert opened["image0"] == ref("wxbs/astro/01.png", "annotations")
    wxbs_opened = opened
    opened = client.get("/api/annotate/open", params={"root": "annotations", "path": "planar/astro_H12.txt"}).json()
    assert opened["kind"] == "planar" and np.allclose(opened["H"], pair.H) and len(opened["pairs"]) == 11

    # a pair opened from the annotation folder saved again under its name: its images are its own copies
    resave = {"name": "astro", "model": "F", "image0": wxbs_opened["image0"], "image1": wxbs_opened["image1"],
              "pairs": wxbs_opened["pairs"], "overwrite": True}
    assert client.post("/api/annotate/save", headers=POST, json=resave).status_code == 200
    resave.update(model="H", pairs=opened["pairs"], image0=ref("planar/astro1.png", "annotations"), image1=ref("planar/astro2.png",
                                                                                          "annotations"))
    assert client.post("/api/annotate/save", headers=POST, json=resave).status_code == 200
    assert len(read_wxbs(annotations / "wxbs")) == len(read_planar(annotations / "planar")) == 1
    opened = client.get("/api/annotate/open", params={"root": "annotations", "path": "wxbs/astro/corrs.txt"}).json()

    # a corrs.txt edited by hand wins over the tool's record of it
    (annotations / "wxbs" / "astro" / "corrs.txt").write_text("1 2 3 4\n" * 8)
    opened = client.get("/api/annotate/open", params={"root": "annotations", "path": "wxbs/astro/corrs.txt"}).json()
    assert [list(p.values())[:4] for p in opened["pairs"]] == [[1, 2, 3, 4]] * 8


@pytest.mark.parametrize("body, status, words", [
    ({"name": "../x", "model": "F"}, 400, "pair name"),
    ({"name": "ok", "model": "Q"}, 400, "model must be"),
    ({"name": "ok", "model": "F", "image0": ref("../run/pairs.json")}, 403, "outside"),
])
def test_bad_saves(client, body, status, words):
    full = {"image0": ref("plane0.png"), "image1": ref("plane1.png"), "pairs": planar_pairs(8), **body}
    answer = client.post("/api/annotate/save", headers=POST, json=full)
    assert answer.status_code == status and words in answer.json()["error"]


def test_open_refuses_other_files(client):
    answer = client.get("/api/annotate/open", params={"root": "images", "path": "left.png"})
    assert answer.status_code == 400 and "none of the ground truths" in answer.json()["error"]
    answer = client.get("/api/annotate/open", params={"root": "images", "path": "../run/pairs.json"})
    assert answer.status_code == 403


def test_saving_needs_an_annotation_folder(web_images):
    with TestClient(create_app([web_images])) as other:
        body = {"name": "x", "model": "H", "image0": ref("plane0.png", "plane0"), "image1": ref("plane1.png"),
                "pairs": planar_pairs(4)}
        answer = other.post("/api/annotate/save", headers=POST, json=body)
        assert answer.status_code == 409 and "--annotations" in answer.json()["error"]
        assert other.get("/api/annotate/saved").json() == {"annotations": [], "folder": None}


def test_summary_json_is_json(client):
    run = client.get("/api/runs/run/pairs/0/files/summary.json")
    assert json.loads(run.content)["method"] == "slime"
