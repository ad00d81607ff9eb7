"""Hz+ on real planar pairs with ground-truth homographies, against OpenCV SIFT in the same test."""

import cv2
import numpy as np
import pytest
import torch
from conftest import DATA, require

from slime_match.config import make_config
from slime_match.eval.metrics import correct_matches_homography
from slime_match.io import load_image
from slime_match.pipelines import make_base_pipeline

PAIRS = [("oxford_graf", "img1.png", f"img{k}.png", f"H1to{k}p") for k in (2, 3)] + [
    (f"hpatches/{seq}", "1.ppm", f"{k}.ppm", f"H_1_{k}") for seq in ("v_wormhole", "v_churchill") for k in (2, 3, 4)
]


def sift_mutual_ratio(grey0: np.ndarray, grey1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV SIFT (8000 features) + RootSIFT + mutual ratio test 0.9: the reference baseline."""
    sift = cv2.SIFT_create(nfeatures=8000)
    out = []
    for grey in (grey0, grey1):
        kp, desc = sift.detectAndCompute(grey, None)
        desc = np.sqrt(desc / np.maximum(desc.sum(1, keepdims=True), 1e-12)).astype(np.float32)
        out.append((np.array([k.pt for k in kp]), desc))
    (xy0, d0), (xy1, d1) = out
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    fwd = matcher.knnMatch(d0, d1, k=2)
    bwd = matcher.knnMatch(d1, d0, k=2)
    best_fwd = {m[0].queryIdx: m[0].trainIdx for m in fwd if m[0].distance < 0.9 * m[1].distance}
    best_bwd = {m[0].queryIdx: m[0].trainIdx for m in bwd if m[0].distance < 0.9 * m[1].distance}
    pairs = np.array([(i, j) for i, j in best_fwd.items() if best_bwd.get(j) == i]).reshape(-1, 2)
    return xy0[pairs[:, 0]], xy1[pairs[:, 1]]


@pytest.fixture(scope="module")
def runner():
    """Hz+ (AffNet + OriNet + TFeat) with features cached per image, and the SIFT reference."""
    pipeline = make_base_pipeline(make_config("hz+", descriptor="tfeat").base, torch.device("cpu"))
    cache = {}

    def features(path):
        if path not in cache:
            image = load_image(path)
            cache[path] = (image, pipeline.extract(image))
        return cache[path]

    def run(folder, name0, name1, h_name):
        base = require(DATA / folder)
        (image0, f0), (image1, f1) = features(base / name0), features(base / name1)
        m = pipeline.match(f0, f1, image0.shape[:2], image1.shape[:2])
        x0, x1 = f0.xy.numpy()[m.idx0], f1.xy.numpy()[m.idx1]
        h = np.loadtxt(base / h_name)
        ours = correct_matches_homography(x0, x1, h)
        grey = [cv2.imread(str(base / n), cv2.IMREAD_GRAYSCALE) for n in (name0, name1)]
        s0, s1 = sift_mutual_ratio(*grey)
        return ours, correct_matches_homography(s0, s1, h)

    return run


def test_hz_plus_precision_and_count_vs_sift(runner):
    total_ours = total_sift = 0
    for folder, name0, name1, h_name in PAIRS:
        ours, sift = runner(folder, name0, name1, h_name)
        assert len(ours) > 0 and ours.mean() >= 0.85, f"{folder} {name1}: precision {ours.mean():.3f}"
        total_ours += int(ours.sum())
        total_sift += int(sift.sum())
    assert total_ours >= total_sift, (total_ours, total_sift)


def test_hz_plus_beats_sift_on_graf_1_to_4(runner):
    ours, sift = runner("oxford_graf", "img1.png", "img4.png", "H1to4p")
    assert ours.sum() > sift.sum(), (int(ours.sum()), int(sift.sum()))
