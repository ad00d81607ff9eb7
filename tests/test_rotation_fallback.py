"""The rotation fallback: where Slime on a base upright by design finds no match, Slime runs again on Hz+ and
its matches come back with a record of both runs; "off" keeps the empty result; the option is Slime's. Its
real-data gate (a rolled ScanNet pair) is in ``quality/test_learned_gates.py``."""

import json

import numpy as np
import pytest
from conftest import require_learned_weights, rotated_astronaut

import slime_match as sm
from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.rotation_fallback import FALLBACK_BASE

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_rotation_fallback_is_a_slime_option():
    assert make_config("slime-aliked").rotation_fallback == "auto"
    assert make_config("slime-aliked", rotation_fallback="off").rotation_fallback == "off"
    with pytest.raises(ConfigError, match="is a Slime option"):
        make_config("aliked-lg", rotation_fallback="off")
    with pytest.raises(ConfigError, match="rotation_fallback"):
        make_config("slime-aliked", rotation_fallback="always")


def test_an_empty_result_of_an_upright_base_runs_slime_on_hz_plus():
    """Image 1 blank: ALIKED finds nothing to match, so the fallback runs, finds nothing either, and the empty
    result stands; the record keeps the fallback's counts and warnings."""
    require_learned_weights("aliked-n16", "lightglue-aliked")
    image0, _, _ = rotated_astronaut()
    blank = np.full_like(image0, 0.5)
    result = sm.match(image0, blank, "slime-aliked", views="off", device="cpu")
    record = result.summary["decisions"]["rotation_fallback"]
    assert len(result.scores) == 0 and not record["kept"]
    assert record["base"] == FALLBACK_BASE and record["first_base"] == "aliked-lg"
    assert record["pipeline"]["base"] == FALLBACK_BASE
    other = record["other_run"]
    assert other["base"] == FALLBACK_BASE and other["counts"]["ftheta_matches"] == 0
    assert any("found no match" in warning for warning in other["warnings"])
    assert "holds 0 matches in F^theta (< views.min_support 100" in result.summary["warnings"][-1]
    assert result.summary["counts"]["block_planes"] == 0 and result.summary["seconds"]["rotation_fallback"] > 0
    json.dumps(result.summary)  # the record is part of summary.json

    off = sm.match(image0, blank, "slime-aliked", views="off", device="cpu", rotation_fallback="off")
    assert len(off.scores) == 0 and "rotation_fallback" not in off.summary["decisions"]


def test_slime_on_hz_plus_takes_no_fallback():
    image0, image1, _ = rotated_astronaut()
    blank = np.full_like(image1, 0.5)
    result = sm.match(image0, blank, "slime", descriptor="rootsift", views="off", device="cpu")
    assert len(result.scores) == 0 and "rotation_fallback" not in result.summary["decisions"]
