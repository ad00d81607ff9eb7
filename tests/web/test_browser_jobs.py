"""Match jobs in a real headless browser: one job per click, the numba notice while the first match starts,
a reload that finds the running job again and cancels it, no stale result after a cancel or another image,
and the layout at 1400x900 (result, layers and counts in view)."""

from __future__ import annotations

import pytest

pytest.importorskip("fastapi", reason="slime web needs the web extra (FastAPI)")
pytest.importorskip("uvicorn", reason="slime web needs the web extra (uvicorn)")
pytest.importorskip("selenium.webdriver", reason="the browser tests need selenium (the test extra)")
from selenium.webdriver.support.ui import Select

from .browser_steps import needs_browser, open_page, pick, settle, until

pytestmark = needs_browser


def server_jobs(browser) -> list[dict]:
    return browser.execute_async_script("fetch('/api/jobs').then(r => r.json()).then(j => arguments[0](j.jobs));")


def status(browser) -> str:
    return browser.find_element("id", "status").text


def start_match(browser) -> None:
    Select(browser.find_element("id", "preset")).select_by_value("slime-rootsift")
    browser.find_element("id", "opt-scales").send_keys("1,2")
    browser.execute_script("const b = document.getElementById('run'); b.click(); b.click();")  # a double click


def test_one_job_per_click_reattached_after_a_reload_and_cancelled(browser, server, shots):
    open_page(browser, server)
    pick(browser, 0, "left.png")
    pick(browser, 1, "right.png")
    start_match(browser)
    until(lambda: "numba compiles" in status(browser), 60, "the notice of the first match")
    assert len(server_jobs(browser)) == 1
    browser.save_screenshot(str(shots / "job-first-match-notice.png"))

    # a reload finds the running job, shows its progress and cancels it
    job = browser.execute_script("return slimeWeb.S.job;")
    open_page(browser, server, fresh=False)
    assert browser.execute_script("return slimeWeb.S.job;") == job
    until(lambda: status(browser).startswith("running"), 30, "the job's progress")
    assert browser.find_element("id", "jobs-box").get_attribute("open") is not None
    assert browser.find_elements("id", f"job-cancel-{job}")
    browser.save_screenshot(str(shots / "job-reattached.png"))
    browser.find_element("id", "cancel").click()
    until(lambda: status(browser).startswith("cancelled"), 30, "the cancel")
    assert [j["status"] for j in server_jobs(browser)] == ["cancelled"]
    assert not browser.find_element("id", "run").get_attribute("disabled")


def test_a_result_fits_1400x900_and_goes_when_another_image_is_picked(browser, server, shots):
    open_page(browser, server)
    pick(browser, 0, "left.png")
    pick(browser, 1, "right.png")
    start_match(browser)
    until(lambda: browser.find_elements("id", "layer-planes"), 180, "the match and its stages")
    settle(browser)
    browser.save_screenshot(str(shots / "match-layout-1400x900.png"))
    assert browser.execute_script("return [innerWidth, innerHeight];") == [1400, 900]
    bottoms = browser.execute_script(
        "return ['result', 'layers', 'stage-box'].map((id) => document.getElementById(id).getBoundingClientRect()"
        ".bottom);")
    assert max(bottoms) <= 900, bottoms  # in view without scrolling the sidebar
    assert "warning" not in browser.find_element("id", "info").text
    assert browser.find_elements("css selector", "#stage-table tr")

    pick(browser, 1, "plane1.png")  # another image: the last result's table, layers and progress go
    assert browser.find_elements("css selector", "#stage-table tr") == []
    assert browser.find_element("id", "stage-box").get_attribute("hidden") is not None
    assert browser.find_elements("css selector", "#progress li") == [] and status(browser) == ""
    assert browser.find_elements("id", "layer-planes") == []
