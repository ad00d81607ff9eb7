"""``slime bench`` on the hard sets: the standard protocols per dataset and per pair, next to the other metrics,
and their command-line options."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from conftest import DATA, require

from slime_match.errors import ConfigError
from slime_match.eval import aggregation, bench
from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.datasets import Pair
from slime_match.eval.predictions import pair_slug
from slime_match.eval.scoring import PairGT, pair_protocol

HARD = DATA / "hard"
SIFT = "opencv-sift:rootsift=true,mutual=true"


def _parse(argv):
    parser = argparse.ArgumentParser()
    bench.add_bench_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["bench", *argv])


@pytest.fixture(scope="module")
def hard_run(tmp_path_factory):
    """SIFT on the first 2 pairs of EVD and of WxBS."""
    evd, wxbs = require(HARD / "evd"), require(HARD / "wxbs")
    out = tmp_path_factory.mktemp("hard")
    argv = [f"evd:{evd}", f"wxbs:{wxbs}", "--methods", SIFT, "--max-pairs", "2", "--thresholds", "none,3"]
    argv += ["--map-pairs", "0", "-o", str(out)]
    return out, argv


def test_protocols_per_pair_dataset_and_console(hard_run, capsys):
    out, argv = hard_run
    assert bench.main(argv) == 0
    console = capsys.readouterr().out
    summary = json.loads((out / "metrics.json").read_text())
    label = next(iter(summary["methods"]))
    assert [p["protocol"] for p in summary["pairs"]] == ["evd", "evd", "wxbs", "wxbs"]
    for pair in summary["pairs"]:
        rec = pair["methods"][label]
        assert 0 <= rec["protocol"]["maa"] <= 1 and set(rec["thresholds"]) == {"none", "3"}
        low, high = rec["protocol"]["maa_min"], rec["protocol"]["maa_max"]  # over the 10 orders of the matches
        assert low <= rec["protocol"]["maa"] <= high and low <= rec["protocol"]["maa_mean"] <= high
        if pair["protocol"] == "wxbs":
            assert len(rec["protocol"]["recall"]) == 20
            assert rec["protocol"]["maa"] == pytest.approx(np.mean(rec["protocol"]["recall"]))
        else:
            error = rec["protocol"]["error"]
            maa = np.mean([error is not None and error < t for t in range(1, 16)])
            assert rec["protocol"]["maa"] == pytest.approx(maa)
    agg = aggregation.aggregate(summary)
    for dataset, protocol in ((f"evd:{HARD / 'evd'}", "evd"), (f"wxbs:{HARD / 'wxbs'}", "wxbs")):
        row = agg["protocols"][(dataset, label)]
        members = [p for p in summary["pairs"] if p["dataset"] == dataset]
        maa = [p["methods"][label]["protocol"]["maa"] for p in members]
        assert row["protocol"] == protocol and row["pairs"] == 2
        assert row["maa"] == pytest.approx(np.mean(maa)) and row["solved"] == sum(m > 0 for m in maa)
        assert row["maa_mean"] == pytest.approx(np.mean([p["methods"][label]["protocol"]["maa_mean"] for p in members]))
        assert (f"{dataset} {label}: {protocol.upper()} mAA {row['maa']:.2f} ({row['maa_mean']:.2f} over 10 orders "
                f"of the matches), {row['solved']}/2 pairs solved") in console
    table = (out / "table.md").read_text()
    assert "### Standard protocols (raw matches, OpenCV MAGSAC++)" in table
    assert "MAGSAC++ 3 px" in table and "### Standard protocols per pair (pair mAA" in table
    assert "| mAA | mAA over 10 orders |" in table
    assert sum(line.startswith(("| evd/", "| wxbs/")) for line in table.splitlines()) == 4


def test_pairs_without_matches_are_counted_and_listed(hard_run, tmp_path, capsys):
    """A cached prediction without matches scores 0 and is named in the tables and the console."""
    out, argv = hard_run
    bench.main(argv)
    summary = json.loads((out / "metrics.json").read_text())
    label, name = next(iter(summary["methods"])), summary["pairs"][2]["name"]
    path = out / "predictions" / label / f"{pair_slug(name)}.npz"
    empty = np.zeros((0, 2))
    np.savez(path, keypoints0=empty, keypoints1=empty, scores=np.zeros(0), seconds=np.float64(0), code="test")
    capsys.readouterr()
    assert bench.main(argv) == 0
    console = capsys.readouterr().out
    summary = json.loads((out / "metrics.json").read_text())
    assert summary["pairs"][2]["methods"][label]["protocol"] == {
        "maa": 0.0, "maa_mean": 0.0, "maa_min": 0.0, "maa_max": 0.0, "recall": [0.0] * 20}
    assert f"1 without matches ({name})" in console
    assert f"| {name} |" in (out / "table.md").read_text().split("per pair")[0]


NEW_RECORD = {"mode": "auto", "images": "image0", "tilts": [2.0, 4.0], "views": 15, "decision": "kept",
              "reason": "every view tried",
              "tried": [{"image": 0, "tilt": 2.0, "views": 5, "planes": 3, "ftheta_matches": 0, "ftheta_by_angle": {}},
                        {"image": 0, "tilt": 4.0, "views": 10, "planes": 40, "ftheta_matches": 63,
                         "ftheta_by_angle": {"18": 50, "36": 20}}]}
EARLIER_RECORD = {"mode": "auto", "tilts": [2.0, 4.0], "views": 15, "reason": "every tilt tried",  # before "tried"
                  "found": [{"tilt": 2.0, "views": 5, "planes": 3, "ftheta_matches": 0, "ftheta_by_angle": {}},
                            {"tilt": 4.0, "views": 10, "planes": 40, "ftheta_matches": 63,
                             "ftheta_by_angle": {"18": 50, "36": 20}}]}
BOTH_RECORD = {"mode": "always", "images": "both", "tilts": [2.0], "views": 10, "decision": "kept",
               "reason": "every view tried",
               "tried": [{"image": 0, "tilt": 2.0, "views": 5, "planes": 3, "ftheta_matches": 0, "ftheta_by_angle": {}},
                         {"image": 1, "tilt": 2.0, "views": 5, "planes": 9, "ftheta_matches": 40,
                          "ftheta_by_angle": {"0": 40}}]}


@pytest.mark.parametrize("views, note", [
    (NEW_RECORD, "(views: tilt 2 [0], 4 [63 at 18, 36])"),
    (EARLIER_RECORD, "(views: tilt 2 [0], 4 [63 at 18, 36])"),
    (BOTH_RECORD, "(views: image 0 tilt 2 [0], image 1 tilt 2 [40 at 0])"),
])
def test_the_views_a_run_added_are_kept_and_shown_per_pair(hard_run, views, note):
    """A prediction's recorded decisions (summary.json's) reach metrics.json and the per-pair protocol table."""
    out, argv = hard_run
    bench.main(argv)
    summary = json.loads((out / "metrics.json").read_text())
    label, name = next(iter(summary["methods"])), summary["pairs"][0]["name"]
    path = out / "predictions" / label / f"{pair_slug(name)}.npz"
    saved = dict(np.load(path))
    np.savez(path, **saved | {"decisions": np.str_(json.dumps({"views": views}))})
    assert bench.main(argv) == 0
    summary = json.loads((out / "metrics.json").read_text())
    assert summary["pairs"][0]["methods"][label]["views"] == views
    assert "views" not in summary["pairs"][1]["methods"][label]  # SIFT records none
    rows = [line for line in (out / "table.md").read_text().splitlines() if line.startswith(f"| {name} |")]
    assert rows[-1].endswith(f"{note} |"), rows


def test_protocol_options():
    cfg = bench.config_from_args(_parse(["planar:x", "--protocol-datasets", "EVD, planar"]))
    assert cfg.protocol_datasets == ["evd", "planar"]
    assert (cfg.protocol_h_threshold, cfg.protocol_f_threshold, cfg.protocol_max_iters) == (3.0, 3.0, 10000)
    assert cfg.protocol_orders == 10
    cfg = bench.config_from_args(
        _parse(["wxbs:x", "--protocol-datasets", "", "--protocol-f-threshold", "0.5", "--protocol-max-iters", "99",
                "--protocol-orders", "1"])
    )
    assert cfg.protocol_datasets == [] and cfg.protocol_f_threshold == 0.5 and cfg.protocol_max_iters == 99
    assert cfg.protocol_orders == 1
    defaults = BenchConfig()
    assert defaults.protocol_datasets == ["evd", "wxbs"] and defaults.protocol_h_threshold == 3.0
    for bad in (["--protocol-h-threshold", "0"], ["--protocol-f-threshold", "-1"], ["--protocol-max-iters", "0"],
                ["--protocol-orders", "0"]):
        with pytest.raises(ConfigError):
            bench.config_from_args(_parse(["evd:x", *bad]))
    assert bench.config_from_args(_parse(["evd:x", "--methods", "asift;opencv-sift:mutual=true"])).methods == [
        "asift",
        "opencv-sift:mutual=true",
    ]


def test_protocol_follows_the_ground_truth_of_the_listed_datasets():
    config = BenchConfig(protocol_datasets=["evd", "wxbs", "planar"])
    image = np.zeros((4, 4))
    homography = PairGT(Pair("a", image, image, "homography", H=np.eye(3)), (4, 4), (4, 4))
    corrs = PairGT(Pair("b", image, image, "fundamental", F=np.eye(3), corrs=np.zeros((8, 4))), (4, 4), (4, 4))
    pose = PairGT(Pair("c", image, image, "fundamental", F=np.eye(3)), (4, 4), (4, 4))
    assert [pair_protocol(s, homography, config) for s in ("evd:/d", "planar:/d", "hpatches:/d")] == [
        "evd",
        "evd",
        None,
    ]
    assert [pair_protocol("wxbs:/d", gt, config) for gt in (corrs, pose)] == ["wxbs", None]
    assert pair_protocol("wxbs:/d", corrs, BenchConfig(protocol_datasets=[])) is None
