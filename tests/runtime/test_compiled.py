"""The compiled loops: the warm-up groups, the notice while numba compiles them (a first run), and its
silence when they come from the on-disk cache."""

import os
import subprocess
import sys

import pytest

from slime_match._runtime.compiled import GROUPS, NOTICE, warm_up
from slime_match.config import make_config
from slime_match.pipelines import make_base_pipeline

CALL_A_LOOP = ("import numpy as np; from slime_match._runtime.compiled import install_notice; install_notice(); "
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
    """Importing the package installs nothing: a loop compiled without ``install_notice`` is silent."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    code = CALL_A_LOOP.replace("from slime_match._runtime.compiled import install_notice; install_notice(); ", "")
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[1 0 1]" and NOTICE not in run.stderr


def test_warm_up_loads_named_groups_and_refuses_others():
    assert set(warm_up("blob", "ransac")) == {"blob", "ransac"}
    with pytest.raises(ValueError, match="unknown group of compiled loops 'sift': one of patches, blob, dtm, ransac"):
        warm_up("sift")


def test_pipelines_name_the_loops_they_run_on_the_cpu():
    weight_free = {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift"}
    hz = make_base_pipeline(make_config("hz+", **weight_free).base)
    assert hz.kernel_groups() == ("patches", "blob", "dtm") and set(hz.kernel_groups()) <= set(GROUPS)
    assert make_base_pipeline(make_config("rootsift").base).kernel_groups() == ("blob",)


def test_compile_seconds_count_compiling_not_loading_from_the_cache(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    code = CALL_A_LOOP + "; from slime_match._runtime.compiled import compile_seconds; print(compile_seconds())"
    runs = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
            for _ in range(2)]
    first, second = (float(run.stdout.split()[-1]) for run in runs)
    assert first > 0.05 and second < first / 5  # the second run loads the loop from the cache the first wrote

