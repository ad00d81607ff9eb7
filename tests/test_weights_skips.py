"""Tests that need network weights skip, naming them, when the weights are neither cached nor downloadable, and
fail instead under SLIME_REQUIRE_WEIGHTS=1 (what CI sets)."""

import socket
import textwrap
from pathlib import Path

import pytest

pytest_plugins = ["pytester"]

CONFTEST = Path(__file__).with_name("conftest.py")

INNER_CONFTEST = f"""
import importlib.util

spec = importlib.util.spec_from_file_location("outer_conftest", {str(CONFTEST)!r})
outer = importlib.util.module_from_spec(spec)
spec.loader.exec_module(outer)
pytest_runtest_setup = outer.pytest_runtest_setup
pytest_runtest_call = outer.pytest_runtest_call
require_weights = outer.require_weights
"""

INNER_TESTS = """
import pytest

from slime_match.features.weights import load_model


@pytest.fixture(scope="module")
def network():
    return load_model("tfeat")


def test_in_a_fixture(network):
    pass


def test_in_the_test():
    load_model("affnet")


def test_by_name():
    from conftest import require_weights

    require_weights("orinet")


def test_weight_free():
    pass
"""


@pytest.fixture
def offline_without_weights(tmp_path, monkeypatch):
    """An empty weights cache and no download host that resolves."""

    def no_dns(host, *args, **kwargs):
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "empty_cache"))
    monkeypatch.setattr(socket, "getaddrinfo", no_dns)


def _run(pytester, monkeypatch, require: str):
    monkeypatch.setenv("SLIME_REQUIRE_WEIGHTS", require)
    pytester.makeconftest(INNER_CONFTEST)
    pytester.makepyfile(test_inner=textwrap.dedent(INNER_TESTS))
    return pytester.runpytest("-rsf", "-p", "no:cacheprovider")


def test_missing_weights_skip_with_a_reason_naming_them(pytester, monkeypatch, offline_without_weights):
    result = _run(pytester, monkeypatch, "")
    result.assert_outcomes(passed=1, skipped=3)
    text = result.stdout.str()
    assert "tfeat weights 'tfeat-liberty.params' are not in" in text
    assert "affnet weights 'AffNet.pth' are not in" in text
    assert "needs the orinet weights, which are not cached" in text


def test_ci_turns_a_missing_weights_skip_into_a_failure(pytester, monkeypatch, offline_without_weights):
    result = _run(pytester, monkeypatch, "1")
    result.assert_outcomes(passed=1, failed=2, errors=1)
    assert result.stdout.str().count("SLIME_REQUIRE_WEIGHTS is set") >= 3
