"""WxBS reader: F from the GT correspondences of a tiny synthetic folder."""

import cv2
import numpy as np

from slime_match.eval.datasets import load_dataset
from slime_match.eval.datasets.pair import fundamental_from_pose

from .helpers import rot, same_up_to_scale, texture, two_view_points


def test_wxbs_folder_f_from_corrs(tmp_path):
    rng = np.random.default_rng(3)
    K = np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]])
    R, t = rot([0.1, 1, 0], 15), np.array([1.0, 0.2, 0.1])
    x0, x1 = two_view_points(K, K, R, t, rng, n=40, w=320, h=240)
    d = tmp_path / "WGBS" / "kremlin"
    d.mkdir(parents=True)
    cv2.imwrite(str(d / "01.png"), texture())
    cv2.imwrite(str(d / "02.jpg"), texture(seed=2))
    np.savetxt(d / "corrs.txt", np.concatenate([x0, x1], 1))
    (p,) = load_dataset(f"wxbs:{tmp_path}")
    assert p.name == "WGBS/kremlin" and p.kind == "fundamental" and p.corrs.shape == (40, 4)
    assert same_up_to_scale(p.F, fundamental_from_pose(K, K, R, t)) < 1e-6
