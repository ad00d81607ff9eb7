"""The top-level Python API: ``slime_match.match`` and ``Matcher`` on the kinds of input users pass."""

import subprocess
import sys

import cv2
import numpy as np
import pytest
import torch

import slime_match as sm
from slime_match.cli import main
from slime_match.errors import ConfigError, SlimeMatchError

WEIGHT_FREE = {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift"}


@pytest.fixture(scope="module")
def rgb_pair(pair):
    """(H, W, 3) uint8 RGB images of the real stereo pair."""
    return [cv2.imread(path)[:, :, ::-1].copy() for path in pair]


@pytest.fixture(scope="module")
def reference(rgb_pair):
    return sm.match(*rgb_pair, "hz+", **WEIGHT_FREE)


def _same(a, b):
    return (np.array_equal(a.keypoints0, b.keypoints0) and np.array_equal(a.keypoints1, b.keypoints1)
            and np.array_equal(a.scores, b.scores))


def test_match_finds_matches_and_names_its_configuration(reference):
    assert len(reference) > 100
    assert reference.summary["method"] == "hz+"


@pytest.mark.parametrize("convert", [
    lambda im: im.astype(np.float32) / 255.0,  # float in [0, 1]
    lambda im: im.astype(np.uint16) * 257,  # 16-bit
    lambda im: torch.from_numpy(im).permute(2, 0, 1).float() / 255.0,  # (3, H, W) tensor
    lambda im: torch.from_numpy(im).permute(2, 0, 1)[None],  # (1, 3, H, W) uint8 tensor
], ids=["float", "uint16", "tensor-chw", "tensor-1chw"])
def test_input_kinds_give_the_same_matches(rgb_pair, reference, convert):
    assert _same(sm.match(*(convert(im) for im in rgb_pair), "hz+", **WEIGHT_FREE), reference)


def test_match_takes_a_config_and_leaves_it_unchanged(rgb_pair, reference):
    config = sm.make_config("hz+", **WEIGHT_FREE)
    assert _same(sm.match(*rgb_pair, config), reference)
    auto = sm.make_config("hz+", shape="baumberg", orientation="gradient")  # descriptor "auto"
    matcher = sm.Matcher(auto)
    assert auto.base.descriptor == "auto"  # the matcher resolves "auto" on its own copy
    assert matcher.config.base.descriptor in ("hardnet", "hardtfeat", "tfeat", "rootsift")  # the best available


def test_match_refuses_options_beside_a_config_and_odd_presets(rgb_pair):
    with pytest.raises(ConfigError, match="descriptor.*make_config"):
        sm.match(*rgb_pair, sm.make_config("hz+"), descriptor="tfeat")
    with pytest.raises(ConfigError, match="unknown method/preset"):
        sm.match(*rgb_pair, 3)
    with pytest.raises(ConfigError, match="unknown method/preset 'sift'"):
        sm.match(*rgb_pair, "sift")


@pytest.mark.parametrize(("preset", "options", "message"), [
    ("hz+", {"scales": (1, 2)}, "'scales' is a Slime option"),
    ("rootsift", {"workers": 2}, "'workers' is a Slime option"),
    ("hz+", {"base": "rootsift"}, "base 'rootsift' is the pipeline inside Slime"),
    ("rootsift", {"descriptor": "tfeat"}, "rootsift base pipeline does not use 'descriptor'"),
    ("slime-rootsift", {"shape": "affnet"}, "rootsift base pipeline does not use 'shape'"),
    ("slime-keynet", {"fginn_ratio": 0.9}, "keynet base pipeline does not use 'fginn_ratio'"),
    ("slime", {"threshold": 2.0}, "ransac is 'none'"),
])
def test_make_config_refuses_options_the_method_would_ignore(preset, options, message):
    with pytest.raises(ConfigError, match=message):
        sm.make_config(preset, **options)


@pytest.mark.parametrize(("options", "message"), [
    ({"seed": -1}, "seed must be an integer of at least 0, got -1"),
    ({"seed": 1.5}, "seed must be an integer of at least 0, got 1.5"),
    ({"scales": (1, 2, 1)}, "scales must be distinct"),
])
def test_make_config_refuses_bad_values(options, message):
    with pytest.raises(ConfigError, match=message):
        sm.make_config("slime", **options)


def test_make_config_takes_the_options_each_method_reads():
    assert sm.make_config("rootsift", upright=True, fginn_ratio=0.9).base.upright
    assert sm.make_config("hz+", base="hz+", **WEIGHT_FREE).base.shape == "baumberg"
    assert sm.make_config("slime-rootsift", dtm=sm.make_config().base.dtm, workers=1).slime.workers == 1
    assert sm.make_config("hz+", ransac="homography", threshold=2.0).threshold == 2.0


def test_matcher_repr_names_its_configuration():
    assert repr(sm.Matcher(sm.make_config("slime", device="cpu", **WEIGHT_FREE))) == (
        "Matcher(method='slime', base='hz+', scales=(1, 2, 3), shape='baumberg', orientation='gradient', "
        "descriptor='rootsift', device='cpu')")
    rootsift = sm.Matcher(sm.make_config("rootsift-upright", device="cpu"))
    assert repr(rootsift) == "Matcher(method='rootsift', upright=True, device='cpu')"


def test_geometry_result_repr_is_one_line(reference):
    geometry = reference.geometry(kind="homography", threshold=3.0)
    assert repr(geometry) == (f"GeometryResult('homography', {int(geometry.inliers.sum())} of {len(reference)} "
                              f"inliers, threshold=3.0 px, backend={geometry.info['backend']!r})")


def test_save_and_load_round_trip(rgb_pair, reference, tmp_path, pair):
    result = sm.match(*rgb_pair, "hz+", ransac="homography", threshold=15, **WEIGHT_FREE)
    result.save(tmp_path / "pair.npz")
    loaded = sm.MatchResult.load(tmp_path / "pair.npz")
    assert _same(loaded, result) and np.array_equal(loaded.inliers, result.inliers)
    assert loaded.geometry_kind == "homography" and np.array_equal(loaded.model, result.model)
    assert loaded.summary["counts"]["inliers"] == int(result.inliers.sum())
    assert repr(loaded) == (f"MatchResult({len(result)} matches, method='hz+', {int(result.inliers.sum())} inliers "
                            f"(homography), {result.summary['seconds']['total']:.2f} s)")
    out = tmp_path / "cli"
    assert main(["match", *pair, "-o", str(out), "--method", "hz+", "--no-plot", "--shape", "baumberg",
                 "--orientation", "gradient", "--descriptor", "rootsift"]) == 0
    from_cli = sm.MatchResult.load(out / "matches.npz")  # its summary is the folder's summary.json
    assert _same(from_cli, reference) and from_cli.inliers is None and from_cli.model is None
    assert from_cli.summary["method"] == "hz+"


def test_load_refuses_files_that_are_not_matches(tmp_path):
    with pytest.raises(SlimeMatchError, match="no such matches file"):
        sm.MatchResult.load(tmp_path / "none.npz")
    (tmp_path / "summary.json").write_text("{}")
    with pytest.raises(SlimeMatchError, match=r"not a matches file \(not an .npz archive\)"):
        sm.MatchResult.load(tmp_path / "summary.json")
    np.savez(tmp_path / "other.npz", keypoints0=np.zeros((3, 2)))
    with pytest.raises(SlimeMatchError, match="not a matches file: it has no keypoints1, scores"):
        sm.MatchResult.load(tmp_path / "other.npz")
    np.savez(tmp_path / "objects.npz", keypoints0=np.array([None, 1], dtype=object))
    with pytest.raises(SlimeMatchError, match="not a readable matches file"):
        sm.MatchResult.load(tmp_path / "objects.npz")


def test_drawing_leaves_the_callers_matplotlib_backend_alone(tmp_path):
    """Pictures are drawn on their own Figure objects: a notebook's backend and open figures stay as they were."""
    script = f"""
import matplotlib
matplotlib.use("svg")
import matplotlib.pyplot as plt
import numpy as np
import slime_match as sm
from slime_match.eval import figures
from slime_match.slime import visualize
from slime_match.viz import plot_matches
mine = plt.figure()
image = np.zeros((40, 50, 3), np.float32)
result = sm.MatchResult(np.array([[1.0, 2.0]]), np.array([[3.0, 4.0]]), np.array([0.5]))
plot_matches(image, image, result, {str(tmp_path / "m.png")!r})
print(matplotlib.get_backend(), plt.get_fignums() == [mine.number])
"""
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert run.stdout.split() == ["svg", "True"]
    assert (tmp_path / "m.png").stat().st_size > 0
