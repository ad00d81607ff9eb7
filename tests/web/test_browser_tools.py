"""The tools over the shown matches in a real headless browser: RANSAC run again, a confidence floor, image 0
warped over image 1 (checkerboard), the matches coloured by their error to the pair's annotated ground truth,
and the exports (view PNG, matches JSON and CSV)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

pytest.importorskip("fastapi", reason="slime web needs the web extra (FastAPI)")
pytest.importorskip("uvicorn", reason="slime web needs the web extra (uvicorn)")
pytest.importorskip("selenium.webdriver", reason="the browser tests need selenium (the test extra)")
from selenium.webdriver.support.ui import Select

from .browser_steps import needs_browser, open_page, pointer, settle, until
from .conftest import MANY, PLANAR_H

pytestmark = needs_browser

CAPTURE = """window.captured = [];
download = (blob, name) => blob.text().then((text) => window.captured.push([name, blob.type, text.length, text]));"""


def open_run_pair(browser, server, index: int) -> None:
    open_page(browser, server)
    browser.find_element("id", "tab-runs").click()
    until(lambda: browser.find_elements("id", f"open-pair-{index}"), 30, "the run's pairs")
    browser.find_element("id", f"open-pair-{index}").click()
    until(lambda: browser.execute_script("return slimeWeb.S.matches !== null && !!slimeWeb.S.imgs[1];"), 30,
          "the run's pair")
    browser.find_element("id", "tab-match").click()


def canvas_pixel(browser, pane: int, x: float, y: float) -> np.ndarray:
    return np.array(browser.execute_script(f"""
        const v = slimeWeb.view, dpr = window.devicePixelRatio || 1; v.draw();
        const [sx, sy] = v.toScreen({pane}, {x}, {y});
        return Array.from(v.ctx.getImageData(Math.floor(sx * dpr), Math.floor(sy * dpr), 1, 1).data.slice(0, 3));"""))


def test_ransac_again_overlay_and_exports(browser, server, shots, web_images):
    open_run_pair(browser, server, 1)  # plane0 / plane1: 10 matches, image 1 shifted by 1 px
    Select(browser.find_element("id", "rr-method")).select_by_value("magsac-homography")
    browser.find_element("id", "rr-threshold").send_keys("2")
    browser.find_element("id", "rr-run").click()
    until(lambda: "10 inliers (homography, magsac-homography, 2.0 px, of 10)"
          in browser.find_element("id", "inlier-count").text, 30, "RANSAC again")
    H = np.array(browser.execute_script("return slimeWeb.S.matches.model;"))
    assert np.allclose(H / H[2, 2], [[1, 0, 1], [0, 1, 1], [0, 0, 1]], atol=1e-6)

    # image 0 warped by that H over image 1, every other square of a checkerboard (32 px)
    browser.find_element("id", "show-matches").click()
    Select(browser.find_element("id", "overlay")).select_by_value("checker")
    until(lambda: browser.execute_script("return !!slimeWeb.S.overlay;"), 30, "the overlay")
    browser.execute_script("const v = slimeWeb.view; v.views[1] = {s: 4, tx: 20, ty: 20}; v.draw();")
    plane0 = cv2.imread(str(web_images / "plane0.png"))[:, :, ::-1].astype(int)
    plane1 = cv2.imread(str(web_images / "plane1.png"))[:, :, ::-1].astype(int)
    assert np.abs(canvas_pixel(browser, 1, 12, 12) - plane0[11, 11]).max() <= 3  # a square of image 0, warped
    assert np.abs(canvas_pixel(browser, 1, 44, 12) - plane1[12, 44]).max() <= 3  # a square of image 1
    browser.execute_script("slimeWeb.view.fit(1);")
    settle(browser)
    browser.save_screenshot(str(shots / "overlay-checkerboard.png"))

    browser.execute_script(CAPTURE)
    for button in ("export-json", "export-csv", "export-png"):
        browser.find_element("id", button).click()
    captured = until(lambda: browser.execute_script("return window.captured.length === 3 && window.captured;"),
                     30, "the exports")
    files = {name: (kind, size, text) for name, kind, size, text in captured}
    assert files["view.png"][0] == "image/png" and files["view.png"][1] > 1000
    rows = files["matches.csv"][2].strip().split("\n")
    assert rows[0] == "x0,y0,x1,y1,score,confidence,inlier" and len(rows) == 11
    keypoints = browser.execute_script("return slimeWeb.S.matches.keypoints0;")
    x0, y0, x1, y1, score, confidence, inlier = rows[1].split(",")
    assert [float(x0), float(y0)] == keypoints[0] and inlier == "1"
    assert abs(float(x1) - float(x0) - 1) < 1e-6 and abs(float(y1) - float(y0) - 1) < 1e-6
    assert float(confidence) == 1.0 and float(score) == 0.0
    assert '"count":10' in files["matches.json"][2] and '"kind":"homography"' in files["matches.json"][2]


def test_a_confidence_floor_thins_the_matches(browser, server):
    open_run_pair(browser, server, 0)
    settle(browser)
    assert browser.execute_script("return slimeWeb.S.drawn.visible;") == MANY
    browser.execute_script("const r = document.getElementById('min-confidence'); r.value = 0.9; "
                           "r.dispatchEvent(new Event('input'));")
    settle(browser)
    confident = browser.execute_script("return slimeWeb.S.matches.confidence.filter((c) => c >= 0.9).length;")
    assert 0 < confident < MANY and browser.execute_script("return slimeWeb.S.drawn.visible;") == confident
    assert browser.find_element("id", "min-confidence-value").text == "0.90"


def test_matches_coloured_by_their_error_to_the_annotated_ground_truth(browser, server, shots):
    open_run_pair(browser, server, 1)
    browser.find_element("id", "gt-color").click()  # no ground truth yet: refused, with the reason
    until(lambda: "no ground truth" in browser.find_element("id", "error").text, 10, "the refusal")
    assert not browser.find_element("id", "gt-color").is_selected()
    browser.find_element("id", "tab-annotate").click()
    for k, (x, y) in enumerate([(60, 50), (330, 60), (90, 240), (310, 230), (200, 140)]):
        pointer(browser, 0, x, y)
        px, py = browser.execute_script("const p = slimeWeb.S.annot.pending; return [p.x, p.y];")
        mapped = PLANAR_H @ [px, py, 1.0]
        pointer(browser, 1, mapped[0] / mapped[2], mapped[1] / mapped[2])
        until(lambda k=k: browser.execute_script(f"return slimeWeb.S.annot.pairs.length === {k + 1};"), 30,
              f"pair {k + 1}")
    settle(browser)
    until(lambda: browser.execute_script("return !!slimeWeb.S.annot.fit && !!slimeWeb.S.annot.fit.H;"), 30, "H")
    browser.find_element("id", "tab-match").click()
    browser.find_element("id", "gt-color").click()
    settle(browser)
    errors = np.array(browser.execute_script("return slimeWeb.S.gtErrors.values;"))
    m = browser.execute_script("return [slimeWeb.S.matches.keypoints0, slimeWeb.S.matches.keypoints1];")
    x0, x1 = np.array(m[0]), np.array(m[1])
    mapped = np.c_[x0, np.ones(len(x0))] @ PLANAR_H.T
    truth = np.linalg.norm(mapped[:, :2] / mapped[:, 2:] - x1, axis=1)
    assert len(errors) == 10 and np.abs(errors - truth).max() < 2.0  # the clicked H is PLANAR_H within clicks
    within = int((errors < 3).sum())
    assert browser.find_element("id", "gt-summary").text == f"{within} of 10 within 3 px of the annotation's H (H)"
    browser.save_screenshot(str(shots / "matches-by-ground-truth-error.png"))
