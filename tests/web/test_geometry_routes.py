"""RANSAC run again on a match's matches (method, threshold, a confidence floor) without matching again, and
image 0 warped by a homography into image 1's frame for the overlay."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

pytest.importorskip("fastapi", reason="slime web needs the web extra (FastAPI)")
from fastapi.testclient import TestClient

from slime_match.web.app import create_app

from .conftest import MANY, PLANAR_H

POST = {"X-Slime-Web": "1"}


@pytest.fixture(scope="module")
def client(web_images, web_run):
    with TestClient(create_app([web_images], [web_run])) as client:
        yield client


def test_ransac_again_on_a_run_pair(client):
    body = {"source": {"run": "run", "index": 1}, "method": "magsac-homography", "threshold": 1.0}
    answer = client.post("/api/ransac", headers=POST, json=body).json()
    assert answer["kind"] == "homography" and answer["used"] == 10 and answer["inliers"] == [1] * 10
    H = np.array(answer["model"])
    assert np.allclose(H / H[2, 2], [[1, 0, 1], [0, 1, 1], [0, 0, 1]], atol=1e-6)  # the pair is shifted by 1 px


def test_ransac_again_only_on_the_matches_above_a_confidence(client):
    matches = client.get("/api/runs/run/pairs/0").json()
    confident = np.array(matches["confidence"]) >= 0.75
    body = {"source": {"run": "run", "index": 0}, "method": "magsac-fundamental", "threshold": 3,
            "min_confidence": 0.75}
    answer = client.post("/api/ransac", headers=POST, json=body).json()
    inliers = np.array(answer["inliers"], bool)
    assert answer["used"] == confident.sum() and 0 < answer["used"] < MANY and len(inliers) == MANY
    assert not inliers[~confident].any() and inliers.sum() > 0.5 * confident.sum()


@pytest.mark.parametrize("body, status, words", [
    ({"source": {"run": "run", "index": 1}, "method": "none"}, 400, "method must be one of"),
    ({"source": {"run": "run", "index": 1}, "method": "homography", "threshold": -1}, 400, "threshold must be"),
    ({"source": {"run": "run", "index": 1}, "method": "homography", "min_confidence": 2}, 400, "min_confidence"),
    ({"source": {"job": "nope"}, "method": "homography"}, 404, "unknown job"),
    ({"source": "x", "method": "homography"}, 400, "source must be"),
    ({"source": {"run": "run", "index": 9}, "method": "homography"}, 404, "no pair 9"),
])
def test_bad_ransac_requests(client, body, status, words):
    answer = client.post("/api/ransac", headers=POST, json=body)
    assert answer.status_code == status and words in answer.json()["error"]


def test_image_0_warped_into_image_1(client, web_images):
    body = {"image0": {"root": "images", "path": "plane0.png"}, "image1": {"root": "images", "path": "plane1.png"},
            "H": PLANAR_H.tolist()}
    answer = client.post("/api/warp", headers=POST, json=body)
    assert answer.status_code == 200 and answer.headers["content-type"] == "image/png"
    warped = cv2.imdecode(np.frombuffer(answer.content, np.uint8), cv2.IMREAD_UNCHANGED)
    truth = cv2.imread(str(web_images / "plane1.png"))
    assert warped.shape == (300, 400, 4) and warped[0, 399, 3] == 0  # outside image 0: transparent
    inside = warped[:, :, 3] == 255
    assert inside.mean() > 0.7 and np.abs(warped[:, :, :3][inside].astype(int) - truth[inside]).mean() < 3
    bad = client.post("/api/warp", headers=POST, json={**body, "H": [[1, 0], [0, 1]]})
    assert bad.status_code == 400 and "3x3" in bad.json()["error"]
