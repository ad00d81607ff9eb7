"""``slime hloc``: a run as hloc's features.h5 / matches.h5, read back the way hloc reads them."""

import shutil

import numpy as np
import pytest
from conftest import export_pairs, run_cli, write_run_folder

from slime_match.errors import ConfigError, ImageError
from slime_match.runs.export import PairMatches, merge_keypoints
from slime_match.runs.hloc import export_hloc, pair_key, similarity

h5py = pytest.importorskip("h5py")


def _hloc_matches(path, name0, name1):
    """(M, 2) keypoint index pairs and (M,) scores of a pair, looked up in either order as hloc does."""
    with h5py.File(path, "r") as h5:
        key, flip = pair_key(name0, name1), False
        if key not in h5:
            key, flip = pair_key(name1, name0), True
        matches0, scores0 = h5[key]["matches0"][()], h5[key]["matching_scores0"][()]
    idx = np.flatnonzero(matches0 != -1)
    pairs = np.stack([idx, matches0[idx]], 1)
    return (pairs[:, ::-1] if flip else pairs), scores0[idx]


def test_pair_key_and_similarity():
    assert pair_key("a.jpg", "b.jpg") == "a.jpg/b.jpg"
    assert pair_key("day/a.jpg", "night/sub/b.jpg") == "day-a.jpg/night-sub-b.jpg"
    np.testing.assert_allclose(similarity(np.array([0.0, 1.0, 3.0])), [1.0, 0.5, 0.25])


def test_export_round_trip(tmp_path, small_images):
    pairs = export_pairs()
    summary = export_hloc(write_run_folder(tmp_path, pairs), small_images, tmp_path / "hloc")
    keypoints, matches, scores = merge_keypoints(pairs)
    out = tmp_path / "hloc"
    assert sorted(p.name for p in out.iterdir()) == ["features.h5", "matches.h5", "pairs.txt", "summary.json"]
    assert (summary["images"], summary["pairs"], summary["keypoints"], summary["matches"]) == (3, 2, 8, 4)
    assert (out / "pairs.txt").read_text() == "a.png b.png\na.png c.png\n"
    with h5py.File(out / "features.h5", "r") as h5:
        assert sorted(h5) == ["a.png", "b.png", "c.png"]
        for name, points in keypoints.items():
            np.testing.assert_array_equal(h5[name]["keypoints"][()], points.astype(np.float32))
            np.testing.assert_array_equal(h5[name]["image_size"][()], [64, 48])
    for pair, expected, expected_scores in zip(pairs, matches, scores):
        got, got_scores = _hloc_matches(out / "matches.h5", pair.name0, pair.name1)
        order = np.argsort(expected[:, 0])
        np.testing.assert_array_equal(got, expected[order])
        np.testing.assert_allclose(got_scores, 1 / (1 + expected_scores[order]), rtol=1e-6)
    reversed_pair, _ = _hloc_matches(out / "matches.h5", "b.png", "a.png")  # hloc looks both ways
    np.testing.assert_array_equal(reversed_pair, np.sort(matches[0], axis=0)[:, ::-1])


def test_names_in_sub_folders_and_inliers_only(tmp_path, small_images):
    (small_images / "day").mkdir()
    shutil.move(small_images / "b.png", small_images / "day" / "b.png")
    ab, ac = export_pairs()
    ab = PairMatches("a.png", "day/b.png", ab.keypoints0, ab.keypoints1, ab.scores)
    run = write_run_folder(tmp_path, [ab, ac], inliers=True)  # inliers: scores < 0.25
    summary = export_hloc(run, small_images, tmp_path / "hloc", inliers_only=True)
    assert summary["matches"] == 2  # a-b keeps (a0, b0) at 0.05 (0.1 and 0.2 repeat a0); a-c (a1, c0) at 0.2
    with h5py.File(tmp_path / "hloc" / "features.h5", "r") as h5:
        assert "day/b.png" in h5 and h5["day/b.png"]["keypoints"].shape == (2, 2)
    got, _ = _hloc_matches(tmp_path / "hloc" / "matches.h5", "a.png", "day/b.png")
    assert got.shape == (1, 2)


def test_export_refusals(tmp_path, small_images, monkeypatch):
    run = write_run_folder(tmp_path, export_pairs())
    out = tmp_path / "hloc"
    export_hloc(run, small_images, out)
    with pytest.raises(ConfigError, match="earlier hloc export: use --overwrite"):
        export_hloc(run, small_images, out)
    export_hloc(run, small_images, out, overwrite=True, merge_radius=0)
    with h5py.File(out / "features.h5", "r") as h5:
        assert len(h5["a.png"]["keypoints"]) == 5  # the rewrite took merge_radius 0
    (out / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match=r"not part of a hloc export \(notes.txt\)"):
        export_hloc(run, small_images, out, overwrite=True)
    assert (out / "notes.txt").read_text() == "mine" and (out / "features.h5").is_file()
    (out / "notes.txt").unlink()
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match="holds no hloc export"):
        export_hloc(run, small_images, tmp_path / "busy", overwrite=True)
    (small_images / "c.png").unlink()
    with pytest.raises(ImageError, match="c.png"):
        export_hloc(run, small_images, tmp_path / "other")
    assert not (tmp_path / "other").exists()
    monkeypatch.setitem(__import__("sys").modules, "h5py", None)  # `import h5py` raises ImportError
    with pytest.raises(ConfigError, match="pip install 'slime-match\\[hloc\\]'"):
        export_hloc(run, small_images, tmp_path / "third")


def test_slime_hloc_cli(tmp_path, small_images, capsys):
    run = write_run_folder(tmp_path, export_pairs())
    code, out, _ = run_cli(capsys, "hloc", run, "--images", small_images, "-o", tmp_path / "hloc")
    assert code == 0 and out.startswith("3 images, 8 keypoints, 4 matches in 2 pairs ->")
    code, _, err = run_cli(capsys, "hloc", run, "--images", small_images, "-o", tmp_path / "hloc")
    assert code == 2 and "--overwrite" in err
    code, _, err = run_cli(capsys, "hloc", tmp_path / "nowhere", "--images", small_images, "-o", tmp_path / "x")
    assert code == 2 and "not a `slime pairs` run folder" in err and not (tmp_path / "x").exists()
