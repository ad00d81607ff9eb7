"""``slime pairs``: pairs files, one folder per pair, resuming, failures recorded, workers."""

import itertools
import json
import multiprocessing
import os
import signal
import threading
import time

import cv2
import numpy as np
import pytest
from conftest import run_cli

from slime_match._runtime.cpus import available_cpus
from slime_match.config import make_config
from slime_match.errors import ConfigError, ImageError
from slime_match.runs.batch import PairJob, match_pairs, read_pairs

FAST = ["--method", "rootsift"]  # the base RootSIFT alone: the run logic, not the matcher, is under test
SLIME_SMALL = ["--shape", "baumberg", "--orientation", "gradient", "--descriptor", "rootsift", "--scales", "1"]


@pytest.fixture
def images(images):
    """The batch folder (conftest) with a corrupt image besides."""
    (images / "broken.png").write_bytes(b"\x89PNG not really")
    return images


def _pairs_file(tmp_path, text):
    path = tmp_path / "pairs.txt"
    path.write_text(text)
    return path


def test_read_pairs_format(images, tmp_path):
    text = "# stereo\nleft.png right.png\n\nleft.png sub/right.png  # the copy\nleft.png right.png\n"
    jobs = read_pairs(_pairs_file(tmp_path, text), images)
    assert [(j.name0, j.name1) for j in jobs] == [("left.png", "right.png"), ("left.png", "sub/right.png")]
    assert [j.folder for j in jobs] == ["left.png__right.png", "left.png__sub-right.png"]
    assert jobs[1].path1 == images / "sub" / "right.png"
    windows = tmp_path / "windows.txt"  # a byte-order mark and CRLF line ends, as Windows editors write
    windows.write_bytes("\ufeffleft.png right.png\r\nleft.png sub/right.png\r\n".encode("utf-8"))
    assert [(j.name0, j.name1) for j in read_pairs(windows, images)] == [(j.name0, j.name1) for j in jobs]


@pytest.mark.parametrize("text, error, words", [
    ("left.png right.png\nleft.png\n", ConfigError, "pairs.txt:2: expected two image names, got 1"),
    ("# nothing\n\n", ConfigError, "lists no pair"),
    ("left.png right.png\nleft.png gone.png\nx.png left.png\n", ImageError, "2 image(s)"),
    ("left.png sub/right.png\nleft.png sub-right.png\n", ConfigError, "share the output folder"),
])
def test_read_pairs_errors(images, tmp_path, text, error, words):
    (images / "sub-right.png").write_bytes(b"")  # exists, so that only the folder clash is reported
    with pytest.raises(error) as info:
        read_pairs(_pairs_file(tmp_path, text), images)
    assert words in str(info.value)
    with pytest.raises(ConfigError, match="cannot read the pairs file"):
        read_pairs(tmp_path / "absent.txt", images)


def test_pairs_run_resume_failures_and_config_guard(images, tmp_path, capsys, caplog):
    pairs = _pairs_file(tmp_path, "left.png right.png\nright.png left.png\nleft.png broken.png\n")
    out = tmp_path / "run"
    code, stdout, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST)
    assert code == 1 and "3 pairs: 2 matched, 0 already done, 1 failed" in stdout, err
    assert "feature cache" not in stdout  # the base alone has no block or tile features
    index = json.loads((out / "pairs.json").read_text())
    assert index["finished"] and [r["status"] for r in index["pairs"]] == ["done", "done", "failed"]
    assert "broken.png" in index["pairs"][2]["error"] and not (out / "left.png__broken.png").exists()
    for record in index["pairs"][:2]:
        data = np.load(out / record["folder"] / "matches.npz")
        summary = json.loads((out / record["folder"] / "summary.json").read_text())
        assert len(data["scores"]) == record["matches"] == summary["counts"]["matches"] > 100
    assert not (out / "left.png__right.png" / "matches.png").exists()  # plots are opt-in (--plot)
    assert json.loads((out / "run.json").read_text())["config"]["method"] == "rootsift"

    stamp = (out / "left.png__right.png" / "matches.npz").stat().st_mtime_ns
    code, stdout, _ = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST)
    assert code == 1 and "0 matched, 2 already done, 1 failed" in stdout
    assert (out / "left.png__right.png" / "matches.npz").stat().st_mtime_ns == stamp

    code, _, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST, "--upright")
    assert code == 2 and "another configuration" in err and "base.upright" in err

    good = _pairs_file(tmp_path, "left.png right.png\n")
    (out / "right.png__left.png" / "notes.txt").write_text("mine")
    caplog.clear()
    code, stdout, _ = run_cli(capsys, "pairs", good, "--images", images, "-o", out, *FAST, "--upright",
                              "--overwrite", "--plot")
    assert code == 0 and "1 matched, 0 already done, 0 failed" in stdout
    assert (out / "left.png__right.png" / "matches.png").is_file()
    assert json.loads((out / "run.json").read_text())["config"]["base"]["upright"] is True
    # the pairs of the earlier configuration that this pairs file does not list go, a user's file stays
    assert "removed 2 pair(s) of the earlier configuration" in caplog.text
    assert sorted(p.name for p in (out / "records").iterdir()) == ["left.png__right.png.json"]
    assert [p.name for p in (out / "right.png__left.png").iterdir()] == ["notes.txt"]
    assert not (out / "left.png__broken.png").exists()
    caplog.clear()
    other = tmp_path / "other.txt"
    other.write_text("right.png left.png\n")
    code, stdout, _ = run_cli(capsys, "pairs", other, "--images", images, "-o", out, *FAST, "--upright",
                              "--overwrite")  # the same configuration: nothing removed
    assert code == 0 and "removed" not in caplog.text and "1 matched, 0 already done, 0 failed" in stdout
    assert (out / "left.png__right.png" / "matches.npz").is_file()


def test_a_rerun_leaves_only_its_own_files_in_a_pair_folder(images, tmp_path, capsys):
    pairs = _pairs_file(tmp_path, "left.png right.png\n")
    out, folder = tmp_path / "run", tmp_path / "run" / "left.png__right.png"
    code, _, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST, "--plot")
    assert code == 0, err
    (folder / "notes.txt").write_text("mine")
    code, _, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST, "--overwrite")
    assert code == 0, err
    assert sorted(p.name for p in folder.iterdir()) == ["matches.npz", "notes.txt", "summary.json"]
    (images / "left.png").write_bytes(b"\x89PNG not really")  # the pair now fails: its earlier files go
    code, _, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST, "--overwrite")
    assert code == 1, err
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt"]
    assert json.loads((out / "pairs.json").read_text())["pairs"][0]["status"] == "failed"


def test_pairs_bad_input_fails_before_any_work(images, tmp_path, capsys):
    out = tmp_path / "run"
    pairs = _pairs_file(tmp_path, "left.png right.png\nleft.png missing.png\n")
    code, _, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST)
    assert code == 2 and "missing.png" in err and not out.exists()
    good = _pairs_file(tmp_path, "left.png right.png\n")
    code, _, err = run_cli(capsys, "pairs", good, "--images", images, "-o", out, *FAST, "--workers", "0")
    assert code == 2 and "workers must be >= 1" in err and not out.exists()


def test_pairs_workers_give_the_same_matches(images, tmp_path, capsys):
    """Slime (weight-free, one block scale for speed) in two spawned workers, each with its share of the
    cores, gives the matches of one process."""
    pairs = _pairs_file(tmp_path, "left.png right.png\nright.png left.png\nleft.png sub/right.png\n")
    runs = {}
    for workers in (1, 2):
        out = tmp_path / f"run{workers}"
        code, stdout, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *SLIME_SMALL,
                                    "--workers", workers)
        assert code == 0, err
        runs[workers] = out
        if workers == 1:  # the first pair computes the blocks and tiles of its 2 images, the others reuse them
            assert "feature cache: 8 of 12 feature sets" in stdout, stdout
    for folder in ("left.png__right.png", "right.png__left.png", "left.png__sub-right.png"):
        a, b = (np.load(runs[w] / folder / "matches.npz") for w in (1, 2))
        assert len(a["scores"]) > 100 and np.array_equal(a["keypoints0"], b["keypoints0"])
        assert np.array_equal(a["keypoints1"], b["keypoints1"])
    summary = json.loads((runs[2] / "left.png__right.png" / "summary.json").read_text())
    assert summary["config"]["slime"]["workers"] == max(1, available_cpus() // 2)  # no oversubscription


def test_pool_workers_may_fork_slime_workers(images, tmp_path):
    """Two pool workers, each running Slime with two forked workers of its own (what a machine of four cores or
    more, or a GPU machine, gives by default): pool workers must be able to have children."""
    config = make_config("slime", scales=(1,), workers=2, shape="baumberg", orientation="gradient",
                         descriptor="rootsift")
    jobs = read_pairs(_pairs_file(tmp_path, "left.png right.png\nright.png left.png\n"), images)
    records = match_pairs(config, jobs, tmp_path / "run", workers=2)
    assert [r["status"] for r in records] == ["done", "done"], records
    assert all(r["matches"] > 100 for r in records)


def test_an_exhaustive_run_computes_each_image_once(images, tmp_path):
    """Four distinct images, every pair: each image's blocks and tiles are computed once, the rest comes from
    the feature cache, whatever the order the pairs are matched in; records stay in file order."""
    left = cv2.imread(str(images / "left.png"))
    right = cv2.imread(str(images / "right.png"))
    cv2.imwrite(str(images / "left_flipped.png"), left[:, ::-1])
    cv2.imwrite(str(images / "right_flipped.png"), right[:, ::-1])
    names = ["left.png", "left_flipped.png", "right.png", "right_flipped.png"]
    pairs = _pairs_file(tmp_path, "".join(f"{a} {b}\n" for a, b in itertools.combinations(names, 2)))
    # views off: the mirrored pairs match little and would try every view, which a test of the cache does not need
    config = make_config("slime", views="off", **{k.strip("-"): v for k, v in zip(SLIME_SMALL[::2], SLIME_SMALL[1::2])})
    records = match_pairs(config, read_pairs(pairs, images), tmp_path / "run")
    assert [(r["image0"], r["image1"]) for r in records] == list(itertools.combinations(names, 2))
    counts = [json.loads((tmp_path / "run" / r["folder"] / "summary.json").read_text())["counts"] for r in records]
    assert [(r["feature_sets"], r["cached_feature_sets"]) for r in records] == [
        (c["feature_sets"], c["cached_feature_sets"]) for c in counts]
    assert sum(r["feature_sets"] for r in records) == 6 * 4
    assert sum(r["cached_feature_sets"] for r in records) == 6 * 4 - 4 * 2, records


def test_a_dead_worker_fails_its_pair_and_is_replaced(images, tmp_path):
    """Two workers stuck on their pairs (FIFOs without a writer: reading them never ends) are killed: their two
    pairs fail with the reason, and a new worker matches the pair that was left."""
    for name in ("stuck0.png", "stuck1.png"):
        os.mkfifo(images / name)
    jobs = [PairJob(name, "right.png", images / name, images / "right.png", f"{name}__right.png")
            for name in ("stuck0.png", "stuck1.png")]
    jobs += read_pairs(_pairs_file(tmp_path, "left.png right.png\n"), images)

    def kill_both_workers():
        deadline = time.monotonic() + 120
        while len(workers := [p for p in multiprocessing.active_children() if p.name == "slime-pairs-worker"]) < 2:
            assert time.monotonic() < deadline
            time.sleep(0.1)
        time.sleep(1)
        for process in workers:
            os.kill(process.pid, signal.SIGKILL)

    killer = threading.Thread(target=kill_both_workers)
    killer.start()
    records = match_pairs(make_config("rootsift"), jobs, tmp_path / "run", workers=2)
    killer.join()
    assert [r["status"] for r in records] == ["failed", "failed", "done"], records
    assert all("worker process died (exit code -9" in r["error"] for r in records[:2])
    assert records[2]["matches"] > 100
    assert not (tmp_path / "run" / "stuck0.png__right.png").exists()


def test_cpus_per_worker_sets_each_worker_s_share(images, tmp_path, capsys):
    pairs = _pairs_file(tmp_path, "left.png right.png\nright.png left.png\n")
    out = tmp_path / "run"
    code, stdout, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST, "--workers", 2,
                                "--cpus-per-worker", 3)
    assert code == 0 and "2 matched" in stdout, err
    summary = json.loads((out / "left.png__right.png" / "summary.json").read_text())
    assert summary["config"]["slime"]["workers"] == 3
    with pytest.raises(SystemExit) as stop:  # argparse: a one-line error, exit code 2
        run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST, "--cpus-per-worker", 0)
    assert stop.value.code == 2 and "--cpus-per-worker: expected at least 1" in capsys.readouterr().err
