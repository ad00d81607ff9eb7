"""Configuration: options by flat, short or dotted name, each checked where it is defined, and read back from
a run's summary."""

import json

import pytest

import slime_match as sm
from slime_match._runtime.options import config_from_dict, option_paths, parse_value, set_option
from slime_match.choices import PRESET_NAMES
from slime_match.config import PRESETS, MatchConfig, option_path, with_options
from slime_match.slime.blocks import BlockConfig
from slime_match.slime.pipeline import SlimeConfig
from slime_match.slime.tile_sets import TileConfig


def test_option_paths_of_flat_short_and_dotted_names():
    assert option_path("descriptor") == "base.descriptor"
    assert option_path("workers") == "slime.workers"
    assert option_path("threshold") == "threshold"
    assert option_path("scales") == "slime.blocks.scales"
    assert option_path("slime.tiles.t_xi") == "slime.tiles.t_xi"
    with pytest.raises(sm.ConfigError, match="unknown option 'nope'.*slime.tiles.t_xi"):
        option_path("nope")
    paths = option_paths(MatchConfig())
    assert {"slime.tiles.t_xi", "base.blob.shortlist_k", "slime.blocks.scales", "max_side"} <= set(paths)
    assert len(paths) == len(set(paths))


def test_dotted_options_reach_every_nested_field():
    config = sm.make_config("slime", descriptor="tfeat", **{"slime.tiles.t_xi": 12, "slime.planes.t_theta": "1.0",
                                                           "base.dtm.max_iterations": "50"})
    assert config.slime.tiles.t_xi == 12 and config.slime.planes.t_theta == 1.0
    assert config.base.dtm.max_iterations == 50 and config.base.descriptor == "tfeat"
    assert sm.make_config("slime").slime.tiles.t_xi == 9.0  # presets are not changed


def test_set_option_reads_strings_by_type_and_rebuilds_the_path():
    config = MatchConfig()
    changed = set_option(config, "slime.blocks.scales", "1,2")
    assert changed.slime.blocks.scales == (1, 2) and config.slime.blocks.scales == (1, 2, 3)
    assert changed.slime.tiles is config.slime.tiles  # only the dataclasses on the path are rebuilt
    assert set_option(config, "slime.detection", "none").slime.detection is None
    assert set_option(config, "max_side", "640").max_side == 640
    assert set_option(config, "base.upright", "true").base.upright is True
    assert parse_value("none", int | None) is None and parse_value("0.5", float) == 0.5


@pytest.mark.parametrize(("path", "value", "message"), [
    ("slime.tiles.t_xi", "many", "option 'slime.tiles.t_xi': cannot read 'many' as float"),
    ("slime.tiles.same_homography", "all", "same_homography 'all' is not one of shared, iou, set"),
    ("slime.blocks.scales", "1,1", "scales must be distinct"),
    ("slime.tile_test", "edge", "invalid tile_test 'edge': choose one of plane, flow"),
    ("slime.workers", "0", "workers must be an integer of at least 1 or None, got 0"),
    ("base.descriptor", "sift", "invalid descriptor 'sift': choose one of auto, hardnet, hardtfeat, tfeat, rootsift"),
    ("slime.tiles.nope", "1", "unknown option 'slime.tiles.nope': TileConfig has q_pair"),
    ("slime.nope.x", "1", "'slime.nope' is not a group of options"),
    ("base.descriptor.x", "1", "'base.descriptor' is not a group of options"),
])
def test_set_option_refuses_unknown_paths_and_bad_values(path, value, message):
    with pytest.raises(sm.ConfigError, match=message):
        set_option(MatchConfig(), path, value)


def test_each_dataclass_checks_its_own_values():
    with pytest.raises(sm.ConfigError, match="invalid detection 'tile'"):
        SlimeConfig(detection="tile")
    with pytest.raises(sm.ConfigError, match="invalid block_matching 'image'"):
        SlimeConfig(block_matching="image")
    with pytest.raises(sm.ConfigError, match="invalid device 'tpu'"):
        MatchConfig(device="tpu")
    with pytest.raises(sm.ConfigError, match="min_plane_matches must be an integer of at least 4"):
        SlimeConfig(min_plane_matches=3)
    with pytest.raises(sm.ConfigError, match="max_side must be an integer of at least"):
        MatchConfig(max_side=8)
    config = sm.make_config("slime")
    config.slime.tile_test = "edge"  # set after construction: validate (as the Matcher does) finds it
    with pytest.raises(sm.ConfigError, match="invalid tile_test"):
        config.validate()


def test_every_preset_builds_and_the_command_line_offers_each():
    assert tuple(PRESETS) == PRESET_NAMES
    for name in PRESETS:
        assert sm.make_config(name).method in ("slime", name.removesuffix("-upright"))


def test_dotted_slime_options_are_refused_for_a_base_alone():
    with pytest.raises(sm.ConfigError, match="'slime.tiles.t_xi' is a Slime option"):
        sm.make_config("hz+", **{"slime.tiles.t_xi": 3})
    with pytest.raises(sm.ConfigError, match="rootsift base pipeline does not use 'base.blob.shortlist_k'"):
        sm.make_config("rootsift", **{"base.blob.shortlist_k": 3})


@pytest.mark.parametrize(("preset", "options", "message"), [
    ("hz+", {"views.min_support": 50}, r"'views.min_support' is the threshold of Slime .* set views.min_inliers"),
    ("slime", {"views.min_inliers": 20}, r"'views.min_inliers' is the threshold of a base pipeline alone .*"),
    ("hz+", {"views": "off", "views.tilts": (2.0,)}, "'views.tilts' sets the simulated views, and they are off"),
    ("slime", {"views": "off", "views.min_support": 50}, "they are off"),
    ("slime", {"views": "always", "views.min_support": 50}, "the mode is 'always', which adds them all"),
    ("aliked-lg", {"views.min_tilt": 1.2}, r"'views.min_tilt' is the threshold of Slime .* set views.min_inliers"),
    ("slime", {"views": "always", "views.min_tilt": 1.2}, "the mode is 'always'"),
    ("slime", {"views.min_tilt": 0.9}, r"views.min_tilt must be >= 1"),
    ("slime", {"views.max_tilt": 1.2}, r"views.max_tilt must be > views.min_tilt"),
    ("slime", {"views.steep_tilts": "8,1"}, r"views.steep_tilts must all be > 1"),
    ("aliked-lg", {"views.steep_tilts": "8"}, r"'views.steep_tilts' is the threshold of Slime"),
    ("rootsift", {"views": "always", "views.min_inliers": 20}, "the mode is 'always'"),
    ("slime", {"views.min_probe": 10}, r"'views.min_probe' sets the probe .* Slime on hz\+ matches block pairs"),
    ("aliked-lg", {"views.min_probe": 10}, r"method 'aliked-lg' runs the aliked-lg pipeline alone"),
    ("slime-aliked", {"views.min_probe": -1}, "views.min_probe"),
    ("slime", {"views.screen_keypoints": 512}, r"'views.screen_keypoints' sets the probe .* block pairs"),
])
def test_view_options_the_run_would_not_read_are_refused(preset, options, message):
    with pytest.raises(sm.ConfigError, match=message) as info:
        sm.make_config(preset, **options)
    assert "\n" not in str(info.value)


def test_view_options_the_run_reads_are_accepted():
    assert sm.make_config("hz+", views="always", **{"views.tilts": "2"}).views.tilts == (2.0,)  # the base's views
    assert sm.make_config("hz+", **{"views.min_inliers": 30}).views.min_inliers == 30
    assert sm.make_config("slime", **{"views.min_support": 80}).views.min_support == 80
    assert sm.make_config("slime-aliked", **{"views.min_tilt": "1"}).views.min_tilt == 1.0
    assert sm.make_config("slime", views="off").views.mode == "off"
    assert sm.make_config("slime-aliked", views="always", **{"views.min_probe": 0}).views.min_probe == 0
    assert sm.make_config("slime", block_matching="levels", **{"views.min_probe": 5}).views.min_probe == 5
    recorded = sm.make_config("slime", views="off")  # options of a recorded configuration are not re-judged
    assert with_options(recorded, views="auto", **{"views.min_support": 90}).views.min_support == 90


@pytest.mark.parametrize(("preset", "options", "message"), [
    ("hz+", {"pool": "rootsift"}, "pool is a Slime option, but method 'hz\\+' runs the hz\\+ pipeline alone"),
    ("slime", {"pool": "hz+"}, "pool 'hz\\+' is the base itself"),
    ("slime", {"pool": "sift"}, "invalid pool .sift.: choose one of .*disk-lg"),
    ("slime-aliked", {"descriptor": "tfeat"}, "the aliked-lg base pipeline does not use 'descriptor'"),
    ("slime-aliked-disk", {"descriptor": "tfeat"}, "the aliked-lg and disk-lg base pipelines do not use 'descriptor'"),
])
def test_a_pooled_base_is_checked(preset, options, message):
    with pytest.raises(sm.ConfigError, match=message):
        sm.make_config(preset, **options)


def test_a_pooled_base_reads_the_base_options():
    config = sm.make_config("slime-aliked-disk")
    assert (config.base.name, config.slime.pool, config.base.max_keypoints) == ("aliked-lg", "disk-lg", 3072)
    # Hz+ pooled under ALIKED reads the descriptor, which ALIKED does not
    assert sm.make_config("slime-aliked", pool="hz+", descriptor="tfeat").base.descriptor == "tfeat"
    assert sm.make_config("slime", pool="rootsift").slime.pool == "rootsift"


def test_a_summary_reads_back_to_the_same_configuration(tmp_path):
    config = sm.make_config("slime-rootsift", scales=(1, 2), workers=1, **{"slime.tiles.t_xi": 12})
    summary = {"method": "slime", "config": json.loads(json.dumps(config.to_dict())), "counts": {}}
    assert MatchConfig.from_dict(summary) == config == MatchConfig.from_dict(config.to_dict())
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    loaded = MatchConfig.load(tmp_path / "summary.json")
    assert loaded == config and isinstance(loaded.slime.blocks.scales, tuple)
    assert with_options(loaded, method="hz+").base.name == "hz+"
    bad = {**config.to_dict(), "slime": {**config.to_dict()["slime"], "t_xi": 3}}
    with pytest.raises(sm.ConfigError, match=r"unknown SlimeConfig option\(s\) \['t_xi'\]"):
        MatchConfig.from_dict(bad)
    (tmp_path / "broken.json").write_text("{")
    with pytest.raises(sm.ConfigError, match="cannot read a configuration"):
        MatchConfig.load(tmp_path / "broken.json")


def test_config_from_dict_builds_nested_dataclasses():
    built = config_from_dict(SlimeConfig, {"blocks": {"scales": [1, 2]}, "tiles": {"t_xi": 4.0}, "workers": 2})
    assert built.blocks == BlockConfig(scales=(1, 2)) and built.tiles == TileConfig(t_xi=4.0) and built.workers == 2


def test_a_registered_base_pipeline_runs_alone_by_its_name():
    from slime_match.pipelines import PIPELINES, register_pipeline
    from slime_match.pipelines.rootsift import RootSiftPipeline

    class Mine(RootSiftPipeline):
        pass

    register_pipeline("mine-config-test", Mine)
    try:
        config = sm.make_config("mine-config-test", fginn_ratio=0.9)
        assert config.method == config.base.name == "mine-config-test" and config.base.fginn_ratio == 0.9
    finally:
        del PIPELINES["mine-config-test"]


def test_working_size_limits():
    """min_side / max_side: 'auto' is Slime's 480 / 1200 px and off for a base pipeline alone; 0 or None is off;
    a command-line string is read as px, 'auto' or 'none'."""
    assert MatchConfig().side_limits() == (480, 1200)
    assert sm.make_config("slime-fast").side_limits() == (480, 1200)
    assert sm.make_config("hz+").side_limits() == (None, None)
    assert sm.make_config("rootsift", min_side=300, max_side=900).side_limits() == (300, 900)
    assert sm.make_config("slime", min_side=0, max_side=0).side_limits() == (None, None)
    assert sm.make_config("slime", max_side=1024).side_limits() == (480, 1024)
    assert sm.make_config("slime", max_side=400).side_limits() == (480, 400)  # the auto min_side gives way
    assert set_option(MatchConfig(), "min_side", "none").min_side is None
    assert set_option(MatchConfig(), "min_side", "640").side_limits() == (640, 1200)
    assert set_option(MatchConfig(), "max_side", "auto").max_side == "auto"
    recorded = sm.make_config("slime", min_side=600).to_dict()
    assert MatchConfig.from_dict(json.loads(json.dumps(recorded))).side_limits() == (600, 1200)
    # a configuration recorded before min_side existed reads back with max_side off and min_side auto
    old = {key: value for key, value in MatchConfig(max_side=None).to_dict().items() if key != "min_side"}
    assert MatchConfig.from_dict(old).side_limits() == (480, None)


@pytest.mark.parametrize(("options", "message"), [
    ({"min_side": 8}, "min_side must be an integer of at least 32 px, 0 or None"),
    ({"max_side": -1}, "max_side must be an integer of at least 32 px"),
    ({"min_side": "big"}, "min_side must be an integer .* got 'big'"),
    ({"min_side": 1.5}, "min_side must be an integer"),
    ({"max_side": True}, "max_side must be an integer"),
    ({"min_side": 900, "max_side": 600}, "min_side 900 px is larger than max_side 600 px: an image cannot"),
    ({"min_side": 1500}, r"min_side 1500 px is larger than max_side 1200 px \(auto for slime\)"),
])
def test_working_size_limits_bad_values(options, message):
    with pytest.raises(sm.ConfigError, match=message):
        sm.make_config("slime", **options)
