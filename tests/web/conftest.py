"""Data of the ``slime web`` tests: a folder of images (a real stereo pair, a planar pair made by a known
homography, a file that is not an image), a ``slime pairs`` run folder; for the browser tests, a server in a
thread, a headless Chromium and the screenshots' folder."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from skimage.data import astronaut, stereo_motorcycle

from slime_match.io import save_json, save_npz

# the planar pair: image 1 is image 0 seen through this homography (image 0 -> 1)
PLANAR_H = np.array([[0.92, 0.06, 18.0], [-0.04, 0.95, 12.0], [1.5e-4, 8e-5, 1.0]])
# a second plane of the same two views: its homography differs from PLANAR_H by e' v^T, with the epipole e' of
# image 1 at infinity along x (so F = [e']_x PLANAR_H holds for both planes)
SECOND_H = PLANAR_H + np.outer([1.0, 0.0, 0.0], [0.0, 0.0, 15.0])
MANY = 20_000  # matches of the run's big pair


@pytest.fixture(scope="session")
def web_images(tmp_path_factory):
    """Image folder: left.png / right.png (the motorcycle pair at 370x250), plane0.png / plane1.png (a
    400x300 planar pair related by PLANAR_H), notes.txt and fake.png (not images) and sub/left.png."""
    folder = tmp_path_factory.mktemp("web") / "images"
    (folder / "sub").mkdir(parents=True)
    left, right, _ = stereo_motorcycle()
    for name, image in (("left.png", left), ("right.png", right)):
        small = cv2.resize(image, (370, 250), interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(folder / name), small[:, :, ::-1])
    cv2.imwrite(str(folder / "sub" / "left.png"), cv2.imread(str(folder / "left.png")))
    plane = cv2.resize(astronaut(), (400, 300), interpolation=cv2.INTER_AREA)[:, :, ::-1]
    cv2.imwrite(str(folder / "plane0.png"), plane)
    cv2.imwrite(str(folder / "plane1.png"), cv2.warpPerspective(plane, PLANAR_H, (400, 300)))
    (folder / "notes.txt").write_text("not an image\n")
    (folder / "fake.png").write_bytes(b"this is not a PNG file at all")
    return folder


@pytest.fixture(scope="session")
def web_run(web_images):
    """A `slime pairs` run folder: left/right with MANY matches (RANSAC inliers and F) and Slime's stages,
    plane0/plane1 done, a failed pair and a pair whose folder points outside the run."""
    run = web_images.parent / "run"
    rng = np.random.default_rng(0)
    big = run / "left.png__right.png"
    big.mkdir(parents=True)
    xy0 = rng.uniform([0, 0], [369, 249], (MANY, 2))
    xy1 = xy0 + rng.normal([-20, 0], 2.0, (MANY, 2))
    save_npz(big / "matches.npz", keypoints0=xy0, keypoints1=xy1, scores=rng.uniform(0, 1, MANY),
             inliers=rng.uniform(0, 1, MANY) < 0.8, F=np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0.0]]))
    save_json(big / "summary.json", {"method": "slime", "counts": {"matches": MANY},
                                     "seconds": {"total": 1.0}, "image_sizes": {"image0": [370, 250],
                                                                                "image1": [370, 250]}})
    save_npz(big / "stages.npz", **synthetic_stages(rng))
    plane = run / "plane0.png__plane1.png"
    plane.mkdir()
    save_npz(plane / "matches.npz", keypoints0=xy0[:10], keypoints1=xy0[:10] + 1, scores=np.zeros(10))
    records = [
        {"image0": "left.png", "image1": "right.png", "folder": big.name, "status": "done", "matches": MANY,
         "seconds": 1.0},
        {"image0": "plane0.png", "image1": "plane1.png", "folder": plane.name, "status": "done", "matches": 10,
         "seconds": 0.5},
        {"image0": "left.png", "image1": "missing.png", "folder": "left.png__missing.png", "status": "failed",
         "matches": None, "seconds": 0.1, "error": "image missing.png not found"},
        {"image0": "a.png", "image1": "b.png", "folder": "../..", "status": "done", "matches": 1, "seconds": 0.1},
    ]
    save_json(run / "pairs.json", {"pairs": records, "finished": True})
    save_json(run / "run.json", {"config": {"method": "slime"}})
    return run


def synthetic_stages(rng) -> dict[str, np.ndarray]:
    """A stages.npz in the layout Slime writes: blocks, tiles, 4 planes (the last one found in a simulated view
    of image 0, whose block is not among ``blocks0``), sets, tile and final matches."""
    boxes = np.array([[0, 0, 370, 250, 0], [0, 0, 185, 125, 1], [185, 125, 370, 250, 1]], float)
    table = rng.uniform([0, 0], [369, 249], (60, 2))
    corners = boxes[:, [0, 1, 2, 1, 2, 3, 0, 3]].reshape(3, 4, 2)
    view_block = np.array([[40, 20], [200, 60], [180, 160], [20, 120]], float)  # turned and stretched
    return {
        "blocks0": boxes, "blocks1": boxes, "tiles0": boxes[1:], "tiles1": boxes[1:],
        "planes_pairs": np.array([[0, 0], [1, 1], [2, 2], [7, 1]]), "planes_H": np.repeat(np.eye(3)[None], 4, 0),
        "planes_corners0": np.concatenate([corners, view_block[None]]),
        "planes_view0": np.array([[1, 0], [1, 0], [1, 0], [4, 18]], float),
        "planes_corners1": corners[[0, 1, 2, 1]], "planes_view1": np.tile([1.0, 0.0], (4, 1)),
        "block_matches_xy0": table, "block_matches_xy1": table - [20, 0],
        "block_matches_plane": np.repeat(np.arange(4), 15),
        "table_xy0": table, "table_xy1": table - [20, 0],
        **{f"{name}_{key}": value for name in ("superset", "fbar", "ftheta") for key, value in
           (("indptr", np.array([0, 30, 60])), ("indices", np.arange(60)), ("plane", np.array([0, 1])),
            ("tile0", np.array([0, 1])), ("tile1", np.array([0, 1])))},
        "tile_matches_xy0": table[:40], "tile_matches_xy1": table[:40] - [20, 0],
        "final_xy0": table[:30], "final_xy1": table[:30] - [20, 0],
    }


@pytest.fixture(scope="module")
def shots(tmp_path_factory) -> Path:
    folder = Path(os.environ.get("SLIME_WEB_SCREENSHOTS") or tmp_path_factory.mktemp("screenshots"))
    folder.mkdir(parents=True, exist_ok=True)
    print(f"screenshots: {folder}")
    return folder


@pytest.fixture(scope="module")
def annotations(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("browser-annotations")


@pytest.fixture(scope="module")
def server(web_images, web_run, annotations):
    uvicorn = pytest.importorskip("uvicorn", reason="slime web needs the web extra (uvicorn)")
    from slime_match.web.app import create_app

    from .browser_steps import free_port

    app = create_app([web_images], [web_run], annotations)
    port = free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        assert time.monotonic() < deadline and thread.is_alive(), "the server did not start"
        time.sleep(0.05)
    yield f"http://127.0.0.1:{port}"
    server.should_exit = True
    thread.join(timeout=10)


@pytest.fixture(scope="module")
def browser(server):
    """Headless Chromium at 1400x900 (CSS px)."""
    webdriver = pytest.importorskip("selenium.webdriver", reason="the browser tests need selenium (the test extra)")
    from .browser_steps import CHROMIUM, DRIVER

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for argument in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                     "--window-size=1400,900", "--force-device-scale-factor=1"):
        options.add_argument(argument)
    driver = webdriver.Chrome(service=webdriver.ChromeService(DRIVER), options=options)
    driver.set_script_timeout(30)
    width, height = driver.execute_script("return [innerWidth, innerHeight];")  # the window's own bars apart
    driver.set_window_size(2 * 1400 - width, 2 * 900 - height)
    yield driver
    driver.quit()


def wait(client, job_id: str, timeout: float = 120.0) -> dict:
    """The state of a web job once it has left "queued" / "running" (fails after ``timeout`` s)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        state = client.get(f"/api/jobs/{job_id}").json()
        if state["status"] not in ("queued", "running"):
            return state
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} did not finish in {timeout} s")
