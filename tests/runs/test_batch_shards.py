"""``slime pairs --shard I/N`` and ``--reindex``: the split of a pairs list, concurrent shards writing one run
folder, and the index rebuilt from the pair records."""

import itertools
import json
import os
import shutil
import subprocess
import sys

import pytest
from conftest import run_cli

from slime_match.errors import ConfigError
from slime_match.runs.batch import read_pairs
from slime_match.runs.index import write_index
from slime_match.runs.shards import parse_shard, shard_positions

FAST = ["--method", "rootsift"]
PAIRS = ("left.png right.png\nright.png left.png\nleft.png sub/right.png\nsub/right.png left.png\n"
         "right.png sub/right.png\nsub/right.png right.png\n")


def _images_of(pairs, positions):
    return {image for k in positions for image in pairs[k]}


@pytest.mark.parametrize("count", [1, 2, 3, 5, 28, 30])
def test_shards_split_a_list_into_balanced_disjoint_parts(count):
    pairs = list(itertools.combinations(range(8), 2))  # 28 pairs, one component
    parts = [shard_positions(pairs, index, count) for index in range(1, count + 1)]
    assert sorted(itertools.chain(*parts)) == list(range(len(pairs)))
    assert max(map(len, parts)) - min(map(len, parts)) <= 1
    assert all(part == sorted(part) for part in parts)  # list order within a part
    assert parts == [shard_positions(pairs, index, count) for index in range(1, count + 1)]  # deterministic


def test_shards_keep_pairs_that_share_images_together():
    first = list(itertools.combinations("abcd", 2))  # 6 pairs each, their lines interleaved
    second = list(itertools.combinations("wxyz", 2))
    pairs = [pair for both in zip(first, second) for pair in both]
    parts = [shard_positions(pairs, index, 2) for index in (1, 2)]
    assert [_images_of(pairs, part) for part in parts] == [set("abcd"), set("wxyz")]
    frames = [(k, k + step) for step in (1, 2) for k in range(30 - step)]  # video frames, each with the 2 next
    for index in (1, 2, 3):
        images = sorted(_images_of(frames, shard_positions(frames, index, 3)))
        assert images == list(range(images[0], images[-1] + 1)) and len(images) <= 12  # a run of frames


@pytest.mark.parametrize("text", ["3/2", "0/2", "1/0", "a/2", "2", "1/2/3", ""])
def test_bad_shards_are_refused(text, tmp_path, capsys):
    with pytest.raises(ConfigError, match="I/N"):
        parse_shard(text)
    with pytest.raises(SystemExit) as exit_info:  # argparse: a one-line error, exit code 2
        run_cli(capsys, "pairs", tmp_path / "pairs.txt", "-o", tmp_path / "run", "--shard", text)
    assert exit_info.value.code == 2 and "--shard" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_concurrent_shards_keep_every_record_and_reindex_rebuilds_the_index(images, tmp_path, capsys):
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(PAIRS)
    out = tmp_path / "run"
    command = [sys.executable, "-m", "slime_match.cli", "pairs", str(pairs), "--images", str(images), "-o",
               str(out), *FAST]
    shards = [subprocess.Popen([*command, "--shard", f"{index}/2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True) for index in (1, 2)]
    outputs = [shard.communicate(timeout=300) for shard in shards]
    for index, (shard, (stdout, stderr)) in enumerate(zip(shards, outputs), 1):
        assert shard.returncode == 0, stderr
        assert f"shard {index}/2: 3 pairs: 3 matched, 0 already done, 0 failed" in stdout
    jobs = read_pairs(pairs, images)
    index = json.loads((out / "pairs.json").read_text())
    assert index["finished"] and [r["folder"] for r in index["pairs"]] == [job.folder for job in jobs]
    assert all(r["status"] == "done" and r["matches"] > 100 for r in index["pairs"])
    assert sorted(os.listdir(out / "records")) == sorted(f"{job.folder}.json" for job in jobs)

    (out / "pairs.json").unlink()
    (out / "records" / f"{jobs[0].folder}.json").unlink()  # a finished folder whose record was lost
    code, stdout, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, "--reindex")
    assert code == 0 and "6 pairs: 6 done, 0 failed, 0 not recorded" in stdout, err
    assert json.loads((out / "pairs.json").read_text()) == index

    shutil.rmtree(out / jobs[5].folder)  # an unfinished pair, without a record: not in the index
    (out / "records" / f"{jobs[5].folder}.json").unlink()
    rebuilt = write_index(out, jobs)
    assert not rebuilt["finished"] and [r["folder"] for r in rebuilt["pairs"]] == [j.folder for j in jobs[:5]]
    code, stdout, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", out, *FAST, "--shard", "2/2")
    assert code == 0 and "shard 2/2: 3 pairs: 1 matched, 2 already done" in stdout, err
    assert json.loads((out / "pairs.json").read_text())["finished"]


def test_reindex_refuses_what_it_cannot_do(images, tmp_path, capsys):
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(PAIRS)
    code, _, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", tmp_path / "none", "--reindex")
    assert code == 2 and "not a `slime pairs` run folder" in err and not (tmp_path / "none").exists()
    for option in (["--overwrite"], ["--ray"], ["--shard", "1/2"]):
        code, _, err = run_cli(capsys, "pairs", pairs, "--images", images, "-o", tmp_path / "run", "--reindex",
                               *option)
        assert code == 2 and "--reindex only rebuilds the index" in err
