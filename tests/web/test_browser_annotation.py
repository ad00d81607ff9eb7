"""The annotation tool's life cycle in a real headless browser: annotations belong to their image pair (kept
when another pair is shown, restored when it comes back and after a reload, saved with their own images),
leaving a pair with unsaved points asks first, and a double-click only fits the view."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("fastapi", reason="slime web needs the web extra (FastAPI)")
pytest.importorskip("uvicorn", reason="slime web needs the web extra (uvicorn)")
pytest.importorskip("selenium.webdriver", reason="the browser tests need selenium (the test extra)")
from selenium.common.exceptions import NoAlertPresentException
from selenium.webdriver.common.actions.action_builder import ActionBuilder
from selenium.webdriver.support.ui import Select

from .browser_steps import answer_confirm, needs_browser, open_page, pick, pointer, settle, until
from .conftest import PLANAR_H

pytestmark = needs_browser


def annotated(browser) -> list[list[float]]:
    return browser.execute_script("return slimeWeb.S.annot.pairs.map((p) => [p.x0, p.y0, p.x1, p.y1]);")


def add_pairs(browser, points, first: int = 0) -> None:
    for k, (x, y) in enumerate(points):
        pointer(browser, 0, x, y)
        mapped = PLANAR_H @ [x, y, 1.0]
        pointer(browser, 1, mapped[0] / mapped[2], mapped[1] / mapped[2])
        until(lambda k=k: browser.execute_script(f"return slimeWeb.S.annot.pairs.length === {first + k + 1};"),
              30, f"pair {first + k + 1}")


def no_question(browser) -> bool:
    try:
        browser.switch_to.alert.text  # noqa: B018  (raises when the page asks nothing)
    except NoAlertPresentException:
        return True
    return False


def test_annotations_belong_to_their_pair_across_switches_reloads_and_saves(browser, server, shots, annotations):
    open_page(browser, server)
    browser.find_element("id", "tab-annotate").click()
    pick(browser, 0, "plane0.png")
    pick(browser, 1, "plane1.png")
    add_pairs(browser, [(60, 50), (330, 60), (200, 140)])
    first = annotated(browser)
    assert "unsaved" in browser.find_element("id", "ann-status").text
    table = browser.execute_script("return document.getElementById('ann-pairs').getBoundingClientRect().bottom;")
    assert table <= 900  # the pairs' table in view at 1400x900

    # a run's pair opened from the Runs tab: the page asks, then shows that pair with no annotation
    browser.find_element("id", "tab-runs").click()
    until(lambda: browser.find_elements("id", "open-pair-0"), 30, "the run's pairs")
    browser.find_element("id", "open-pair-0").click()
    assert "3 unsaved annotated pairs" in answer_confirm(browser, accept=True)
    until(lambda: browser.execute_script("return slimeWeb.S.images[1] && slimeWeb.S.images[1].path === "
                                         "'right.png';"), 30, "the run's pair")
    browser.find_element("id", "tab-annotate").click()
    assert annotated(browser) == [] and browser.find_elements("css selector", "#ann-pairs tbody tr") == []
    settle(browser)
    browser.save_screenshot(str(shots / "annotate-other-pair.png"))

    # back to the first pair: its points come back (nothing unsaved on the run's pair: no question)
    pick(browser, 0, "plane0.png")
    pick(browser, 1, "plane1.png")
    assert no_question(browser) and annotated(browser) == first

    # a reload shows the last pair with its draft
    open_page(browser, server, fresh=False)
    assert browser.execute_script("return slimeWeb.S.images.map((r) => r.path);") == ["plane0.png", "plane1.png"]
    browser.find_element("id", "tab-annotate").click()
    assert np.allclose(annotated(browser), first) and "unsaved" in browser.find_element("id", "ann-status").text
    settle(browser)
    browser.save_screenshot(str(shots / "annotate-draft-restored.png"))

    # leaving it asks; answering no keeps the pair and its points
    Select(browser.find_element("id", "img1-path")).select_by_value("right.png")
    assert "unsaved" in answer_confirm(browser, accept=False)
    until(lambda: browser.find_element("id", "img1-path").get_attribute("value") == "plane1.png", 10,
          "the picker back on the shown image")
    assert browser.execute_script("return slimeWeb.S.images[1].path;") == "plane1.png"
    assert len(annotated(browser)) == 3

    # saved with its own images; once saved, leaving it asks nothing
    add_pairs(browser, [(90, 240)], first=3)
    name = browser.find_element("id", "ann-name")
    name.clear()
    name.send_keys("lifecycle")
    browser.find_element("id", "ann-save").click()
    until(lambda: "saved (planar)" in browser.find_element("id", "ann-status").text, 30, "the save")
    record = json.loads((annotations / "planar" / "lifecycle_annotation.json").read_text())
    assert (record["image0"], record["image1"], len(record["pairs"])) == ("plane0.png", "plane1.png", 4)
    pick(browser, 1, "right.png")
    assert no_question(browser) and annotated(browser) == []


def test_a_double_click_fits_the_view_and_selects_or_places_nothing(browser, server):
    open_page(browser, server)
    browser.find_element("id", "tab-runs").click()
    until(lambda: browser.find_elements("id", "open-pair-1"), 30, "the run's pairs")
    browser.find_element("id", "open-pair-1").click()
    until(lambda: browser.execute_script("return slimeWeb.S.matches !== null;"), 30, "the run's pair")
    x, y = browser.execute_script("return slimeWeb.S.matches.keypoints0[0];")
    browser.execute_script("slimeWeb.view.zoom(0, 1.7, 20, 20); slimeWeb.view.draw();")
    pointer(browser, 0, x, y, click=False)
    actions = ActionBuilder(browser)
    actions.pointer_action.double_click()
    actions.perform()
    until(lambda: browser.execute_script("const v = slimeWeb.view; return Math.abs(v.views[0].s - "
                                         "Math.min(v.paneWidth() / 400, v.height / 300) * 0.98) < 1e-9;"), 10,
          "the fitted view")
    assert browser.execute_script("return slimeWeb.S.selected;") is None

    browser.find_element("id", "tab-annotate").click()
    pointer(browser, 0, 200, 150, click=False)
    actions = ActionBuilder(browser)
    actions.pointer_action.double_click()
    actions.perform()
    settle(browser)
    assert browser.execute_script("return slimeWeb.S.annot.pending;") is None and annotated(browser) == []
