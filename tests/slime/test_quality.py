"""Slime vs its base Hz+ on the planar GT pairs and on exact rotations: precision, failures, coverage.

These run Slime on 15 + 9 real pairs (tens of seconds each on a 2-core CPU): marked slow, run them with
``python -m pytest -m slow tests/slime/test_quality.py``.
"""

import numpy as np
import pytest
from conftest import DATA, require

from slime_match.config import make_config
from slime_match.eval.datasets import rotate_image
from slime_match.eval.metrics import correct_matches_homography, coverage, valid_area_homography
from slime_match.io import load_image
from slime_match.matcher import Matcher

PLANAR = [("oxford_graf", "img1.png", f"img{k}.png", f"H1to{k}p") for k in range(2, 7)] + [
    (f"hpatches/{seq}", "1.ppm", f"{k}.ppm", f"H_1_{k}") for seq in ("v_wormhole", "v_churchill") for k in range(2, 7)
]


def _evaluate(matcher, folder, name0, name1, h_name, angle=0):
    base = require(DATA / folder)
    image0, image1 = load_image(base / name0), load_image(base / name1)
    h = np.loadtxt(base / h_name)
    if angle:
        image1, rotation = rotate_image(image1, angle)
        h = rotation @ h
    result = matcher(image0, image1)
    ok = correct_matches_homography(result.keypoints0, result.keypoints1, h)
    valid0, valid1 = valid_area_homography(h, image0.shape[:2], image1.shape[:2])
    cov = coverage(result.keypoints0[ok], result.keypoints1[ok], image0.shape[:2], image1.shape[:2], valid0, valid1)
    return {"matches": len(ok), "correct": int(ok.sum()), "precision": float(ok.mean()) if len(ok) else 0.0,
            "coverage": cov}


@pytest.fixture(scope="module")
def planar_rows():
    """(Slime row, base Hz+ row) per planar pair, both with TFeat descriptors and no RANSAC."""
    slime = Matcher(make_config("slime", descriptor="tfeat"))
    base = Matcher(make_config("hz+", descriptor="tfeat"))
    return [(_evaluate(slime, *p), _evaluate(base, *p)) for p in PLANAR]


@pytest.mark.slow
def test_slime_precision_and_failures_match_base_on_planar_pairs(planar_rows):
    prec_s = np.mean([s["precision"] for s, _ in planar_rows])
    prec_b = np.mean([b["precision"] for _, b in planar_rows])
    fail_s = sum(s["correct"] == 0 for s, _ in planar_rows)
    fail_b = sum(b["correct"] == 0 for _, b in planar_rows)
    print(f"precision {prec_s:.4f} vs {prec_b:.4f}, failures {fail_s} vs {fail_b}")
    assert prec_s >= prec_b - 0.02
    assert fail_s < fail_b or fail_b == 0


@pytest.mark.slow
def test_plane_tile_test_covers_more_than_the_papers_flow_test(planar_rows):
    """Sec. 3.8's plane test (the default, ours) against the paper's flow test (``tile_test="flow"``): on every
    pair at least the flow test's coverage, 2 points more over the 15 pairs and 1.1x Hz+, precision within 2
    points of Hz+'s."""
    flow = Matcher(make_config("slime", descriptor="tfeat", tile_test="flow"))
    rows = [_evaluate(flow, *p) for p in PLANAR]
    cov_p, cov_f, cov_b = (np.mean([r["coverage"] for r in column])
                           for column in ([s for s, _ in planar_rows], rows, [b for _, b in planar_rows]))
    prec_p, prec_b = (np.mean([r[k]["precision"] for r in planar_rows]) for k in (0, 1))
    print(f"coverage plane {cov_p:.4f}, flow {cov_f:.4f}, hz+ {cov_b:.4f}; precision {prec_p:.4f} vs {prec_b:.4f}")
    assert all(s["coverage"] >= r["coverage"] - 0.005 for r, (s, _) in zip(rows, planar_rows, strict=True))
    assert cov_p >= 1.1 * cov_b and cov_p >= cov_f + 0.02
    assert prec_p >= prec_b - 0.02


@pytest.mark.slow
def test_slime_coverage_beats_a_base_at_magnification_2_on_planar_pairs():
    """Slime's gain is relative to its base: with patches at 2x the HarrisZ+ ellipse (our default is 6x, the
    reference pipelines used 1x) Hz+ covers 0.451 at precision 0.928 and Slime on it 0.571 at 0.973 (1.27x;
    42015fd), the paper's bar met with the same base on both sides."""
    slime = Matcher(make_config("slime", descriptor="tfeat", magnification=2))
    base = Matcher(make_config("hz+", descriptor="tfeat", magnification=2))
    rows = [(_evaluate(slime, *p), _evaluate(base, *p)) for p in PLANAR]
    cov_s, cov_b = (np.mean([r[k]["coverage"] for r in rows]) for k in (0, 1))
    prec_s, prec_b = (np.mean([r[k]["precision"] for r in rows]) for k in (0, 1))
    print(f"coverage {cov_s:.4f} vs {cov_b:.4f}, precision {prec_s:.4f} vs {prec_b:.4f}")
    assert cov_s >= 1.2 * cov_b
    assert prec_s >= prec_b - 0.02
    assert sum(s["correct"] == 0 for s, _ in rows) <= sum(b["correct"] == 0 for _, b in rows)


@pytest.mark.slow
@pytest.mark.parametrize("angle", [45, 90, 180, 270])
@pytest.mark.parametrize("pair", [("oxford_graf", "img1.png", "img3.png", "H1to3p"),
                                  ("hpatches/v_wormhole", "1.ppm", "3.ppm", "H_1_3")])
def test_slime_finds_rotated_pairs(pair, angle):
    row = _evaluate(Matcher(make_config("slime", descriptor="tfeat")), *pair, angle=angle)
    assert row["correct"] > 0 and row["precision"] >= 0.8, row


@pytest.mark.slow
def test_slime_keeps_graf_1_to_6_rotated_45_degrees():
    """The hardest rotated pair: carving the final global DTM's hull with the tile keypoints once left 248
    correct matches of the 2312 it received (precision 0.64)."""
    row = _evaluate(Matcher(make_config("slime", descriptor="tfeat")), "oxford_graf", "img1.png", "img6.png",
                    "H1to6p", angle=45)
    assert row["correct"] >= 1000 and row["precision"] >= 0.8, row


@pytest.mark.slow
def test_fbar_counting_homographies_keeps_more_of_graf_1_to_3():
    """F-bar's two slots a tile hold two homographies, not two sets: the literal reading (every tile set takes
    a slot) filled them with pieces of one plane and lost whole regions. Measured coverage 0.559 vs 0.520."""
    rows = {mode: _evaluate(Matcher(make_config("slime", descriptor="tfeat", same_homography=mode)), "oxford_graf",
                            "img1.png", "img3.png", "H1to3p") for mode in ("shared", "set")}
    assert rows["shared"]["coverage"] >= rows["set"]["coverage"] + 0.02, rows
    assert rows["shared"]["precision"] >= 0.97, rows


@pytest.mark.slow
def test_slime_fine_covers_more_of_graf_1_to_5():
    """The slime-fine preset's fourth block scale keeps fine texture the paper's three levels lose: measured
    0.483 at precision 0.915 on graf 1 -> 5, where the default covers 0.432 and Hz+ 0.373 (db1ab10)."""
    row = _evaluate(Matcher(make_config("slime-fine", descriptor="tfeat")), "oxford_graf", "img1.png", "img5.png",
                    "H1to5p")
    assert row["coverage"] >= 0.40 and row["precision"] >= 0.88, row
