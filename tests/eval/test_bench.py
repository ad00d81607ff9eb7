"""Smoke tests of ``slime bench``: files, cache resumability, tables consistent with the per-pair metrics."""

from __future__ import annotations

import csv
import json
import logging
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import DATA, require

from slime_match.eval import aggregation, bench, methods
from slime_match.eval import metrics as M
from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.code_version import UNKNOWN, code_version

HZ_FREE = "hz+:descriptor=rootsift,shape=baumberg,orientation=gradient,max_keypoints=600"
METHODS = f"rootsift;{HZ_FREE}"


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    """A planar folder (graf img1 at 256x208 and an exact perspective warp of it) and a WxBS-style folder
    (the Middlebury motorcycle stereo pair at 0.4 scale, GT correspondences from its disparity)."""
    root = tmp_path_factory.mktemp("data")
    img = cv2.imread(str(require(DATA / "oxford_graf" / "img1.png")))
    img = cv2.resize(img, (256, 208), interpolation=cv2.INTER_AREA)
    H = np.array([[0.9, 0.12, 20.0], [-0.08, 0.95, 12.0], [2e-4, 1e-4, 1.0]])
    planar = root / "planar"
    planar.mkdir()
    cv2.imwrite(str(planar / "g1.png"), img)
    cv2.imwrite(str(planar / "g2.png"), cv2.warpPerspective(img, H, (256, 208), flags=cv2.INTER_LINEAR))
    np.savetxt(planar / "g_H12.txt", H)

    from skimage.data import stereo_motorcycle

    left, right, disp = stereo_motorcycle()
    pair = root / "wxbs" / "moto"
    pair.mkdir(parents=True)
    half = [cv2.resize(im, None, fx=0.4, fy=0.4, interpolation=cv2.INTER_AREA) for im in (left, right)]
    cv2.imwrite(str(pair / "01.png"), cv2.cvtColor(half[0], cv2.COLOR_RGB2BGR))
    cv2.imwrite(str(pair / "02.png"), cv2.cvtColor(half[1], cv2.COLOR_RGB2BGR))
    rows, cols = np.mgrid[8 : disp.shape[0] - 8 : 16, 8 : disp.shape[1] - 8 : 16]
    d = disp[rows, cols]
    ok = np.isfinite(d) & (cols - d >= 0)
    full = np.stack([cols[ok], rows[ok], cols[ok] - d[ok], rows[ok]], 1).astype(np.float64)
    np.savetxt(pair / "corrs.txt", (full + 0.5) * 0.4 - 0.5)  # pixel centres at 0.4 scale
    return root


def _args(tiny_data, out):
    return [
        f"planar:{tiny_data / 'planar'}",
        f"wxbs:{tiny_data / 'wxbs'}",
        "--methods",
        METHODS,
        "--rotations",
        "90",
        "--thresholds",
        "none,3",
        "--map-pairs",
        "1",
        "--device",
        "cpu",
        "-o",
        str(out),
    ]


@pytest.fixture(scope="module")
def first_run(tiny_data, tmp_path_factory):
    out = tmp_path_factory.mktemp("results")
    args = bench.config_from_args(_parse(_args(tiny_data, out)))
    stats = bench.run_bench(args)
    return out, stats


def _parse(argv):
    import argparse

    parser = argparse.ArgumentParser()
    bench.add_bench_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["bench", *argv])


def test_files_and_cache(first_run):
    out, stats = first_run
    protocols = stats.pop("protocols")  # the WxBS pair gets its standard protocol
    assert stats == {"computed": 6, "cached": 0, "pairs": 3, "output": str(out)}
    assert {(d.split(":")[0], v["protocol"], v["pairs"]) for (d, _), v in protocols.items()} == {("wxbs", "wxbs", 1)}
    for name in ("table.md", "table.csv", "metrics.json", "bar_coverage.png", "bar_accuracy.png"):
        assert (out / name).stat().st_size > 0
    preds = sorted((out / "predictions").rglob("*.npz"))
    assert len(preds) == 6
    assert {p.parent.name for p in preds} == {"rootsift", methods.method_label(HZ_FREE)}
    maps = list((out / "maps").rglob("*.png"))
    assert {p.name.split("_")[0] for p in maps} == {"coverage", "error"} and len(maps) == 4


def test_rerun_loads_cache_without_recomputing(first_run, tiny_data, monkeypatch):
    out, _ = first_run
    before = {p: p.stat().st_mtime_ns for p in (out / "predictions").rglob("*.npz")}
    table = (out / "table.csv").read_text()

    def refuse(*_, **__):
        raise AssertionError("a cached prediction was recomputed")

    monkeypatch.setattr(bench, "make_method", refuse)
    assert bench.main(_args(tiny_data, out)) == 0
    assert {p: p.stat().st_mtime_ns for p in (out / "predictions").rglob("*.npz")} == before
    assert (out / "table.csv").read_text() == table  # metrics are deterministic under the seed


def test_a_rerun_replaces_the_report_and_an_interrupted_one_leaves_it(first_run, tiny_data, tmp_path, monkeypatch):
    out = tmp_path / "copy"
    shutil.copytree(first_run[0], out)
    (out / "notes.txt").write_text("mine")
    report = {name: (out / name).read_bytes() for name in ("metrics.json", "table.md", "table.csv")}

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(bench, "evaluate_pair", interrupted)
        with pytest.raises(KeyboardInterrupt):
            bench.main([*_args(tiny_data, out), "--map-pairs", "0"])
    assert {name: (out / name).read_bytes() for name in report} == report and (out / "maps").is_dir()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
    assert bench.main([*_args(tiny_data, out), "--map-pairs", "0"]) == 0  # from the cache
    assert not (out / "maps").exists()  # the earlier run's maps go, the user's file stays
    assert (out / "notes.txt").read_text() == "mine" and (out / "table.csv").read_bytes() == report["table.csv"]


def test_predictions_record_their_code_and_stale_ones_are_reported(first_run, tiny_data, tmp_path, caplog):
    out, _ = first_run
    summary = json.loads((out / "metrics.json").read_text())
    assert {m["code"] for p in summary["pairs"] for m in p["methods"].values()} == {code_version()}
    copy = tmp_path / "results"
    shutil.copytree(out, copy)
    old = next((copy / "predictions" / "rootsift").glob("*.npz"))
    with np.load(old) as data:  # a prediction written before code versions were recorded
        np.savez(old, **{k: data[k] for k in data.files if k != "code"})
    with caplog.at_level(logging.WARNING, logger="slime_match"):
        assert bench.main(_args(tiny_data, copy)) == 0
    assert f"1 predictions of rootsift come from code {UNKNOWN}" in caplog.text
    times = (copy / "table.md").read_text().split("### Time per pair")[1]
    rootsift = next(line for line in times.splitlines() if line.startswith("| RootSIFT |"))
    assert rootsift.endswith(f"| {code_version()} (2), {UNKNOWN} (1) |")  # most pairs first


def test_table_consistent_with_metrics(first_run):
    out, _ = first_run
    summary = json.loads((out / "metrics.json").read_text())
    assert [p["group"] for p in summary["pairs"]] == ["planar", "planar", "non-planar"]
    assert [p["upright"] for p in summary["pairs"]] == [True, False, True]
    rows = list(csv.DictReader((out / "table.csv").open()))
    assert len(rows) == 2 * 2 * 2  # groups x methods x thresholds
    for row in rows:
        pairs = [p for p in summary["pairs"] if p["group"] == row["group"]]
        recs = [p["methods"][row["method"]]["thresholds"][row["threshold"]] for p in pairs]
        errors = np.array([math.inf if r["error"] is None else r["error"] for r in recs])
        assert float(row["coverage"]) == pytest.approx(
            100 * np.mean([r["coverage"] for r in recs]), abs=0.006
        )
        assert float(row["precision"]) == pytest.approx(
            100 * np.mean([r["precision"] for r in recs]), abs=0.006
        )
        assert float(row["accuracy"]) == pytest.approx(100 * M.mean_average_accuracy(errors), abs=0.006)
        assert int(row["no_match"]) == sum(r["n_matches"] == 0 for r in recs)
        assert int(row["wrong_only"]) == sum(r["n_matches"] > 0 and r["n_correct"] == 0 for r in recs)
        for r in recs:
            assert 0 <= r["n_correct"] <= r["n_matches"] and 0 <= r["coverage"] <= 1
    for method in summary["methods"]:  # the best threshold maximises the non-planar accuracy
        mine = [r for r in rows if r["method"] == method and r["group"] == "non-planar"]
        best = [r for r in mine if r["best"] == "1"]
        assert len(best) == 1 and float(best[0]["accuracy"]) == max(float(r["accuracy"]) for r in mine)
    table = (out / "table.md").read_text()
    assert "| RootSIFT | 3 |" in table and "| RootSIFT | -- |" in table
    assert (
        table.count("Hz+ [descriptor=rootsift, shape=baumberg, orientation=gradient, max_keypoints=600] |")
        == 1 + 1 + 2 + 1 + 1 + 1
    )  # main, original vs rotated, detailed (2 thresholds), WxBS protocol, its per-pair header, time


def test_rotated_pairs_table(first_run):
    """The planar pairs are also reported split into original and rotated pairs, from the same records."""
    out, _ = first_run
    summary = json.loads((out / "metrics.json").read_text())
    agg = aggregation.aggregate(summary)
    original, rotated = summary["pairs"][0], summary["pairs"][1]
    for method in summary["methods"]:
        for th in summary["config"]["thresholds"]:
            for group, pair in (("planar original", original), ("planar rotated", rotated)):
                rec = pair["methods"][method]["thresholds"][th]
                row = agg["rotation_rows"][(group, method, th)]
                assert row["pairs"] == 1
                assert row["coverage"] == pytest.approx(100 * rec["coverage"])
                assert row["no_match"] == (rec["n_matches"] == 0)
    table = (out / "table.md").read_text()
    assert "### Planar pairs: original vs rotated" in table and "planar original 1, planar rotated 1 pairs" in table


def test_metrics_are_meaningful(first_run):
    """RootSIFT + homography RANSAC on an exact synthetic warp (and its 90 deg rotation) is near-perfect;
    RANSAC keeps a subset of the raw matches."""
    out, _ = first_run
    summary = json.loads((out / "metrics.json").read_text())
    for pair in summary["pairs"][:2]:
        rs = pair["methods"]["rootsift"]["thresholds"]
        assert rs["3"]["precision"] > 0.95 and rs["3"]["error"] < 2.0 and rs["3"]["coverage"] > 0.2
        assert rs["3"]["n_matches"] <= rs["none"]["n_matches"] == pair["methods"]["rootsift"]["raw_matches"]
    moto = summary["pairs"][2]["methods"]["rootsift"]["thresholds"]["3"]
    assert moto["precision"] > 0.8 and moto["n_matches"] > 50


def test_pose_pair_gets_auc(tmp_path):
    require(DATA / "scannet_sample")
    stats = bench.run_bench(
        BenchConfig(
            datasets=["scannet-sample"],
            methods=["opencv-sift"],
            output=str(tmp_path),
            thresholds=["none", "2"],
            max_pairs=1,
            map_pairs=0,
        )
    )
    assert stats["computed"] == 1
    summary = json.loads((tmp_path / "metrics.json").read_text())
    errs = summary["pairs"][0]["methods"]["opencv-sift"]["thresholds"]["2"]["pose_errors"]
    assert set(errs) == {"0.5", "1", "2", "3"}
    table = (tmp_path / "table.md").read_text()
    assert "### Pose AUC" in table and "| OpenCV SIFT | 2 |" in table


def _hard_folder(out: Path, tmp_path: Path, datasets: list[str]) -> Path:
    """A copy of the results folder ``out`` that says it scored ``datasets`` (a second folder for the doc)."""
    extra = tmp_path / "hard"
    shutil.copytree(out, extra)
    summary = json.loads((extra / "metrics.json").read_text())
    summary["config"]["datasets"] = datasets
    (extra / "metrics.json").write_text(json.dumps(summary))
    return extra


def test_results_doc_holds_every_folder_with_its_code(first_run, tmp_path):
    """``python -m slime_match.eval.report A --extra B --doc D``: D quotes the command, then A's tables and
    B's under a heading of B's datasets, each with the code versions of its predictions."""
    from slime_match.eval import report

    out, _ = first_run
    extra = _hard_folder(out, tmp_path, ["evd:/data/evd", "wxbs:/data/wxbs"])
    doc = tmp_path / "results.md"
    assert report.main([str(out), "--extra", str(extra), "--doc", str(doc), "--command", "run it"]) == 0
    text = doc.read_text()
    assert text.startswith("# Benchmark results\n\nGenerated by `run it`.")
    assert text.count(f"code `{code_version()}`") == 2 and "\n## evd, wxbs\n" in text
    assert text.index(f"`{out}`") < text.index("## evd, wxbs") < text.index(f"`{extra}`")
    assert (extra / "table.md").stat().st_size > 0
    assert "/data/evd" in text and "DATA/" not in text


def test_results_doc_writes_the_data_folder_as_DATA(first_run, tmp_path):
    """``--data-root R``: the datasets' paths under R read ``DATA/...`` in the document, wherever R was."""
    from slime_match.eval import report

    out, _ = first_run
    extra = _hard_folder(out, tmp_path, ["evd:../lab/data/hard/evd", "wxbs:../lab/data/hard/wxbs"])
    doc = tmp_path / "results.md"
    assert report.main([str(out), "--extra", str(extra), "--doc", str(doc), "--data-root", "../lab/data/"]) == 0
    text = doc.read_text()
    assert "../lab" not in text and "datasets: evd:DATA/hard/evd, wxbs:DATA/hard/wxbs;" in text
