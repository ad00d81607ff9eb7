"""Steps of the browser tests: wait for the page, pick images, click image points, answer the page's
questions."""

from __future__ import annotations

import shutil
import socket
import time

import pytest

webdriver = pytest.importorskip("selenium.webdriver", reason="the browser tests need selenium (the test extra)")
from selenium.common.exceptions import NoAlertPresentException
from selenium.webdriver.common.actions.action_builder import ActionBuilder
from selenium.webdriver.support.ui import Select

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")
needs_browser = pytest.mark.skipif(CHROMIUM is None or DRIVER is None,
                                   reason="needs Debian's chromium and chromium-driver (apt-get install chromium "
                                          "chromium-driver; .ci/run installs them)")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def until(condition, timeout: float = 60.0, what: str = "the page"):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


def open_page(browser, server, fresh: bool = True):
    """Load the page; ``fresh``: with nothing kept in the browser (no drafts, no last pair)."""
    if fresh:
        browser.get(server + "/static/style.css")  # the page's origin, without running the page
        browser.execute_script("localStorage.clear();")
    browser.get(server + "/")
    until(lambda: browser.execute_script("return document.body.dataset.ready === '1'"), 60, "the page to load")


def answer_confirm(browser, accept: bool, timeout: float = 10.0) -> str:
    """Answer the page's question (window.confirm); its text."""
    def question():
        try:
            return browser.switch_to.alert
        except NoAlertPresentException:
            return None
    alert = until(question, timeout, "the page's question")
    text = alert.text
    if accept:
        alert.accept()
    else:
        alert.dismiss()
    return text


def pick(browser, side: int, name: str) -> None:
    until(lambda: any(o.get_attribute("value") == name
                      for o in browser.find_elements("css selector", f"#img{side}-path option")), 10,
          f"{name} in the list")
    Select(browser.find_element("id", f"img{side}-path")).select_by_value(name)
    until(lambda: browser.execute_script(f"return !!slimeWeb.S.imgs[{side}] && "
                                         f"slimeWeb.S.images[{side}].path === '{name}'"), 10, f"{name} shown")


def settle(browser) -> None:
    until(lambda: not browser.execute_script("return slimeWeb.busy()"), 60, "the page to settle")
    browser.execute_script("slimeWeb.view.draw()")


def pointer(browser, pane: int, x: float, y: float, click: bool = True) -> None:
    """Move to (and click) image point (x, y) of a pane, in viewport pixels (rounded)."""
    left, top = browser.execute_script("const r = slimeWeb.view.canvas.getBoundingClientRect(); "
                                       "return [r.left, r.top];")
    sx, sy = browser.execute_script(f"return slimeWeb.screenOf({pane}, {x}, {y});")
    actions = ActionBuilder(browser)
    actions.pointer_action.move_to_location(round(left + sx), round(top + sy))
    if click:
        actions.pointer_action.click()
    actions.perform()
