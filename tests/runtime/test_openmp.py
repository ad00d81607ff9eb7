"""The OpenMP spin default: set by the ``slime`` command before torch, never over the user's choice or after
torch; importing the package leaves the process as it is."""

import os
import subprocess
import sys

import pytest

from slime_match._runtime.openmp import SPIN_COUNT


def _spin_after(code: str, **env: str) -> str:
    """GOMP_SPINCOUNT seen by a fresh interpreter after ``code`` ('unset' when absent)."""
    clean = {k: v for k, v in os.environ.items() if k not in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")}
    out = subprocess.run(
        [sys.executable, "-c", f"{code}\nimport os\nprint(os.environ.get('GOMP_SPINCOUNT', 'unset'))"],
        env={**clean, **env},
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.strip()


CLI = ("import contextlib, io\nfrom slime_match.cli import main\n"  # ``slime viz --help``: the parser, no work
       "with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n    main(['viz', '--help'])")


@pytest.mark.parametrize(
    ("code", "env", "expected"),
    [
        (CLI, {}, SPIN_COUNT),
        (CLI, {"GOMP_SPINCOUNT": "7"}, "7"),
        (CLI, {"OMP_WAIT_POLICY": "PASSIVE"}, "unset"),
        ("import torch\n" + CLI, {}, "unset"),  # too late: libgomp has read its settings
        ("import slime_match; slime_match.Matcher", {}, "unset"),  # the library leaves the process as it is
    ],
)
def test_spin_default(code, env, expected):
    assert _spin_after(code, **env) == expected


def test_import_changes_nothing():
    """``import slime_match`` loads neither torch nor numba and registers no listener; the API loads on use."""
    code = ("import sys, slime_match\nprint('torch' in sys.modules, 'numba' in sys.modules)\n"
            "slime_match.make_config\nprint('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False", "True"]
