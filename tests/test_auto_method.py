"""The default method "auto": Slime on ALIKED + LightGlue when their weights are available, else Slime on Hz+, with
a note of the choice in the configuration and the summary, and a warning when it passed the learned base over."""

import json

import numpy as np
import pytest
from conftest import require_learned_weights, run_cli

import slime_match as sm
from slime_match.auto_method import passed_over
from slime_match.config import MatchConfig, make_config


def test_auto_takes_slime_on_aliked_when_its_weights_are_cached():
    require_learned_weights("aliked-n16", "lightglue-aliked")
    config = make_config()
    assert config == make_config("slime-aliked", auto_choice=config.auto_choice)
    assert config.auto_choice.startswith("method auto: slime-aliked") and not passed_over(config.auto_choice)
    assert make_config("auto", seed=3, views="off").base.name == "aliked-lg"  # options both presets read


@pytest.mark.parametrize(("options", "named"), [({"descriptor": "tfeat"}, "descriptor"),
                                                ({"base": "rootsift"}, "base"),
                                                ({"upright": True, "shape": "baumberg"}, "shape, upright")])
def test_options_of_another_base_make_auto_take_it(options, named):
    config = make_config("auto", **options)
    assert config.method == "slime" and config.base.name == options.get("base", "hz+")
    assert config.auto_choice.endswith(f"as given: {named}") and not passed_over(config.auto_choice)


def test_missing_learned_weights_are_passed_over_loudly(offline, monkeypatch):
    config = make_config()
    assert config.method == "slime" and config.base.name == "hz+"
    assert passed_over(config.auto_choice) and "aliked-n16.pth" in config.auto_choice
    monkeypatch.undo()  # the Hz+ weights are back
    matcher = sm.Matcher(make_config("auto", descriptor="rootsift", shape="baumberg", orientation="gradient"))
    assert not matcher.warnings  # no choice was passed over: the options named Hz+
    config.base.descriptor, config.base.shape, config.base.orientation = "rootsift", "baumberg", "gradient"
    matcher = sm.Matcher(config)
    assert config.auto_choice in matcher.warnings


def test_a_named_preset_records_no_choice_and_a_recorded_choice_survives_a_reload(tmp_path):
    assert make_config("slime").auto_choice == ""
    config = make_config("slime", auto_choice="method auto: slime (test)")
    (tmp_path / "config.json").write_text(json.dumps(config.to_dict()))
    assert MatchConfig.load(tmp_path / "config.json").auto_choice == "method auto: slime (test)"


def test_the_summary_names_the_choice(pair):
    config = make_config("auto", descriptor="rootsift", shape="baumberg", orientation="gradient", scales=(1,),
                         views="off")
    result = sm.Matcher(config)(*pair)
    assert result.summary["decisions"]["method"] == config.auto_choice
    assert np.all(np.isfinite(result.keypoints0))


def test_cli_default_is_auto(capsys, pair, tmp_path):
    code, out, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "out", "--descriptor", "rootsift", "--shape",
                           "baumberg", "--orientation", "gradient", "--scales", "1", "--views", "off", "--no-plot")
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["decisions"]["method"].startswith("method auto: slime (Slime on the base the options ask for)")
    assert out.startswith(summary["decisions"]["method"] + "\n")  # the choice, then the result line
