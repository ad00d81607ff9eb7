"""The `slime` command line: outputs, options, and bad input (clear one-line errors, never a traceback)."""

import json
import re

import cv2
import numpy as np
import pytest
from conftest import run_cli

import slime_match.matcher
import slime_match.viz
from slime_match.cli import main
from slime_match.config import make_config
from slime_match.errors import caused_by_interrupt
from slime_match.matcher import Matcher
from slime_match.result import MatchResult
from slime_match.slime.refine import global_dtm

WEIGHT_FREE = ["--shape", "baumberg", "--orientation", "gradient", "--descriptor", "rootsift"]


def test_match_writes_all_outputs(pair, tmp_path, capsys):
    code, out, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift")
    assert code == 0, err
    assert "matches" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["matches.npz", "matches.png", "summary.json"]
    data = np.load(tmp_path / "matches.npz")
    assert set(data.files) == {"keypoints0", "keypoints1", "scores"}
    k = len(data["scores"])
    assert k > 100 and data["keypoints0"].shape == (k, 2) and data["keypoints0"].dtype == np.float64
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["method"] == "rootsift" and summary["counts"]["matches"] == k
    assert {"features", "matching", "total"} <= set(summary["seconds"])
    assert summary["config"]["base"]["fginn_ratio"] == 0.8


@pytest.mark.parametrize("ransac, key", [("fundamental", "F"), ("homography", "H"), ("magsac-fundamental", "F")])
def test_ransac_outputs(pair, tmp_path, capsys, ransac, key):
    code, out, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift", "--ransac", ransac,
                          "--threshold", "3", "--no-plot")
    assert code == 0, err
    data = np.load(tmp_path / "matches.npz")
    assert data[key].shape == (3, 3) and data["inliers"].dtype == bool
    assert 0 < data["inliers"].sum() <= len(data["scores"])
    assert "inliers" in out


def test_hz_plus_weight_free(pair, tmp_path, capsys):
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "hz+", *WEIGHT_FREE, "--no-plot")
    assert code == 0, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["pipeline"]["descriptor"] == "rootsift" and summary["pipeline"]["shape"] == "baumberg"
    assert summary["counts"]["matches"] > 50


def test_slime_stages_viz_and_reruns_into_the_same_folders(pair, tmp_path, capsys):
    # at its own size (--min-side none): the stages' points, in original px, are then the global DTM's own
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, *WEIGHT_FREE, "--save-stages", "--no-plot",
                           "--min-side", "none")
    assert code == 0, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["method"] == "slime" and summary["counts"]["matches"] > 0
    assert {"block_pairs", "expansion", "plane_selection", "global_dtm"} <= set(summary["seconds"])
    stages = np.load(tmp_path / "stages.npz")
    assert stages["final_xy0"].shape == (summary["counts"]["matches"], 2)
    sizes = [tuple(summary["image_sizes"][f"image{i}"][::-1]) for i in (0, 1)]  # (H, W)
    rerun = global_dtm(stages["dtm_input_xy0"], stages["dtm_input_xy1"], stages["dtm_input_score"], *sizes)
    np.testing.assert_array_equal(rerun[0], stages["final_xy0"])  # the global DTM's input is saved whole
    code, _out, err = run_cli(capsys, "viz", tmp_path / "stages.npz", *pair, "-o", tmp_path / "viz")
    assert code == 0, err
    assert {p.name for p in (tmp_path / "viz").iterdir()} == {
        f"{s}.png" for s in ("blocks", "tiles", "planes", "superset", "fbar", "ftheta", "tile_matches", "final")}

    (tmp_path / "viz" / "notes.txt").write_text("mine")
    code, _out, err = run_cli(capsys, "viz", tmp_path / "stages.npz", *pair, "-o", tmp_path / "viz", "--stage",
                              "final")
    assert code == 0, err
    assert {p.name for p in (tmp_path / "viz").iterdir()} == {"final.png", "notes.txt"}  # no earlier picture

    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift", "--no-plot")
    assert code == 0, err  # an earlier run's stages.npz goes; other files stay
    assert {p.name for p in tmp_path.iterdir()} == {"matches.npz", "summary.json", "viz"}


def test_an_interrupted_match_leaves_the_earlier_result_intact(pair, tmp_path, capsys, monkeypatch):
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift")
    assert code == 0, err
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(slime_match.viz, "plot_matches", interrupted)
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift", "--ransac", "homography")
    assert code == 130 and err.splitlines()[-1] == "interrupted"
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_slime_detection_option(pair, tmp_path, capsys):
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, *WEIGHT_FREE, "--detection", "scale", "--no-plot")
    assert code == 0, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["config"]["slime"]["detection"] == "scale" and summary["counts"]["matches"] > 0
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "r", "--base", "rootsift", "--detection", "merged")
    assert code == 2 and "'merged' needs the hz+ base" in err


def test_slime_tile_test_option(pair, tmp_path, capsys):
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, *WEIGHT_FREE, "--tile-test", "flow", "--no-plot")
    assert code == 0, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["config"]["slime"]["tile_test"] == "flow" and summary["counts"]["tile_matches"] > 0
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "r", "--method", "hz+", "--tile-test", "plane")
    assert code == 2 and "'tile_test' is a Slime option" in err and not (tmp_path / "r").exists()


def test_stage_lines_by_default_and_help_groups(pair, tmp_path, capsys):
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift", "--no-plot")
    assert code == 0, err
    lines = [line for line in err.splitlines() if line.endswith(" s")]
    assert [line.split(":")[0] for line in lines] == ["load", "features", "matching", "views"], err
    with pytest.raises(SystemExit):
        main(["match", "--help"])
    text = capsys.readouterr().out
    groups = text.index("\nmatching:"), text.index("\nSlime and base pipeline internals")
    assert groups[0] < text.index("\n  --descriptor") < groups[1] < text.index("\n  --detection")


def test_views_option(pair, tmp_path, capsys):
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "hz+", *WEIGHT_FREE, "--views", "always",
                           "--set", "views.tilts=2", "--no-plot")
    assert code == 0, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["config"]["views"]["mode"] == "always" and summary["config"]["views"]["tilts"] == [2.0]
    assert summary["decisions"]["views"] == {"mode": "always", "images": "both", "tilts": [2.0], "views": 10,
                                             "decision": "kept", "reason": "every view tried",
                                             "tried": [{"image": 0, "tilt": 2.0, "views": 5},
                                                       {"image": 1, "tilt": 2.0, "views": 5}]}
    with pytest.raises(SystemExit):
        main(["match", *pair, "-o", str(tmp_path / "r"), "--views", "sometimes"])
    assert "--views" in capsys.readouterr().err and not (tmp_path / "r").exists()
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "r", "--set", "views.tilts=0.5")
    assert code == 2 and "views.tilts" in err and not (tmp_path / "r").exists()


def test_set_any_option_and_rerun_a_recorded_configuration(pair, tmp_path, capsys):
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "a", *WEIGHT_FREE, "--set", "slime.tiles.t_xi=12",
                           "--set", "slime.blocks.scales=1,2", "--no-plot")
    assert code == 0, err
    first = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert first["config"]["slime"]["tiles"]["t_xi"] == 12 and first["config"]["slime"]["blocks"]["scales"] == [1, 2]
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "b", "--config", tmp_path / "a" / "summary.json",
                           "--no-plot")
    assert code == 0, err
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["config"] == first["config"]
    a, b = np.load(tmp_path / "a" / "matches.npz"), np.load(tmp_path / "b" / "matches.npz")
    np.testing.assert_array_equal(a["keypoints0"], b["keypoints0"])
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "c", "--config", tmp_path / "a" / "summary.json",
                           "--method", "rootsift", "--set", "slime.tiles.t_xi=9")
    assert code == 2 and "'slime.tiles.t_xi' is a Slime option" in err and not (tmp_path / "c").exists()


@pytest.mark.parametrize(("options", "message"), [
    (["--set", "slime.tiles.nope=1"], "unknown option 'slime.tiles.nope'"),
    (["--set", "slime.tiles.t_xi=many"], "cannot read 'many' as float"),
    (["--config", "missing.json"], "cannot read a configuration from missing.json"),
    (["--method", "hz+", "--set", "views.min_support=50"], "'views.min_support' is the threshold of Slime"),
    (["--views", "off", "--set", "views.tilts=2"], "'views.tilts' sets the simulated views, and they are off"),
])
def test_bad_settings_and_configs_are_one_line_errors(pair, tmp_path, capsys, options, message):
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "out", *options)
    assert code == 2 and message in err and not (tmp_path / "out").exists()
    assert len(err.strip().splitlines()) == 1


def test_a_setting_without_a_value_is_a_usage_error(pair, tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        run_cli(capsys, "match", *pair, "-o", tmp_path / "out", "--set", "t_xi")
    assert stop.value.code == 2 and "expected OPTION=VALUE" in capsys.readouterr().err


def test_blank_image_gives_explicit_empty_result(pair, tmp_path, capsys, caplog):
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((200, 300, 3), 128, np.uint8))
    for method in (["--method", "rootsift"], ["--method", "hz+", *WEIGHT_FREE], WEIGHT_FREE):
        out_dir = tmp_path / "out"
        code, _, err = run_cli(capsys, "match", blank, pair[0], "-o", out_dir, *method)
        assert code == 0, err
        data = np.load(out_dir / "matches.npz")
        assert data["keypoints0"].shape == (0, 2) and data["scores"].shape == (0,)
        summary = json.loads((out_dir / "summary.json").read_text())
        assert summary["counts"]["matches"] == 0
        for warning in summary["warnings"]:  # logged once (to stderr) as it happens, not repeated at the end
            assert caplog.text.count(warning) == 1 and warning not in err
        caplog.clear()
    assert "Slime found no match" in summary["warnings"][0]  # the default method says why it is empty
    # and tries no view
    assert re.search(r"the blocks of image 0 hold at most \d+ keypoints", summary["decisions"]["views"]["reason"])


def test_identical_images_match_in_place(pair, tmp_path, capsys):
    code, _, err = run_cli(capsys, "match", pair[0], pair[0], "-o", tmp_path, "--method", "rootsift", "--no-plot")
    assert code == 0, err
    data = np.load(tmp_path / "matches.npz")
    shift = np.linalg.norm(data["keypoints0"] - data["keypoints1"], axis=1)
    assert len(shift) > 100 and np.mean(shift < 1.0) > 0.95


def test_grey_rgba_and_16bit_inputs(pair, tmp_path, capsys):
    left = cv2.imread(pair[0])
    variants = {"grey.png": cv2.cvtColor(left, cv2.COLOR_BGR2GRAY), "rgba.png": cv2.cvtColor(left, cv2.COLOR_BGR2BGRA),
                "deep.png": left.astype(np.uint16) * 257}
    for name, image in variants.items():
        cv2.imwrite(str(tmp_path / name), image)
        code, _, err = run_cli(capsys, "match", tmp_path / name, pair[1], "-o", tmp_path / name[:-4], "--method",
                            "rootsift", "--no-plot")
        assert code == 0, err
        assert len(np.load(tmp_path / name[:-4] / "matches.npz")["scores"]) > 50


@pytest.mark.parametrize("case", ["missing", "not_image", "tiny", "directory"])
def test_bad_input_one_line_error_no_output(pair, tmp_path, capsys, case):
    bad = {"missing": tmp_path / "nope.png", "not_image": tmp_path / "notes.png", "tiny": tmp_path / "tiny.png",
           "directory": tmp_path}[case]
    (tmp_path / "notes.png").write_text("not an image")
    cv2.imwrite(str(tmp_path / "tiny.png"), np.zeros((16, 16, 3), np.uint8))
    out_dir = tmp_path / "out"
    code, _out, err = run_cli(capsys, "match", bad, pair[1], "-o", out_dir, "--method", "rootsift")
    assert code == 2
    assert err.startswith("error: ") and err.count("\n") == 1 and "Traceback" not in err
    assert not out_dir.exists()


def test_bad_options_and_missing_gpu(pair, tmp_path, capsys):
    for bad in (["--descriptor", "sift2"], ["--scales", "1,x"], ["--scales", "0,2"], ["--workers", "0"],
                ["--workers", "two"]):
        with pytest.raises(SystemExit):
            main(["match", *pair, "-o", str(tmp_path), *bad])
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--threshold", "-1", "--method", "rootsift")
    assert code == 2 and "threshold" in err
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--max-side", "8", "--method", "rootsift")
    assert code == 2 and "max_side" in err and not (tmp_path / "matches.npz").exists()
    for ignored, word in ((["--method", "hz+", "--save-stages"], "--save-stages"),
                          (["--method", "rootsift", "--shape", "baumberg"], "'shape'"),
                          (["--method", "hz+", "--scales", "1,2"], "'scales'"),
                          (["--threshold", "2"], "threshold")):  # options the run would not use
        code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, *ignored)
        assert code == 2 and word in err and not (tmp_path / "matches.npz").exists()
    import torch

    if not torch.cuda.is_available():
        code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--device", "cuda", "--method", "rootsift")
        assert code == 2 and "no CUDA" in err


def test_max_side_shrinks_and_maps_back(pair, tmp_path, capsys):
    """The 370 x 250 pair matched at --max-side 185: the summary gives both sizes, matches are in original px."""
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift", "--max-side", "185",
                           "--no-plot")
    assert code == 0, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["image_sizes"]["image0"] == [370, 250] and summary["working_sizes"]["image0"] == [185, 125]
    assert summary["config"]["max_side"] == 185
    keypoints = np.load(tmp_path / "matches.npz")["keypoints0"]
    assert len(keypoints) > 20 and keypoints[:, 0].max() > 185 and keypoints.max() < 370


def test_min_side_upsamples_and_summary_records_the_sizes(pair, tmp_path, capsys):
    """The 370 x 250 pair with --min-side 500: matched at 740 x 500 (factor 2), matches in original px; the
    summary and MatchResult.load record both sizes, the factors and the limits applied."""
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift", "--min-side", "500",
                           "--max-side", "none", "--no-plot")
    assert code == 0, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["image_sizes"] == {"image0": [370, 250], "image1": [370, 250]}
    assert summary["working_sizes"] == {"image0": [740, 500], "image1": [740, 500]}
    assert summary["working_factors"] == {"image0": [2.0, 2.0], "image1": [2.0, 2.0]}
    assert summary["side_limits"] == {"min_side": 500, "max_side": None}
    assert summary["config"]["min_side"] == 500 and summary["config"]["max_side"] == 0
    result = MatchResult.load(tmp_path / "matches.npz")
    assert result.image_sizes == ((370, 250), (370, 250)) and result.working_sizes == ((740, 500), (740, 500))
    assert result.working_factors == ((2.0, 2.0), (2.0, 2.0))
    assert len(result) > 20 and result.keypoints0[:, 0].max() > 250 and result.keypoints0.max() < 370
    assert result.keypoints1.min() > -0.5


def test_working_size_defaults_per_method(pair, tmp_path, capsys):
    """A base pipeline alone runs at full size by default (auto); Slime's auto limits are 480 / 1200 px."""
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift", "--no-plot")
    assert code == 0, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["working_sizes"] == summary["image_sizes"] and summary["config"]["min_side"] == "auto"
    assert summary["side_limits"] == {"min_side": None, "max_side": None}
    assert summary["working_factors"]["image0"] == [1.0, 1.0]
    from slime_match.cli.commands import build_parser
    from slime_match.cli.match_options import config_of

    args = build_parser().parse_args(["match", *pair, "-o", str(tmp_path), "--max-side", "none"])
    assert config_of(args).side_limits() == (480, None)


def test_bad_working_size_options(pair, tmp_path, capsys):
    for bad in (["--min-side", "big"], ["--max-side", "1.5"], ["--min-side", ""]):
        with pytest.raises(SystemExit):
            main(["match", *pair, "-o", str(tmp_path), *bad])
    for bad, message in ((["--min-side", "8"], "min_side must be an integer of at least 32 px"),
                         (["--min-side", "-480"], "min_side must be an integer of at least 32 px"),
                         (["--min-side", "900", "--max-side", "600"], "min_side 900 px is larger than max_side 600")):
        code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift", *bad)
        assert code == 2 and message in err and not (tmp_path / "matches.npz").exists(), err


def test_workers_option_sets_slime_processes_and_keeps_the_matches(pair, tmp_path, capsys, caplog):
    """On the CPU, ``--workers 1`` (no forks) and ``--workers 2`` give the same matches; -v and the summary name
    the count. (On CUDA the block crops are detected on the GPU without workers and on the CPU workers with
    them, which rounds differently.)"""
    caplog.set_level("INFO", logger="slime_match")
    for workers in (1, 2):
        code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / str(workers), *WEIGHT_FREE, "--scales", "1",
                               "--workers", workers, "--device", "cpu", "--no-plot", "-v")
        assert code == 0, err
        assert f"{workers} worker process" in caplog.text
        summary = json.loads((tmp_path / str(workers) / "summary.json").read_text())
        assert summary["config"]["slime"]["workers"] == workers
    one, two = (np.load(tmp_path / str(w) / "matches.npz") for w in (1, 2))
    assert len(one["scores"]) > 0
    for key in ("keypoints0", "keypoints1", "scores"):
        assert np.array_equal(one[key], two[key])


def test_verbose_logs_stages_as_they_finish(pair, tmp_path, capsys, caplog):
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path, *WEIGHT_FREE, "--scales", "1,2", "-v",
                           "--no-plot")
    assert code == 0, err
    assert "Slime: 8 x 8 blocks (64 block pairs)" in caplog.text
    summary = json.loads((tmp_path / "summary.json").read_text())
    for stage in ("features", "block_pairs", "plane_selection", "global_dtm"):
        assert f"{stage}: " in caplog.text and stage in summary["seconds"]
    caplog.clear()
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "quiet", "--method", "rootsift", "--no-plot")
    assert code == 0 and "features: " not in caplog.text


def test_viz_bad_input(tmp_path, capsys, pair):
    code, _, err = run_cli(capsys, "viz", tmp_path / "none.npz", *pair, "-o", tmp_path)
    assert code == 2 and "no such stages file" in err
    text = tmp_path / "notes.npz"
    text.write_text("not an archive")
    code, _, err = run_cli(capsys, "viz", text, *pair, "-o", tmp_path)
    assert code == 2 and "not a stages file (not an .npz archive)" in err
    matches = tmp_path / "matches.npz"  # a matches file, without the stages
    np.savez(matches, keypoints0=np.zeros((0, 2)), keypoints1=np.zeros((0, 2)), scores=np.zeros(0))
    code, _, err = run_cli(capsys, "viz", matches, *pair, "-o", tmp_path / "viz")
    assert code == 2 and "not a stages file: it has no blocks0, blocks1, tiles0 and" in err
    assert "--save-stages" in err and not (tmp_path / "viz").exists()


@pytest.mark.parametrize("command", [["match", "IMAGE0", "IMAGE1"], ["demo"], ["viz", "STAGES", "IMAGE0", "IMAGE1"],
                                     ["bench", "graf"]])
def test_output_folder_that_is_a_file_is_refused_up_front(tmp_path, capsys, pair, command):
    blocker = tmp_path / "taken"
    blocker.write_text("")
    stand_in = {"IMAGE0": pair[0], "IMAGE1": pair[1], "STAGES": tmp_path / "stages.npz"}
    args = [stand_in.get(part, part) for part in command]
    for output, problem in ((blocker, "is a file"), (blocker / "run", f"lies under {blocker}, which is a file")):
        code, _, err = run_cli(capsys, *args, "-o", output)
        assert code == 2 and f"output folder {output} {problem}, not a folder" in err


def test_demo_scores_the_real_pair(tmp_path, capsys):
    (tmp_path / "stages.npz").write_bytes(b"an earlier run's")
    (tmp_path / "notes.txt").write_text("mine")
    code, out, err = run_cli(capsys, "demo", "-o", tmp_path, "--method", "rootsift")
    assert code == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "matches.npz", "matches.png", "motorcycle_left.png", "motorcycle_right.png", "notes.txt", "summary.json"]
    gt = json.loads((tmp_path / "summary.json").read_text())["ground_truth"]
    assert gt["precision"] > 0.8 and "precision" in out


def _interrupted_in_compiled_code(*args, **kwargs):
    """What numba raises when Ctrl-C arrives inside a compiled function."""
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as inner:
        raise SystemError("CPUDispatcher(...) returned a result with an exception set") from inner


def test_caused_by_interrupt_follows_the_cause_chain():
    with pytest.raises(SystemError) as info:
        _interrupted_in_compiled_code()
    assert caused_by_interrupt(info.value)
    assert not caused_by_interrupt(ValueError("plain"))


def test_ctrl_c_inside_compiled_code_is_an_interruption(pair, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(slime_match.matcher, "run_slime", _interrupted_in_compiled_code)
    with pytest.raises(KeyboardInterrupt):  # the API raises what the user pressed
        Matcher(make_config("slime", shape="baumberg", orientation="gradient", descriptor="rootsift"))(*pair)
    code, _, err = run_cli(capsys, "match", *pair, "-o", tmp_path / "out", *WEIGHT_FREE)
    assert code == 130 and err.strip().splitlines()[-1] == "interrupted"  # after the stage lines that finished
    assert not (tmp_path / "out").exists()


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0 and capsys.readouterr().out.strip() == f"slime-match {slime_match.__version__}"
