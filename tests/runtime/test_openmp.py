"""The OpenMP spin default: set on import before torch, never over the user's choice or after torch."""

import os
import subprocess
import sys

import pytest

from slime_match._runtime.openmp import SPIN_COUNT


def _spin_after(code: str, **env: str) -> str:
    """GOMP_SPINCOUNT seen by a fresh interpreter after ``code`` ('unset' when absent)."""
    clean = {k: v for k, v in os.environ.items() if k not in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")}
    out = subprocess.run(
        [sys.executable, "-c", f"{code}; import os; print(os.environ.get('GOMP_SPINCOUNT', 'unset'))"],
        env={**clean, **env},
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.strip()


@pytest.mark.parametrize(
    ("code", "env", "expected"),
    [
        ("import slime_match", {}, SPIN_COUNT),
        ("import slime_match", {"GOMP_SPINCOUNT": "7"}, "7"),
        ("import slime_match", {"OMP_WAIT_POLICY": "PASSIVE"}, "unset"),
        ("import torch; import slime_match", {}, "unset"),  # too late: libgomp has read its settings
    ],
)
def test_spin_default(code, env, expected):
    assert _spin_after(code, **env) == expected
