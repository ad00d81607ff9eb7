"""The annotation tool's models: F refused, with the reason, for pairs that do not determine it (too few, on a
line, on one plane), H and F residuals per pair, and the bench's other homography files opened."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

pytest.importorskip("fastapi", reason="slime web needs the web extra (FastAPI)")
from fastapi.testclient import TestClient

from slime_match.web.annotation_models import fit
from slime_match.web.app import create_app

from .conftest import PLANAR_H, SECOND_H

POST = {"X-Slime-Web": "1"}


def pairs_of(x0: np.ndarray, H: np.ndarray, group: int = 0) -> list[dict]:
    x1 = np.c_[x0, np.ones(len(x0))] @ H.T
    x1 = x1[:, :2] / x1[:, 2:]
    return [{"x0": a[0], "y0": a[1], "x1": b[0], "y1": b[1], "set": group, "occluded": False}
            for a, b in zip(x0.tolist(), x1.tolist())]


GRID = np.array([[40, 40], [200, 50], [350, 60], [60, 150], [210, 160], [340, 140], [50, 260], [330, 250]], float)


def test_f_of_eight_coplanar_pairs_is_refused_with_the_reason():
    fitted = fit(pairs_of(GRID, PLANAR_H))
    assert fitted["F"] is None and fitted["H"] is not None
    assert "8 of the 8 pairs lie on one plane" in fitted["why"]["F"] and fitted["why"]["H"] is None
    assert fitted["residual_F"] == [None] * 8 and max(fitted["residual_H"]) < 1e-6


def test_f_with_one_pair_off_the_plane_is_refused_and_with_two_it_is_fitted():
    one = pairs_of(GRID, PLANAR_H) + pairs_of(np.array([[120.0, 200.0]]), SECOND_H, 1)
    assert fit(one)["F"] is None and "8 of the 9 pairs lie on one plane" in fit(one)["why"]["F"]
    two = one + pairs_of(np.array([[280.0, 90.0]]), SECOND_H, 1)
    fitted = fit(two)
    assert fitted["why"]["F"] is None and len(fitted["residual_F"]) == 10
    assert max(fitted["residual_F"]) < 1e-3  # both planes satisfy x1^T F x0 = 0
    F = np.array(fitted["F"])
    truth = np.cross(np.eye(3), [1.0, 0.0, 0.0]).T @ PLANAR_H  # [e']_x H with e' = (1, 0, 0)
    assert abs(abs(np.sum(F * truth)) / np.linalg.norm(F) / np.linalg.norm(truth) - 1) < 1e-6
    assert fitted["set_H"]["1"] is None and fitted["set_why"]["1"] == "H needs 4 pairs, there are 2"


def test_too_few_and_collinear_pairs_are_refused():
    assert fit(pairs_of(GRID[:7], PLANAR_H))["why"]["F"] == "F needs 8 pairs, there are 7"
    line = np.c_[np.linspace(20, 380, 9), np.linspace(30, 270, 9)]
    fitted = fit(pairs_of(line, PLANAR_H))
    assert fitted["why"]["F"] == "F refused: the points lie on a line"
    assert fitted["why"]["H"] == "H is undetermined: the points lie on a line" and fitted["H"] is None
    assert fit(pairs_of(GRID[:3], PLANAR_H))["why"]["H"] == "H needs 4 pairs, there are 3"


def test_saving_f_of_coplanar_pairs_is_refused(web_images, tmp_path):
    with TestClient(create_app([web_images], annotations=tmp_path / "gt")) as client:
        body = {"name": "flat", "model": "F", "image0": {"root": "images", "path": "plane0.png"},
                "image1": {"root": "images", "path": "plane1.png"}, "pairs": pairs_of(GRID, PLANAR_H)}
        answer = client.post("/api/annotate/save", headers=POST, json=body)
        assert answer.status_code == 400 and "lie on one plane" in answer.json()["error"]
        assert not (tmp_path / "gt" / "wxbs").exists()


def test_oxford_and_evd_homographies_open(web_images, tmp_path):
    oxford, evd = tmp_path / "graf", tmp_path / "evd"
    oxford.mkdir()
    for k in (1, 3):
        shutil.copy(web_images / "plane0.png", oxford / f"img{k}.png")
    np.savetxt(oxford / "H1to3p", PLANAR_H)
    for sub in ("1", "2", "h"):
        (evd / sub).mkdir(parents=True)
    shutil.copy(web_images / "plane0.png", evd / "1" / "adam.png")
    shutil.copy(web_images / "plane1.png", evd / "2" / "adam.png")
    np.savetxt(evd / "h" / "adam.txt", PLANAR_H)
    (evd / "h" / "lost.txt").write_text("1 0 0\n0 1 0\n0 0 1\n")
    with TestClient(create_app([oxford, evd])) as client:
        opened = client.get("/api/annotate/open", params={"root": "graf", "path": "H1to3p"}).json()
        assert opened["kind"] == "planar" and np.allclose(opened["H"], PLANAR_H) and opened["pairs"] == []
        assert opened["image0"] == {"root": "graf", "path": "img1.png"}
        assert opened["image1"] == {"root": "graf", "path": "img3.png"}
        opened = client.get("/api/annotate/open", params={"root": "evd", "path": "h/adam.txt"}).json()
        assert opened["image0"] == {"root": "evd", "path": "1/adam.png"} and np.allclose(opened["H"], PLANAR_H)
        assert opened["image1"] == {"root": "evd", "path": "2/adam.png"}
        missing = client.get("/api/annotate/open", params={"root": "evd", "path": "h/lost.txt"})
        assert missing.status_code == 400 and "1/lost.* and 2/lost.* are missing" in missing.json()["error"]
