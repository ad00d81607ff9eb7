"""Refactoring guard: every method's matches on a few real pairs, bit for bit, as recorded in a fixture.

Each case runs a matcher on the CPU (a GPU rounds differently) and compares a digest of its raw float64
outputs (keypoints, scores, and for one Slime case every ``--save-stages`` array) and its stage counts with
``data/identical_matches.json``. A change
of the code's structure must leave them equal; a change that alters the matches on purpose re-records them:

    python tests/test_identical_matches.py --record
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from conftest import DATA, require

from slime_match.config import make_config
from slime_match.eval.datasets import rotate_image
from slime_match.io import load_image
from slime_match.matcher import Matcher

FIXTURE = Path(__file__).resolve().parent / "data" / "identical_matches.json"
WEIGHT_FREE = {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift"}
SCANNET = ("scannet_sample/images", "scene0711_00_frame-001680.jpg", "scene0711_00_frame-001995.jpg")

# name -> (images, preset, options): graf 1 -> 3 and a ScanNet pair at half size, the motorcycle stereo pair
CASES: dict[str, tuple[str, str, dict]] = {
    "graf-slime-tfeat": ("graf", "slime", {"descriptor": "tfeat", "keep_stages": True}),
    "graf-rotated-slime-weight-free": ("graf-rotated", "slime", WEIGHT_FREE),
    "graf-slime-upright-tfeat": ("graf", "slime-upright", {"descriptor": "tfeat"}),
    "graf-slime-flow-block-detection": ("graf", "slime", {"tile_test": "flow", "detection": "block",
                                                           **WEIGHT_FREE}),
    "scannet-hzplus-tfeat": ("scannet", "hz+", {"descriptor": "tfeat"}),
    "scannet-slime-tfeat": ("scannet", "slime", {"descriptor": "tfeat"}),
    "graf-slime-rootsift": ("graf", "slime-rootsift", {}),
    "motorcycle-rootsift": ("motorcycle", "rootsift", {}),
    "motorcycle-keynet": ("motorcycle", "keynet", {"descriptor": "tfeat"}),
    "motorcycle-slime-keynet": ("motorcycle", "slime-keynet", {"descriptor": "tfeat"}),
}


def _half(image: np.ndarray) -> np.ndarray:
    return cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2), interpolation=cv2.INTER_AREA)


def load_pair(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The two images of a case, as float arrays."""
    if name.startswith("graf"):
        folder = require(DATA / "oxford_graf")
        a, b = (_half(load_image(folder / f)) for f in ("img1.png", "img3.png"))
        return (a, rotate_image(b, 90)[0]) if name == "graf-rotated" else (a, b)
    if name == "scannet":
        folder = require(DATA / SCANNET[0])
        return tuple(_half(load_image(folder / f)) for f in SCANNET[1:])
    from skimage.data import stereo_motorcycle

    left, right, _ = stereo_motorcycle()
    return tuple(cv2.resize(im, (370, 250), interpolation=cv2.INTER_AREA).astype(np.float32) / 255
                 for im in (left, right))


def digest(array: np.ndarray) -> str:
    """SHA-256 of an array's shape, dtype and bytes."""
    array = np.ascontiguousarray(array)
    return hashlib.sha256(f"{array.shape}{array.dtype}".encode() + array.tobytes()).hexdigest()[:24]


def outputs(case: str) -> dict:
    """What a case's run gives: matches count, digests of the outputs, the stage counts."""
    images, preset, options = CASES[case]
    result = Matcher(make_config(preset, device="cpu", **options))(*load_pair(images))
    arrays = {"keypoints0": result.keypoints0, "keypoints1": result.keypoints1, "scores": result.scores}
    arrays.update({f"stages.{k}": v for k, v in sorted((result.stages or {}).items())})
    return {"matches": len(result), "digests": {k: digest(v) for k, v in arrays.items()},
            "counts": result.summary.get("counts", {})}


@pytest.mark.parametrize("case", list(CASES))
def test_matches_identical_to_recorded(case):
    expected = json.loads(FIXTURE.read_text())[case]
    got = outputs(case)
    assert got["counts"] == expected["counts"]
    assert got["matches"] == expected["matches"]
    changed = sorted(k for k in expected["digests"] if got["digests"].get(k) != expected["digests"][k])
    assert set(got["digests"]) == set(expected["digests"]) and not changed, changed


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        sys.exit(__doc__)
    FIXTURE.parent.mkdir(exist_ok=True)
    FIXTURE.write_text(json.dumps({case: outputs(case) for case in CASES}, indent=1) + "\n")
    print(f"recorded {len(CASES)} cases in {FIXTURE}")
