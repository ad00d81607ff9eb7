"""Reading a `slime pairs` run, merging its keypoints per image with one-to-one matches, staging exports."""

import os
import stat

import numpy as np
import pytest
from conftest import export_pairs, write_run_folder

from slime_match.errors import ConfigError, ImageError, SlimeMatchError
from slime_match.io import save_json
from slime_match.runs.export import (
    PairMatches,
    check_export_folder,
    check_images,
    merge_keypoints,
    read_run,
    staged_folder,
)


def test_merge_keypoints_exact():
    keypoints, matches, scores = merge_keypoints(export_pairs(), merge_radius=1.0)
    # image a: (10.4, 10.3) (score 0.05) absorbs (10, 10); (5, 5) (0.2) and (50, 50) (0.3) absorb (50.5, 50)
    np.testing.assert_array_equal(keypoints["a.png"], [[10.4, 10.3], [5, 5], [50, 50]])
    np.testing.assert_array_equal(keypoints["b.png"], [[20, 20], [30, 30], [60, 60]])
    np.testing.assert_array_equal(keypoints["c.png"], [[9, 9], [7, 7]])
    # a-b by score: (a0, b0) at 0.05; 0.1 repeats it, 0.2 reuses a0; (a2, b2) at 0.3
    np.testing.assert_array_equal(matches[0], [[0, 0], [2, 2]])
    np.testing.assert_array_equal(matches[1], [[1, 0], [2, 1]])
    np.testing.assert_array_equal(scores[0], [0.05, 0.3])
    np.testing.assert_array_equal(scores[1], [0.2, 0.4])


def test_merge_radius_zero_merges_only_identical_positions():
    keypoints, matches, _ = merge_keypoints(export_pairs(), merge_radius=0)
    assert len(keypoints["a.png"]) == 5  # (10, 10) once, (10.4, 10.3), (50, 50), (50.5, 50), (5, 5)
    assert len(matches[0]) == 3  # (10, 10) and (10.4, 10.3) are now two keypoints: one more match
    for pair_matches in matches:
        assert len(np.unique(pair_matches[:, 0])) == len(np.unique(pair_matches[:, 1])) == len(pair_matches)


def test_merge_keypoints_empty_pair_and_bad_radius():
    empty = PairMatches("a.png", "d.png", np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
    keypoints, matches, scores = merge_keypoints([*export_pairs(), empty])
    assert keypoints["d.png"].shape == (0, 2) and matches[2].shape == (0, 2) and scores[2].shape == (0,)
    for bad in (-1, float("nan")):
        with pytest.raises(ConfigError, match="merge_radius"):
            merge_keypoints(export_pairs(), merge_radius=bad)


def test_read_run(tmp_path):
    pairs = read_run(write_run_folder(tmp_path, export_pairs(), inliers=True), inliers_only=True)
    assert [(p.name0, p.name1) for p in pairs] == [("a.png", "b.png"), ("a.png", "c.png")]  # not the failed one
    np.testing.assert_array_equal(pairs[0].scores, [0.1, 0.2, 0.05])
    with pytest.raises(SlimeMatchError, match="--ransac"):
        read_run(write_run_folder(tmp_path / "plain", export_pairs()), inliers_only=True)
    with pytest.raises(SlimeMatchError, match="not a `slime pairs` run folder"):
        read_run(tmp_path / "nowhere")
    save_json(tmp_path / "failed" / "pairs.json", {"pairs": [{"status": "failed"}]})
    with pytest.raises(SlimeMatchError, match="no finished pair"):
        read_run(tmp_path / "failed")


def test_check_images(tmp_path, small_images):
    assert check_images(export_pairs(), small_images) == ["a.png", "b.png", "c.png"]
    (small_images / "b.png").unlink()
    with pytest.raises(ImageError, match="1 image.* not found .*b.png"):
        check_images(export_pairs(), small_images)


def test_export_folder_checks(tmp_path):
    out, own = tmp_path / "out", ("marker.db", "sparse")
    check_export_folder(out, own, "COLMAP", overwrite=False)  # absent: fine
    out.mkdir()
    check_export_folder(out, own, "COLMAP", overwrite=False)  # empty: fine
    (out / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match="holds no COLMAP export"):
        check_export_folder(out, own, "COLMAP", overwrite=True)
    (out / "marker.db").write_text("")
    (out / "sparse").mkdir()
    with pytest.raises(ConfigError, match="earlier COLMAP export: use --overwrite"):
        check_export_folder(out, own, "COLMAP", overwrite=False)
    with pytest.raises(ConfigError, match=r"not part of a COLMAP export \(notes.txt\), which --overwrite would "):
        check_export_folder(out, own, "COLMAP", overwrite=True)  # a user's file is never deleted with it
    with pytest.raises(ConfigError, match="is a file"):
        check_export_folder(out / "notes.txt", own, "COLMAP", overwrite=True)
    (out / "notes.txt").unlink()
    check_export_folder(out, own, "COLMAP", overwrite=True)


def test_staged_folder_is_all_or_nothing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("old")
    with pytest.raises(RuntimeError), staged_folder(out) as staging:
        (staging / "new.txt").write_text("new")
        raise RuntimeError("failed half-way")
    assert [p.name for p in out.iterdir()] == ["old.txt"]  # the earlier export is untouched
    with staged_folder(out) as staging:
        (staging / "new.txt").write_text("new")
        assert not (out / "new.txt").exists()
    assert [p.name for p in out.iterdir()] == ["new.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no staging folder left
    previous = os.umask(0o022)
    try:
        with staged_folder(tmp_path / "fresh"):
            pass
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "fresh").stat().st_mode) == 0o755  # a plain mkdir's, not mkdtemp's 0700

