"""The code version that predictions record: its format, and how it follows the git checkout."""

import re

import pytest

from slime_match.eval.code_version import code_version


def test_code_version_format():
    assert re.fullmatch(r"\d+\.\d+\.\d+(\+g[0-9a-f]{4,40}(\.dirty)?)?", code_version())


@pytest.mark.parametrize(
    "git, expected",
    [
        ({}, "0.1.0"),  # no git, or not a checkout
        ({"log": "abc1234"}, "0.1.0"),  # a checkout that does not track the package (site-packages)
        ({"log": "abc1234", "ls-files": "__init__.py", "status": ""}, "0.1.0+gabc1234"),
        ({"log": "abc1234", "ls-files": "__init__.py", "status": " M x.py"}, "0.1.0+gabc1234.dirty"),
    ],
)
def test_code_version_from_git(monkeypatch, git, expected):
    from slime_match.eval import code_version as cv

    monkeypatch.setattr(cv.slime_match, "__version__", "0.1.0")
    monkeypatch.setattr(cv, "_git", lambda command, *_: git.get(command))
    cv.code_version.cache_clear()
    try:
        assert cv.code_version() == expected
    finally:
        cv.code_version.cache_clear()
