"""The rotation fallback: where Slime on a base upright by design finds no match, or keeps views without its
plain matches measuring a tilt, Slime runs again on Hz+ (the latter first on its plain stage) and its matches
come back, where they hold more geometry, with a record of both runs ("edge-on" only for the latter); "off"
never runs it; the option is Slime's. Its real-data gates (a rolled ScanNet pair; graf seen at 85 degrees under
"edge-on") are in ``quality/test_learned_gates.py``."""

import json

import numpy as np
import pytest
import torch
from conftest import require_learned_weights, rotated_astronaut

import slime_match as sm
from slime_match import rotation_fallback
from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.rotation_fallback import FALLBACK_BASE, RotationFallback
from slime_match.slime.pipeline import SlimeConfig, SlimeOutput
from slime_match.slime.view_step import PlainTilt
from slime_match.views import ViewConfig

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_rotation_fallback_is_a_slime_option():
    assert make_config("slime-aliked").rotation_fallback == "auto"
    assert make_config("slime-aliked", rotation_fallback="off").rotation_fallback == "off"
    assert make_config("slime-aliked", rotation_fallback="edge-on").rotation_fallback == "edge-on"
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


def _output(matches: int, ftheta: int, tilt: PlainTilt | None = None, views: str = "not needed") -> SlimeOutput:
    """A Slime output with ``matches`` final matches, ``ftheta`` F^theta matches, the plain tilt and the views'
    decision (views "auto")."""
    xy = np.zeros((matches, 2))
    return SlimeOutput(xy, xy, np.zeros(matches), {"ftheta_matches": ftheta}, None, [],
                       {"views": {"mode": "auto", "decision": views}}, tilt)


MEASURED = PlainTilt(6.2, 22, 3)  # 10 matches on one affine map from 2 planes at least: the scene's tilt
ONE_PLANE = PlainTilt(3.7, 18, 1)  # one plane's matches fit an affine map whatever they are: not measured


@pytest.mark.parametrize(("first", "trigger"), [
    (_output(0, 0), "no match"),
    (_output(59, 64, None, "kept"), "no tilt"),  # views kept, no affine map fits the plain F^theta
    (_output(73, 66, ONE_PLANE, "kept"), "no tilt"),
    (_output(15, 8, ONE_PLANE, "dropped"), None),  # the views found nothing either: appearance, not viewpoint
    (_output(1441, 1528, PlainTilt(8.0, 70, 7), "kept"), None),  # the plain matches measure the scene's tilt
    (_output(703, 466, PlainTilt(1.1, 466, 11)), None),  # enough geometry: no view needed
])
def test_the_fallback_runs_where_the_upright_base_finds_no_match_or_under_edge_on_no_tilt(first, trigger):
    assert RotationFallback.trigger(first, "edge-on") == trigger
    assert RotationFallback.trigger(first, "auto") == (trigger if trigger == "no match" else None)
    assert RotationFallback.trigger(first, "off") is None


class _FakeHzPlus:
    """Stands for Slime on Hz+: ``run_slime`` answers ``look`` without views, ``full`` with them."""

    def __init__(self, monkeypatch, look: SlimeOutput, full: SlimeOutput) -> None:
        self.calls: list[str] = []
        pipeline = type("Pipeline", (), {"describe": staticmethod(lambda: {"base": FALLBACK_BASE})})()

        def run_slime(_pipeline, _image0, _image1, config, _timer, seed, level_cache, views):
            self.calls.append(views.mode)
            assert config.refine_tiles == (views.mode != "off")  # the look stops at F^theta
            return look if views.mode == "off" else full

        monkeypatch.setattr(rotation_fallback, "run_slime", run_slime)
        self.fallback = RotationFallback(torch.device("cpu"), None, None)
        self.fallback.pipeline = pipeline

    def run(self, first: SlimeOutput, gain: float = 0.35) -> tuple[SlimeOutput, dict]:
        image = np.zeros((8, 8, 3), np.float32)
        return self.fallback.run(first, RotationFallback.trigger(first, "edge-on"), "aliked-lg", gain, image, image,
                                 SlimeConfig(), 0, ViewConfig())


def test_no_tilt_runs_hz_plus_in_full_only_where_its_plain_matches_measure_one(monkeypatch):
    first = _output(59, 64, None, "kept")
    fake = _FakeHzPlus(monkeypatch, _output(73, 22, ONE_PLANE), _output(1380, 2133, MEASURED, "kept"))
    taken, record = fake.run(first)
    assert taken is first and fake.calls == ["off"] and not record["kept"] and record["trigger"] == "no tilt"
    assert record["reason"].endswith("shows none in its plain F^theta either: the first run's 59 matches stand")
    assert record["other_run"]["counts"] == {"ftheta_matches": 22}


@pytest.mark.parametrize(("first_ftheta", "full_ftheta", "kept"), [
    (64, 2133, True),  # 0.35 x 2133 = 747 > 64: Hz+ holds far more geometry at ALIKED's density
    (66, 119, False),  # 0.35 x 119 = 42 < 66: as many matches as the learned base finds on the same planes
    (10, 99, False),  # under views.min_support: too little consistent geometry, whatever the first run holds
])
def test_hz_plus_is_taken_where_it_holds_more_geometry_at_the_learned_bases_density(monkeypatch, first_ftheta,
                                                                                     full_ftheta, kept):
    first = _output(59, first_ftheta, None, "kept")
    full = _output(1380, full_ftheta, MEASURED, "kept")
    fake = _FakeHzPlus(monkeypatch, _output(73, 22, MEASURED), full)
    taken, record = fake.run(first)
    assert fake.calls == ["off", "auto"] and record["kept"] == kept
    assert taken is (full if kept else first)
    assert record["other_run"]["counts"]["ftheta_matches"] == (first_ftheta if kept else full_ftheta)
    assert ("matches are returned" in taken.warnings[0]) if kept else not taken.warnings
    assert "measures a tilt of 6.2 in its plain F^theta" in record["reason"]
