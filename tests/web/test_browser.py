"""``slime web`` in a real headless browser (Debian's Chromium and chromium-driver through Selenium): match two
images and see the count and Slime's stage layers while the page stays responsive, draw 20,000 matches with
smooth zoom and pan, and annotate a planar pair whose homography is known.

The screenshots go to ``$SLIME_WEB_SCREENSHOTS`` when set, else to a temporary folder named in the output.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("fastapi", reason="slime web needs the web extra (FastAPI)")
pytest.importorskip("uvicorn", reason="slime web needs the web extra (uvicorn)")
pytest.importorskip("selenium.webdriver", reason="the browser tests need selenium (the test extra)")
from selenium.webdriver.common.actions.action_builder import ActionBuilder
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import Select

from slime_match.eval.datasets.planar import read_planar
from slime_match.eval.datasets.wxbs import read_wxbs

from .browser_steps import needs_browser, open_page, pick, pointer, settle, until
from .conftest import MANY, PLANAR_H, SECOND_H

pytestmark = needs_browser


def test_match_two_images_see_count_and_stage_layers(browser, server, shots):
    (shots / "match-running.png").unlink(missing_ok=True)
    open_page(browser, server)
    pick(browser, 0, "left.png")
    pick(browser, 1, "right.png")
    Select(browser.find_element("id", "preset")).select_by_value("slime-rootsift")
    browser.find_element("id", "opt-scales").send_keys("1,2")
    Select(browser.find_element("id", "opt-ransac")).select_by_value("fundamental")
    browser.find_element("id", "run").click()
    until(lambda: browser.execute_script("return slimeWeb.S.job !== null"), 60, "the job")

    # the page stays interactive while the worker matches: redraws and requests answer at once
    until(lambda: "running" in browser.find_element("id", "status").text, 60, "the job to run")
    probes = []
    while "running" in browser.find_element("id", "status").text and len(probes) < 40:
        start = time.perf_counter()
        frames = browser.execute_script("return slimeWeb.measureFrames(10);")
        took = browser.execute_async_script("const done = arguments[0], t0 = performance.now(); "
                                            "fetch('/api/info').then(() => done(performance.now() - t0));")
        probes.append((time.perf_counter() - start, frames["max"], took))
        if len(browser.find_elements("css selector", "#progress li")) >= 3 and not (shots / "match-running.png").exists():
            browser.save_screenshot(str(shots / "match-running.png"))
        time.sleep(0.3)
    assert probes, "the match ended before the page could be probed"
    print(f"during the match: {len(probes)} probes, slowest round trip {max(p[0] for p in probes):.3f} s, "
          f"slowest frame {max(p[1] for p in probes):.1f} ms, slowest /api/info {max(p[2] for p in probes):.0f} ms")
    assert max(p[0] for p in probes) < 1.0 and max(p[2] for p in probes) < 500

    count = until(lambda: browser.find_element("id", "match-count").text, 120, "the match count")
    job = browser.execute_script("return slimeWeb.S.job;")
    state = browser.execute_async_script(f"fetch('/api/jobs/{job}').then(r => r.json()).then(arguments[0]);")
    assert state["status"] == "done" and count == f"{state['counts']['matches']} matches"
    assert state["counts"]["matches"] > 100 and 0 < state["counts"]["inliers"] <= state["counts"]["matches"]
    assert f"{state['counts']['inliers']} inliers (fundamental)" in browser.find_element("id", "inlier-count").text
    stages = [li.text for li in browser.find_elements("css selector", "#progress li")]
    assert any(s.startswith("features:") for s in stages) and any(s.startswith("global_dtm:") for s in stages)

    until(lambda: browser.find_elements("id", "layer-planes"), 60, "the stage layers")
    browser.find_element("css selector", "#decisions summary").click()  # the adaptive steps, in words
    decisions = [li.text for li in browser.find_elements("css selector", "#decisions-list li")]
    assert any(d.startswith("simulated views (") for d in decisions), decisions
    assert any(d.startswith("epipolar vote: ") for d in decisions), decisions
    settle(browser)
    browser.save_screenshot(str(shots / "match-done.png"))
    # a keypoint clicked shows its match
    x, y = browser.execute_script("return slimeWeb.S.matches.keypoints0[0];")
    pointer(browser, 0, x, y)
    until(lambda: "match(es)" in browser.find_element("id", "info").text, 60, "the clicked match")
    assert 0 in browser.execute_script("return slimeWeb.S.selected;")
    # a stage layer toggled on draws; hovering a plane shows its homography
    browser.find_element("id", "show-matches").click()
    browser.find_element("id", "layer-planes").click()
    assert browser.execute_script("return slimeWeb.S.layers.planes === true;")
    px, py = browser.execute_script("return slimeWeb.S.stages.layers.planes.xy0[0];")
    pointer(browser, 0, px, py, click=False)
    until(lambda: "H (image 0 -> 1)" in browser.find_element("id", "info").text, 60, "the plane's homography")
    settle(browser)
    browser.save_screenshot(str(shots / "stage-planes.png"))
    browser.find_element("id", "layer-planes").click()
    browser.find_element("id", "layer-tiles").click()
    browser.find_element("id", "layer-ftheta").click()
    fx, fy = browser.execute_script("return slimeWeb.S.stages.layers.ftheta.xy0[0];")
    pointer(browser, 0, fx, fy, click=False)  # a set of F^theta: its matches, tile pair and plane
    until(lambda: "of ftheta, tile pair" in browser.find_element("id", "info").text, 60, "the hovered set")
    settle(browser)
    browser.save_screenshot(str(shots / "stage-tiles-ftheta.png"))
    assert browser.execute_script("return slimeWeb.S.layers.tiles && !slimeWeb.S.layers.planes;")


def test_twenty_thousand_matches_zoom_and_pan_smoothly(browser, server, shots):
    open_page(browser, server)
    browser.find_element("id", "tab-runs").click()
    until(lambda: browser.find_elements("id", "open-pair-0"), 60, "the run's pairs")
    rows = browser.find_elements("css selector", "#run-pairs tbody tr")
    assert len(rows) == 4 and "failed" in rows[2].text
    browser.find_element("id", "open-pair-0").click()
    until(lambda: browser.find_element("id", "match-count").text == f"{MANY} matches", 60, "the run's pair")
    settle(browser)
    frames = browser.execute_script("return slimeWeb.measureFrames(40);")
    print(f"{MANY} matches: frame time mean {frames['mean']:.1f} ms, median {frames['median']:.1f} ms, "
          f"max {frames['max']:.1f} ms")
    assert frames["median"] < 50
    drawn = browser.execute_script("return slimeWeb.S.drawn;")
    assert drawn["visible"] == MANY and drawn["lineStride"] > 1  # thinned
    # the wheel zooms the image under the pointer; zoomed in, fewer matches are in view and fewer thinned
    scale = browser.execute_script("return slimeWeb.view.views[0].s;")
    pointer(browser, 0, 185, 125, click=False)
    for _ in range(3):
        browser.execute_script("const c = slimeWeb.view.canvas, r = c.getBoundingClientRect(), "
                               "[x, y] = slimeWeb.screenOf(0, 185, 125); c.dispatchEvent(new WheelEvent('wheel', "
                               "{deltaY: -120, clientX: r.left + x, clientY: r.top + y, bubbles: true}));")
    settle(browser)
    assert browser.execute_script("return slimeWeb.view.views[0].s;") > 1.5 * scale
    zoomed = browser.execute_script("return slimeWeb.S.drawn;")
    assert zoomed["visible"] < MANY
    x, y = browser.execute_script("return slimeWeb.S.matches.keypoints0[0];")
    browser.execute_script("slimeWeb.view.fit(0); slimeWeb.view.draw();")
    pointer(browser, 0, x, y)
    until(lambda: "match(es)" in browser.find_element("id", "info").text, 60, "the clicked match")
    settle(browser)
    browser.save_screenshot(str(shots / "many-matches.png"))
    # a plane found in a simulated view: its image-0 block drawn as the view's outline, the view named
    until(lambda: browser.find_elements("id", "layer-planes"), 60, "the stage layers")
    browser.find_element("id", "show-matches").click()
    browser.find_element("id", "layer-planes").click()
    px, py = browser.execute_script("const L = slimeWeb.S.stages.layers.planes; "
                                    "return L.xy0[L.label.indexOf(3)];")
    pointer(browser, 0, px, py, click=False)
    until(lambda: "simulated view of tilt 4 at 18 deg" in browser.find_element("id", "info").text, 60,
          "the view plane's hover")
    assert "block pair 7 / 1" in browser.find_element("id", "info").text
    settle(browser)
    browser.save_screenshot(str(shots / "stage-view-plane.png"))


def test_annotate_a_planar_pair_and_save_it_for_the_bench(browser, server, shots, annotations, web_images):
    open_page(browser, server)
    browser.find_element("id", "tab-annotate").click()
    pick(browser, 0, "plane0.png")
    browser.find_element("id", "img1-upload").send_keys(str(web_images / "plane1.png"))  # image 1 uploaded
    until(lambda: browser.execute_script("const r = slimeWeb.S.images[1]; return !!slimeWeb.S.imgs[1] && !!r && "
                                         "r.root === 'uploads' && r.path.endsWith('plane1.png');"), 10, "the upload")
    targets = [(60, 50), (330, 60), (200, 140), (90, 240), (310, 230), (150, 80), (260, 180), (120, 170)]
    for k, (x, y) in enumerate(targets):
        pointer(browser, 0, x, y)
        x0, y0 = browser.execute_script("const p = slimeWeb.S.annot.pending; return [p.x, p.y];")
        mapped = PLANAR_H @ [x0, y0, 1.0]
        pointer(browser, 1, mapped[0] / mapped[2], mapped[1] / mapped[2])
        until(lambda k=k: browser.execute_script(f"return slimeWeb.S.annot.pairs.length === {k + 1};"), 60,
              f"pair {k + 1}")
    settle(browser)
    assert len(browser.find_elements("css selector", "#ann-pairs tbody tr")) == 8
    until(lambda: "H: fitted" in browser.find_element("id", "ann-status").text, 60, "the fit")
    # eight pairs on one plane leave F undetermined: refused, with the reason
    assert "F refused: 8 of the 8 pairs lie on one plane" in browser.find_element("id", "ann-status").text
    assert browser.execute_script("return slimeWeb.S.annot.fit.F;") is None

    # saved as a planar pair (H): the bench's reader reads it back
    name = browser.find_element("id", "ann-name")
    name.clear()
    name.send_keys("astro")
    browser.find_element("id", "ann-save").click()
    until(lambda: "saved (planar)" in browser.find_element("id", "ann-status").text, 60, "the planar save")
    [planar] = read_planar(annotations / "planar")
    corners = np.array([[0, 0, 1], [399, 0, 1], [0, 299, 1], [399, 299, 1]], float)
    ours, true = corners @ planar.H.T, corners @ PLANAR_H.T
    assert np.linalg.norm(ours[:, :2] / ours[:, 2:] - true[:, :2] / true[:, 2:], axis=1).max() < 3.0

    # a second plane (a new set) determines F
    browser.find_element("id", "ann-new-set").click()
    second = [(100, 110), (280, 100), (170, 220), (320, 160)]
    for k, (x, y) in enumerate(second):
        pointer(browser, 0, x, y)
        x0, y0 = browser.execute_script("const p = slimeWeb.S.annot.pending; return [p.x, p.y];")
        mapped = SECOND_H @ [x0, y0, 1.0]
        pointer(browser, 1, mapped[0] / mapped[2], mapped[1] / mapped[2])
        until(lambda k=k: browser.execute_script(f"return slimeWeb.S.annot.pairs.length === {k + 9};"), 60,
              f"pair {k + 9}")
    settle(browser)
    until(lambda: "F: fitted" in browser.find_element("id", "ann-status").text, 60, "the fit of F")
    residuals = [row.find_elements("css selector", "td")[5].text
                 for row in browser.find_elements("css selector", "#ann-pairs tbody tr")]
    assert len(residuals) == 12 and all(float(r) < 3.0 for r in residuals)  # each pair's F residual (px)

    # the cursor over a new point of image 0: its H reprojection (set 0) and its epipolar line in image 1
    browser.execute_script("slimeWeb.S.annot.set = 0;")
    probe = np.array([230.0, 110.0])
    pointer(browser, 0, *probe, click=False)
    settle(browser)
    drawn = browser.execute_script("const a = slimeWeb.S.annot; return [a.reprojected, a.epiline, a.cursor];")
    reprojected, epiline, cursor = drawn
    truth = PLANAR_H @ [cursor["x"], cursor["y"], 1.0]
    truth = truth[:2] / truth[2]
    assert reprojected["pane"] == 1 and np.linalg.norm(np.array(reprojected["point"]) - truth) < 2.0
    a, b, c = epiline["line"]
    assert epiline["pane"] == 1 and abs(a * truth[0] + b * truth[1] + c) / np.hypot(a, b) < 3.0
    browser.save_screenshot(str(shots / "annotate.png"))

    # saved as a WxBS pair (F): the bench's reader reads its 12 pairs
    browser.find_element("id", "model-F").click()
    browser.find_element("id", "ann-save").click()
    until(lambda: "saved (wxbs)" in browser.find_element("id", "ann-status").text, 60, "the WxBS save")
    [pair] = read_wxbs(annotations / "wxbs")
    corrs = pair.corrs
    errors = []
    for rows, H in ((corrs[:8], PLANAR_H), (corrs[8:], SECOND_H)):
        mapped = np.c_[rows[:, :2], np.ones(len(rows))] @ H.T
        errors += np.linalg.norm(mapped[:, :2] / mapped[:, 2:] - rows[:, 2:], axis=1).tolist()
    assert corrs.shape == (12, 4) and max(errors) < 1.5, errors

    # move a point, undo it, delete one, undo
    before = browser.execute_script("return slimeWeb.S.annot.pairs[0].x0;")
    pointer(browser, 0, *targets[0], click=False)
    actions = ActionBuilder(browser)
    actions.pointer_action.pointer_down()
    actions.pointer_action.move_by(25, 10)
    actions.pointer_action.pointer_up()
    actions.perform()
    moved = browser.execute_script("return slimeWeb.S.annot.pairs[0].x0;")
    assert moved > before + 10
    browser.find_element("id", "ann-undo").click()
    assert browser.execute_script("return slimeWeb.S.annot.pairs[0].x0;") == before
    scale = browser.execute_script("return slimeWeb.view.views[0].s;")
    browser.find_element("id", "view").send_keys(Keys.ARROW_RIGHT, Keys.ARROW_RIGHT)  # nudged 2 screen px
    assert abs(browser.execute_script("return slimeWeb.S.annot.pairs[0].x0;") - (before + 2 / scale)) < 1e-6
    browser.find_element("id", "ann-undo").click()
    browser.find_element("id", "ann-undo").click()
    browser.find_element("id", "ann-delete").click()  # pair 1 is selected since it was grabbed
    assert browser.execute_script("return slimeWeb.S.annot.pairs.length;") == 11
    browser.find_element("id", "ann-undo").click()
    assert browser.execute_script("return slimeWeb.S.annot.pairs.length;") == 12


def test_points_sit_on_the_pixel_centres_the_library_uses(browser, server, web_images):
    """A point (x, y) is drawn (and clicked) over the pixel whose centre is (x, y), as the matcher's keypoints
    are: zoomed 12x, the canvas under (x - 0.3, y - 0.3) and (x + 0.3, y + 0.3) shows pixel (x, y)."""
    import cv2

    open_page(browser, server)
    pick(browser, 0, "plane0.png")
    image = cv2.imread(str(web_images / "plane0.png"))[:, :, ::-1].astype(int)
    jump = np.abs(np.diff(image, axis=0))[:, :-1].sum(2) + np.abs(np.diff(image, axis=1))[:-1].sum(2)
    y, x = np.unravel_index(np.argmax(jump[100:200, 100:300]), (100, 200))
    x, y = int(x) + 101, int(y) + 101  # a pixel unlike its upper-left neighbours
    seen = browser.execute_script(f"""
        const v = slimeWeb.view;
        v.views[0] = {{ s: 12, tx: v.paneWidth() / 2 - {x} * 12, ty: v.height / 2 - {y} * 12 }};
        v.draw();
        const dpr = window.devicePixelRatio || 1;
        return [[{x} - 0.3, {y} - 0.3], [{x} + 0.3, {y} + 0.3]].map(([px, py]) => {{
          const [sx, sy] = v.toScreen(0, px, py);
          return Array.from(v.ctx.getImageData(Math.floor(sx * dpr), Math.floor(sy * dpr), 1, 1).data.slice(0, 3));
        }});""")
    assert np.abs(np.array(seen) - image[y, x]).max() <= 3, (seen, image[y, x], image[y - 1, x - 1])
