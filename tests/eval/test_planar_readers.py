"""Planar readers (Oxford, HPatches, the paper's planar folder, EVD) on real and tiny synthetic folders."""

from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import DATA, require

from slime_match.eval.datasets import load_dataset

from .helpers import texture


def test_graf_oxford_reader():
    require(DATA / "oxford_graf")
    pairs = load_dataset("graf")
    assert [p.name for p in pairs] == [f"oxford_graf/1-{k}" for k in range(2, 7)]
    p = pairs[1]
    assert p.kind == "homography" and p.image0.name == "img1.png" and p.image1.name == "img3.png"
    assert p.H[0, 0] == pytest.approx(0.76285898) and p.H[1, 2] == pytest.approx(-76.999973)


def test_hpatches_reader_root_and_sequence():
    require(DATA / "hpatches")
    pairs = load_dataset("hpatches")
    assert len(pairs) == 10 and {p.name.split("/")[0] for p in pairs} == {"v_churchill", "v_wormhole"}
    seq = load_dataset(f"hpatches:{DATA / 'hpatches' / 'v_wormhole'}")
    assert [p.name for p in seq] == [f"v_wormhole/1-{k}" for k in range(2, 7)]
    assert seq[0].H[0, 0] == pytest.approx(1.4733) and all(p.image1.suffix == ".ppm" for p in seq)


def _write_h(path: Path, H):
    np.savetxt(path, H)


def test_planar_folder_with_masks_and_rotated_variants(tmp_path):
    for k in (1, 2, 3):
        cv2.imwrite(str(tmp_path / f"boat{k}.png"), texture(seed=k))
    cv2.imwrite(str(tmp_path / "boatrot2.png"), texture(seed=9))
    H2, H3 = np.diag([1.0, 1.0, 1.0]), np.array([[1, 0, 5.0], [0, 1, 2], [0, 0, 1]])
    _write_h(tmp_path / "boat_H12.txt", H2)
    _write_h(tmp_path / "boat_H13.txt", H3)
    _write_h(tmp_path / "boatrot_H12.txt", H3)
    mask = np.zeros((60, 80), np.uint8)
    mask[:10] = 255
    cv2.imwrite(str(tmp_path / "mask_boat3.png"), mask)
    pairs = {p.name: p for p in load_dataset(f"planar:{tmp_path}")}
    assert set(pairs) == {"boat/1-2", "boat/1-3", "boatrot/1-2"}
    assert np.allclose(pairs["boat/1-3"].H, H3) and pairs["boat/1-3"].mask1[:10].all()
    assert pairs["boat/1-3"].mask1.sum() == 800 and pairs["boat/1-2"].mask1 is None
    rot = pairs["boatrot/1-2"]
    assert rot.image0.name == "boat1.png" and rot.image1.name == "boatrot2.png"
    with pytest.raises(FileNotFoundError):
        load_dataset(f"planar:{tmp_path / 'missing'}")


def test_evd_folder(tmp_path):
    for sub in ("1", "2", "h"):
        (tmp_path / sub).mkdir()
    for name in ("adam", "cafe"):
        cv2.imwrite(str(tmp_path / "1" / f"{name}.png"), texture())
        cv2.imwrite(str(tmp_path / "2" / f"{name}.png"), texture(seed=3))
        _write_h(tmp_path / "h" / f"{name}.txt", np.array([[2.0, 0, 1], [0, 2, 3], [0, 0, 1]]))
    pairs = load_dataset(f"evd:{tmp_path}")
    assert [p.name for p in pairs] == ["adam", "cafe"] and pairs[1].image1 == tmp_path / "2" / "cafe.png"
    assert pairs[0].H[1, 2] == 3.0
