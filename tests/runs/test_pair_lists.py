"""``slime make-pairs``: image folders listed, every pair or a sequential window, pairs files that
``slime pairs`` reads back."""

import pytest
from conftest import run_cli

from slime_match.errors import ConfigError, ImageError
from slime_match.runs.batch import read_pairs
from slime_match.runs.pair_lists import (
    exhaustive_pairs,
    list_images,
    make_pairs,
    sequential_pairs,
    write_pairs,
)


@pytest.fixture
def folder(tmp_path):
    """Images at two depths with mixed-case suffixes, plus files and folders that are not images."""
    root = tmp_path / "photos"
    for name in ("b.jpg", "a.PNG", "sub/c.tiff", "sub/deeper/d.webp", "notes.txt", ".hidden.jpg",
                 ".cache/e.jpg", "sub/f.JPEG"):
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"")  # listing reads names only
    (root / "folder.png").mkdir()  # a folder named like an image is not one
    return root


def test_list_images_by_suffix_sorted_relative(folder):
    assert list_images(folder) == ["a.PNG", "b.jpg", "sub/c.tiff", "sub/deeper/d.webp", "sub/f.JPEG"]


def test_exhaustive_pairs():
    assert exhaustive_pairs(["a", "b", "c", "d"]) == [
        ("a", "b"), ("a", "c"), ("a", "d"), ("b", "c"), ("b", "d"), ("c", "d")]
    assert exhaustive_pairs(["a"]) == []
    assert len(exhaustive_pairs([str(i) for i in range(10)])) == 45


def test_sequential_pairs():
    names = ["a", "b", "c", "d"]
    assert sequential_pairs(names, 1) == [("a", "b"), ("b", "c"), ("c", "d")]
    assert sequential_pairs(names, 2) == [("a", "b"), ("a", "c"), ("b", "c"), ("b", "d"), ("c", "d")]
    assert sequential_pairs(names, 3) == sequential_pairs(names, 10) == exhaustive_pairs(names)
    with pytest.raises(ConfigError, match="at least 1"):
        sequential_pairs(names, 0)


def test_make_pairs_bad_input(folder, tmp_path):
    with pytest.raises(ImageError, match="not found"):
        make_pairs(tmp_path / "missing")
    with pytest.raises(ConfigError, match="pairing mode"):
        make_pairs(folder, mode="random")
    with pytest.raises(ConfigError, match="has 1 image"):
        make_pairs(folder / "sub" / "deeper")
    (folder / "with space.jpg").write_bytes(b"")
    (folder / "hash#1.jpg").write_bytes(b"")
    with pytest.raises(ConfigError, match=r"2 image name\(s\) .* white space or '#'"):
        make_pairs(folder)


def test_written_pairs_read_back(folder, tmp_path):
    pairs = make_pairs(folder, mode="sequential", window=2)
    path = tmp_path / "pairs.txt"
    write_pairs(path, pairs, comment="made by a test\nsecond line")
    assert path.read_text().splitlines()[:2] == ["# made by a test", "# second line"]
    jobs = read_pairs(path, folder)
    assert [(job.name0, job.name1) for job in jobs] == pairs
    assert jobs[-1].path1 == folder / "sub" / "f.JPEG"


def test_cli_make_pairs(capsys, folder, tmp_path):
    out = tmp_path / "lists" / "pairs.txt"
    code, stdout, _ = run_cli(capsys, "make-pairs", folder, "-o", out)
    assert code == 0 and stdout.startswith("10 pairs of 5 images (every pair)")
    assert len(read_pairs(out, folder)) == 10

    code, _, err = run_cli(capsys, "make-pairs", folder, "-o", out, "--sequential", "1")
    assert code == 2 and "exists; pass --overwrite" in err
    assert len(read_pairs(out, folder)) == 10  # left as it was

    code, stdout, _ = run_cli(capsys, "make-pairs", folder, "-o", out, "--sequential", "1", "--overwrite")
    assert code == 0 and "4 pairs of 5 images (each image and the next 1 by name)" in stdout
    assert [(j.name0, j.name1) for j in read_pairs(out, folder)] == sequential_pairs(list_images(folder), 1)

    code, _, err = run_cli(capsys, "make-pairs", folder, "-o", tmp_path)
    assert code == 2 and "is a folder" in err
    code, _, err = run_cli(capsys, "make-pairs", tmp_path / "nowhere", "-o", tmp_path / "x.txt")
    assert code == 2 and "not found" in err and not (tmp_path / "x.txt").exists()
    with pytest.raises(SystemExit):
        run_cli(capsys, "make-pairs", folder, "-o", tmp_path / "y.txt", "--sequential", "0")
