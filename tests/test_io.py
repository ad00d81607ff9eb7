"""Image loading of every bit depth / channel layout, and atomic result files."""

import json
import os
import stat

import cv2
import numpy as np
import pytest
import torch
from PIL import Image, ImageOps

from slime_match.errors import ImageError
from slime_match.io import image_size, load_image, save_json, save_npz


def _gradient(h=40, w=50):
    y, x = np.mgrid[0:h, 0:w]
    return (x * 255 / (w - 1)).astype(np.uint8), y


@pytest.mark.parametrize("kind", ["grey", "rgb", "rgba", "grey16", "float"])
def test_load_file_any_depth_and_channels(tmp_path, kind):
    g, _ = _gradient()
    image = {
        "grey": g,
        "rgb": np.dstack([g, g, g]),
        "rgba": np.dstack([g, g, g, np.full_like(g, 7)]),
        "grey16": g.astype(np.uint16) * 257,
        "float": None,
    }[kind]
    if image is None:
        loaded = load_image(g.astype(np.float32) / 255.0)
    else:
        path = tmp_path / "image.png"
        cv2.imwrite(str(path), image)
        loaded = load_image(path)
    assert loaded.shape == (40, 50, 3) and loaded.dtype == np.float32
    assert loaded[:, 0].max() == 0.0 and abs(loaded[:, -1].min() - 1.0) < 1e-6


def test_rgb_order_is_kept(tmp_path):
    image = np.zeros((40, 40, 3), np.uint8)
    image[..., 0] = 255  # red in RGB
    cv2.imwrite(str(tmp_path / "red.png"), image[..., ::-1])  # OpenCV writes BGR
    assert load_image(tmp_path / "red.png")[0, 0].tolist() == [1.0, 0.0, 0.0]


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_is_applied(tmp_path, orientation):
    """A photo tagged as rotated/mirrored loads as viewers show it (PIL's exif_transpose as the reference)."""
    image = np.zeros((40, 60, 3), np.uint8)
    image[:10, :20] = 255  # an asymmetric mark: top-left, wider than high
    pil = Image.fromarray(image)
    exif = pil.getexif()
    exif[0x0112] = orientation
    path = tmp_path / "photo.png"  # lossless, so the comparison is exact
    pil.save(path, exif=exif)
    expected = np.asarray(ImageOps.exif_transpose(Image.open(path)), dtype=np.float32) / 255.0
    loaded = load_image(path)
    assert loaded.shape == expected.shape
    assert np.array_equal(loaded, expected)
    assert image_size(path) == (loaded.shape[1], loaded.shape[0])  # (width, height), upright too


def test_image_size_of_bad_files(tmp_path):
    (tmp_path / "broken.png").write_bytes(b"not an image")
    for path, message in ((tmp_path / "broken.png", "not a readable image"), (tmp_path / "none.png", "no such")):
        with pytest.raises(ImageError, match=message):
            image_size(path)


def test_tensor_inputs():
    chw = torch.rand(3, 36, 48)
    assert np.allclose(load_image(chw), chw.permute(1, 2, 0).numpy())
    assert load_image(torch.rand(1, 36, 48)).shape == (36, 48, 3)
    for half in (torch.bfloat16, torch.float16):  # GPU pipelines often hold images in half precision
        assert np.allclose(load_image(chw.to(half)), chw.permute(1, 2, 0).numpy(), atol=1e-2)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: p / "missing.png", "no such file"),
        (lambda p: p, "directory"),
        (lambda p: (p / "notes.txt").write_text("hello") and p / "notes.txt", "not a readable image"),
        (lambda p: (p / "empty.png").write_bytes(b"") or p / "empty.png", "not a readable image"),
    ],
)
def test_bad_files_raise_clear_errors(tmp_path, make, message):
    with pytest.raises(ImageError, match=message):
        load_image(make(tmp_path))


def test_corrupt_file_raises_without_decoder_noise(tmp_path, capfd):
    """A PNG cut short: our error, and none of OpenCV's C++ log lines on stderr."""
    good = tmp_path / "good.png"
    cv2.imwrite(str(good), np.zeros((40, 40, 3), np.uint8))
    cut = tmp_path / "cut.png"
    cut.write_bytes(good.read_bytes()[:8] + b"garbage" * 10)
    log = getattr(cv2.utils, "logging", None) or cv2  # OpenCV 5 | OpenCV 4
    level = log.getLogLevel()
    with pytest.raises(ImageError, match="not a readable image"):
        load_image(cut)
    if log is not cv2:  # OpenCV 4's PNG decoder writes libpng's messages past OpenCV's log level
        assert capfd.readouterr().err == ""
    assert log.getLogLevel() == level


def test_tiny_and_malformed_arrays():
    with pytest.raises(ImageError, match="smaller than 32"):
        load_image(np.zeros((20, 100), np.uint8))
    with pytest.raises(ImageError, match="expected"):
        load_image(np.zeros((40, 40, 2), np.uint8))
    with pytest.raises(ImageError, match="unsupported image type"):
        load_image([[1, 2], [3, 4]])


def test_atomic_writers_leave_no_partial_file(tmp_path):
    save_npz(tmp_path / "a.npz", x=np.arange(3))
    save_json(tmp_path / "a.json", {"v": np.float32(1.5), "arr": np.arange(2)})
    assert np.load(tmp_path / "a.npz")["x"].tolist() == [0, 1, 2]
    assert json.loads((tmp_path / "a.json").read_text()) == {"v": 1.5, "arr": [0, 1]}
    with pytest.raises(TypeError):
        save_json(tmp_path / "b.json", {"bad": object()})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "a.npz"]


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_atomic_writers_follow_the_umask(tmp_path, umask):
    """Result files get the permissions of a plain open() (0644 under umask 022), not mkstemp's 0600."""
    previous = os.umask(umask)
    try:
        save_npz(tmp_path / "a.npz", x=np.arange(3))
        save_json(tmp_path / "a.json", {"v": 1})
    finally:
        os.umask(previous)
    for name in ("a.npz", "a.json"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o666 & ~umask


def test_float_arrays_scale_and_non_finite_pixels():
    g, _ = _gradient()
    unit = g.astype(np.float32) / 255
    np.testing.assert_allclose(load_image(g.astype(np.float32)), load_image(unit), atol=1e-6)  # 0..255 floats
    holes = unit.copy()
    holes[5, 7], holes[6, 8], holes[7, 9] = np.nan, np.inf, -np.inf
    expected = unit.copy()
    expected[5, 7] = expected[6, 8] = expected[7, 9] = 0.0  # black
    np.testing.assert_array_equal(load_image(holes), load_image(expected))
