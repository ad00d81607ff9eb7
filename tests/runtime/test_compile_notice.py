"""The notice while numba compiles the package's loops (a first run), and its silence when they come from the
on-disk cache."""

import os
import subprocess
import sys

from slime_match._runtime.compile_notice import NOTICE

CALL_A_LOOP = ("import numpy as np; from slime_match._runtime.compile_notice import install; install(); "
               "from slime_match.matching.dtm_kernels import unique_inverse; "
               "print(unique_inverse(np.array([3, 1, 3], np.int64))[1])")


def test_notice_on_compiling_only(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}  # an empty cache: the loop must be compiled
    runs = [subprocess.run([sys.executable, "-c", CALL_A_LOOP], env=env, capture_output=True, text=True, check=True)
            for _ in range(2)]
    assert all(run.stdout.strip() == "[1 0 1]" for run in runs)
    assert runs[0].stderr.count(NOTICE) == 1  # compiled: the notice, once
    assert NOTICE not in runs[1].stderr  # loaded from the cache the first run wrote


def test_no_notice_without_the_listener(tmp_path):
    """Importing the package installs nothing: a loop compiled without ``install`` is silent."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    code = CALL_A_LOOP.replace("from slime_match._runtime.compile_notice import install; install(); ", "")
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[1 0 1]" and NOTICE not in run.stderr
