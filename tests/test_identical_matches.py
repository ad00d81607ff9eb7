"""Refactoring guard: every method's matches on a few real pairs, as recorded in a fixture.

This is not a quality test (the quality gates in ``tests/quality`` compare the matches with ground truth): it
tells that a change of the code's structure left the outputs as they were. Each case runs a matcher on the
CPU and compares with ``data/identical_matches.json``. Where the run takes the recording's decisions (every
stage count and the number of matches as recorded):

* exactly, the integer and boolean arrays of ``--save-stages`` (indices, tiles, flags) by digest, and a stage
  array of another length within ``COUNT_RTOL`` by its length alone;
* the final matches' keypoints in one order, by their keypoints: they come sorted by score, and where two
  scores nearly tie their order flips between CPUs (the keypoints agreed to the bit on the x86-64 CPUs
  measured);
* within a tolerance, the floats (keypoints, scores, the float stage arrays): a fingerprint of each array (its
  shape, non-finite counts, its sum and projections on fixed pseudo-random sign vectors (a hash of the
  position, not a random generator whose stream may change between numpy releases), 65 of its values at evenly
  spaced positions and 65 order statistics) agrees to ``FLOAT_RTOL`` of the array's scale. Float results
  differ in their last bits between CPUs (vector units sum in different orders; float32 descriptor distances
  keep about 5 significant digits); the tolerance is above that, and a shift of every keypoint by a
  thousandth of a pixel, a reordering of the matches or one keypoint moved by 10 px exceeds it;
* the float stage arrays as sets of rows (``canonical_rows``): they come sorted by score, and near-tied scores
  order their rows differently on another CPU (graf's block, tile and final matches on an x86-64 CPU with
  AVX-512: the same rows, sums and order statistics, other projections); the planes' homographies each
  scaled to unit norm, as a homography is defined up to scale (graf's reach entries of 1.4e4, and their
  sum moved by 5.7 on another CPU);
* the final scores as a sorted list, to ``SCORE_RTOL``: they order the matches but are not positions. AdaLAM's
  confidences follow its local samples, so on another CPU a match can hold another score while their
  distribution stays (the motorcycle pair's Key.Net scores on an x86-64 CPU with AVX-512: the same sorted
  values to 2e-3 of the largest, sums 0.0085 apart against a norm of 0.23, signed projections of the unsorted
  scores 0.032 apart).

Where a float difference moved a decision, the matches after it move too: a quantity that sits on a float
threshold falls the other side on another CPU (graf's plane memberships: 1,812,933 on one x86-64 CPU,
1,813,725 on another, 0.04% apart, with the same final matches; with oneDNN held to AVX2 one block match of
41,046 changes, then 14,670 final matches instead of 14,656). Then every stage count must stay within
``CASCADE_RTOL`` (or 2) of the recording, and the final keypoints and scores keep their length and order
statistics to ``CASCADE_RTOL``: a cascade from a last-bit difference stays within that, a changed method does
not.

A change that alters the matches on purpose re-records the fixture:

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


COUNT_RTOL = 2e-3
FLOAT_RTOL = 1e-4  # of an array's scale: its L2 norm for the sums, its largest |value| for single values
SCORE_RTOL = 0.1  # the same for the final scores (see module doc)
CASCADE_RTOL = 0.01  # after a moved decision: counts, lengths, and order statistics of the largest |value|
N_PROJECTIONS = 8
N_VALUES = 65


def digest(array: np.ndarray) -> str:
    """SHA-256 of an array's shape, dtype and bytes (for discrete arrays only)."""
    array = np.ascontiguousarray(array)
    return hashlib.sha256(f"{array.shape}{array.dtype}".encode() + array.tobytes()).hexdigest()[:24]


def _signs(n: int) -> np.ndarray:
    """(N_PROJECTIONS, n) fixed pseudo-random signs +-1, the same on every platform and numpy version (a random
    generator's stream may change between numpy releases): the low bit of a SplitMix64 hash of each
    (projection, position)."""
    with np.errstate(over="ignore"):
        z = (np.arange(n, dtype=np.uint64)[None, :] + np.uint64(1)) * np.uint64(0x9E3779B97F4A7C15)
        z = z + np.arange(1, N_PROJECTIONS + 1, dtype=np.uint64)[:, None] * np.uint64(0xD1B54A32D192ED03)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return np.where(z & np.uint64(1), 1.0, -1.0)


def fingerprint(array: np.ndarray) -> dict:
    """What the fixture keeps of an array: a digest of a discrete one, a float one's sketch (see module doc)."""
    array = np.asarray(array)
    if array.dtype.kind in "biu":
        return {"shape": list(array.shape), "digest": digest(array)}
    x = array.astype(np.float64).ravel()
    nonfinite = [int(np.isnan(x).sum()), int(np.isposinf(x).sum()), int(np.isneginf(x).sum())]
    x = np.where(np.isfinite(x), x, 0.0)
    signs = _signs(len(x))
    positions = np.linspace(0, len(x) - 1, N_VALUES).astype(int) if len(x) else np.zeros(0, int)
    return {"shape": list(array.shape), "nonfinite": nonfinite, "norm": float(np.linalg.norm(x)),
            "max_abs": float(np.abs(x).max(initial=0.0)), "sums": [float(x.sum()), *(signs @ x).tolist()],
            "values": x[positions].tolist(), "order": np.sort(x)[positions].tolist()}


def canonical_rows(name: str, array: np.ndarray) -> np.ndarray:
    """A float stage array as a set: its rows (first axis, flattened) in lexicographic order; the planes'
    homographies (``planes_H``) each divided by its Frobenius norm, with a non-negative last entry."""
    array = np.asarray(array, np.float64)
    rows = array.reshape(len(array), int(np.prod(array.shape[1:])))
    if name.endswith("planes_H"):
        norms = np.linalg.norm(rows, axis=1, keepdims=True)
        rows = rows / np.where(norms > 0, norms, 1.0) * np.where(rows[:, -1:] < 0, -1.0, 1.0)
    return rows[np.lexsort(rows.T[::-1])] if rows.shape[1] else rows


def counts_close(got: int, expected: int, rtol: float = COUNT_RTOL) -> bool:
    """Whether a count is within ``rtol`` of its recorded value (and within 2 of it where that is more)."""
    return abs(got - expected) <= max(rtol * abs(expected), 2)


def differs(got: dict, expected: dict, rtol: float = FLOAT_RTOL) -> str | None:
    """Why two fingerprints of an array differ, or None when they agree (floats within ``rtol``)."""
    if got["shape"] != expected["shape"]:
        if got["shape"][1:] == expected["shape"][1:] and counts_close(got["shape"][0], expected["shape"][0]):
            return None  # a few elements more or fewer: positions no longer correspond (see module doc)
        return f"shape {got['shape']} != {expected['shape']}"
    if "digest" in expected:
        return None if got.get("digest") == expected["digest"] else "values differ (discrete, compared exactly)"
    if got["nonfinite"] != expected["nonfinite"]:
        return f"non-finite counts {got['nonfinite']} != {expected['nonfinite']}"
    for key, scale in (("sums", expected["norm"]), ("values", expected["max_abs"]), ("order", expected["max_abs"])):
        gap = np.abs(np.subtract(got[key], expected[key])).max(initial=0.0)
        if gap > rtol * scale + 1e-12:
            return f"{key} differ by {gap:.3g} > {rtol:g} x {scale:.3g}"
    return None


def outputs(case: str) -> dict:
    """What a case's run gives: matches count, fingerprints of the outputs, the stage counts."""
    images, preset, options = CASES[case]
    result = Matcher(make_config(preset, device="cpu", **options))(*load_pair(images))
    order = np.lexsort((result.keypoints1[:, 1], result.keypoints1[:, 0], result.keypoints0[:, 1],
                        result.keypoints0[:, 0]))  # by keypoints: the score order flips where scores nearly tie
    arrays = {"keypoints0": result.keypoints0[order], "keypoints1": result.keypoints1[order],
              "scores": np.sort(result.scores)}
    arrays.update({f"stages.{k}": canonical_rows(k, v) if np.asarray(v).dtype.kind == "f" and np.ndim(v) else v
                   for k, v in sorted((result.stages or {}).items())})
    return {"matches": len(result), "arrays": {k: fingerprint(v) for k, v in arrays.items()},
            "counts": result.summary.get("counts", {})}


def cascade_differs(got: dict, expected: dict) -> str | None:
    """Why two fingerprints of a final output differ beyond a cascade (see module doc), or None: the length
    within ``CASCADE_RTOL``, the order statistics but the smallest and the largest (one match each: graf's
    worst score moves by 0.15 of 1.35 with oneDNN held to AVX2) within ``CASCADE_RTOL`` of the largest |value|."""
    if not counts_close(got["shape"][0], expected["shape"][0], CASCADE_RTOL):
        return f"length {got['shape'][0]} != {expected['shape'][0]}"
    gap = np.abs(np.subtract(got["order"][1:-1], expected["order"][1:-1])).max(initial=0.0)
    if gap > CASCADE_RTOL * expected["max_abs"] + 1e-12:
        return f"order statistics differ by {gap:.3g} > {CASCADE_RTOL:g} x {expected['max_abs']:.3g}"
    return None


@pytest.mark.parametrize("case", list(CASES))
def test_matches_identical_to_recorded(case):
    expected = json.loads(FIXTURE.read_text())[case]
    got = outputs(case)
    assert set(got["counts"]) == set(expected["counts"])
    assert set(got["arrays"]) == set(expected["arrays"])
    if got["counts"] == expected["counts"] and got["matches"] == expected["matches"]:  # the recording's decisions
        changed = {k: why for k in sorted(expected["arrays"]) if (why := differs(
            got["arrays"][k], expected["arrays"][k], SCORE_RTOL if k == "scores" else FLOAT_RTOL))}
    else:  # a float difference moved a decision, and the matches after it
        moved = {k: (got["counts"][k], v) for k, v in expected["counts"].items()
                 if not counts_close(got["counts"][k], v, CASCADE_RTOL)}
        assert not moved, moved
        changed = {k: why for k in ("keypoints0", "keypoints1", "scores")
                   if (why := cascade_differs(got["arrays"][k], expected["arrays"][k]))}
    assert not changed, changed


def test_fingerprint_tolerates_rounding_and_catches_a_moved_match():
    """float32-level noise passes; a shift of every keypoint by 1e-3 px, the matches in another order, one
    keypoint moved by 10 px, a missing match, a NaN, or two indices swapped in a discrete array do not."""
    rng = np.random.default_rng(0)
    keypoints = rng.uniform(0, 800, (5000, 2))
    recorded = fingerprint(keypoints)
    assert differs(fingerprint(keypoints * (1 + 1e-6 * rng.standard_normal(keypoints.shape))), recorded) is None
    assert differs(fingerprint(keypoints + 1e-3), recorded) is not None
    assert differs(fingerprint(keypoints[::-1]), recorded) is not None
    moved = keypoints.copy()
    moved[1234, 0] += 10.0
    assert differs(fingerprint(moved), recorded) is not None
    assert differs(fingerprint(keypoints[:-1]), recorded) is None  # one of 5000 fewer: within COUNT_RTOL
    assert differs(fingerprint(keypoints[:-20]), recorded).startswith("shape")
    indices = np.arange(100)
    swapped = indices.copy()
    swapped[[3, 4]] = swapped[[4, 3]]
    assert differs(fingerprint(swapped), fingerprint(indices)) is not None
    with_nan = keypoints.copy()
    with_nan[0, 0] = np.nan
    assert differs(fingerprint(with_nan), recorded).startswith("non-finite")


def test_a_cascade_passes_and_a_changed_output_does_not():
    """A few matches replaced and a few more passes the check after a moved decision; a tenth of the matches
    lost, or every keypoint stretched by 2%, does not."""
    rng = np.random.default_rng(2)
    keypoints = rng.uniform(0, 400, (14000, 2))
    recorded = fingerprint(keypoints)
    cascade = np.vstack([keypoints[40:], rng.uniform(0, 400, (60, 2))])
    assert cascade_differs(fingerprint(cascade), recorded) is None
    assert cascade_differs(fingerprint(keypoints[:12600]), recorded).startswith("length")
    assert cascade_differs(fingerprint(keypoints * 1.02), recorded).startswith("order")


def test_canonical_rows_forget_the_row_order_and_a_homography_scale_but_not_a_moved_row():
    rng = np.random.default_rng(1)
    points = rng.uniform(0, 800, (1000, 2))
    recorded = fingerprint(canonical_rows("final_xy0", points))
    assert differs(fingerprint(canonical_rows("final_xy0", points[rng.permutation(1000)])), recorded) is None
    moved = points.copy()
    moved[17, 1] += 10.0
    assert differs(fingerprint(canonical_rows("final_xy0", moved)), recorded) is not None
    homographies = rng.normal(size=(50, 3, 3))
    scaled = homographies * rng.uniform(-1e4, 1e4, (50, 1, 1))
    assert differs(fingerprint(canonical_rows("planes_H", scaled)),
                   fingerprint(canonical_rows("planes_H", homographies))) is None
    assert canonical_rows("planes_H", np.zeros((0, 3, 3))).shape == (0, 9)


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        sys.exit(__doc__)
    FIXTURE.parent.mkdir(exist_ok=True)
    FIXTURE.write_text(json.dumps({case: outputs(case) for case in CASES}, indent=1) + "\n")
    print(f"recorded {len(CASES)} cases in {FIXTURE}")
