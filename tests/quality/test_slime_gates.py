"""Quality gates of Slime at its default settings on real pairs with ground truth.

Each pair's correct matches, coverage and protocol mAA must keep 85% of the value measured below, and its
precision must stay within 3 points of it (:func:`~.gates.shortfalls`): far outside the run-to-run and
CPU-to-CPU spread of these pairs, and crossed by a real loss (one match in three kept, half of image 0
lost, or the simulated views turned off: ``benchmarks/gates_bite.py`` shows each failing here).

Measured with ``python tests/quality/gates.py slime:descriptor=hardtfeat PAIR ...`` on a 2-core x86-64 CPU
(HardTFeat is what ``--descriptor auto`` takes where HardNet's weights are absent); the same numbers come
from ``slime bench`` on these pairs.
"""

import numpy as np
import pytest
from conftest import DATA, require

from slime_match.eval.metrics.pose import pose_auc

from .gates import COUNT_MARGIN, measure, shortfalls

SLIME = "slime:descriptor=hardtfeat"

PLANAR = {  # graf and HPatches viewpoint pairs, and graf 1 -> 3 with image 1 rotated by 45 degrees
    "graf/1-4": {"correct": 12664, "precision": 0.953, "coverage": 0.565},
    "hpatches/v_wormhole/1-4": {"correct": 34989, "precision": 0.997, "coverage": 0.757},
    "graf/1-3@45": {"correct": 9156, "precision": 0.982, "coverage": 0.597},
}
EVD = {  # extreme viewpoints: adam and shop are solved by the image's own planes, dum by the simulated views
    "evd/adam": {"correct": 1964, "precision": 0.819, "maa": 0.867},
    "evd/shop": {"correct": 615, "precision": 0.911, "maa": 1.0},
    # image 1's views; without views: 12, mAA 0. Dum's matches move between CPUs as between seeds (399 correct,
    # precision 0.455, mAA over 10 orders 0.36, at seed 0 on an AMD EPYC with AVX-512, whose 399 the CPU of the
    # other gates also gave; there with oneDNN held to AVX2 (ONEDNN_MAX_CPU_ISA=AVX2) 329, 0.422, 0.61; 441 /
    # 423 / 379 correct, mAA 0.60 / 0.62 / 0.48, at seeds 0 / 1 / 2 on another AMD EPYC; each `predict` +
    # `evaluate_protocol` as measure() runs them, with make_method(SLIME, seed=S)): its gate takes the lowest
    "evd/dum": {"correct": 329, "precision": 0.422, "maa": 0.36},
}
WXBS = {  # wide baseline with appearance and lighting change; mAA = mean recall of the GT correspondences
    "wxbs/zanky": {"correct": 415, "precision": 0.950, "maa": 0.56},
    "wxbs/kyiv_dolltheater2": {"correct": 69, "precision": 0.726, "maa": 0.436},  # run with views=off, see below
}
# At its default settings Slime tries views on this pair and drops them (image 1's branch at tilt 4: 73 F^theta
# matches, all on its views' planes; 100 asked): the same matches as with views=off at five times the time
# (155 s against 33 s), so its gate runs the plain run; the views step's policy has tests of its own
# (tests/slime/test_view_step.py) and EVD dum's gate runs views that are kept.
PLAIN_RUN = {"wxbs/kyiv_dolltheater2"}
SCANNET = {  # indoor pairs at 640 x 480; correct = consistent with the GT epipolar geometry; pair 4's precision
    # and the pose AUC the lower of two float behaviours (an AMD EPYC with AVX-512, alone and with oneDNN held to
    # AVX2: 0.911 and 0.874; 0.456 and 0.314, with pose errors of 9.5, 10.7, 51.6 and 46.7 degrees there)
    "scannet/0": {"correct": 535, "precision": 0.817},
    "scannet/1": {"correct": 301, "precision": 0.798},
    "scannet/3": {"correct": 227, "precision": 0.772},
    "scannet/4": {"correct": 472, "precision": 0.874},
}
SCANNET_POSE_AUC20 = 0.314  # AUC@20 degrees of the four pairs' pose errors (1 px essential RANSAC)


@pytest.fixture(autouse=True)
def _data():
    require(DATA / "hard")


@pytest.mark.parametrize("pair", [*PLANAR, *EVD, *WXBS, *SCANNET])
def test_slime_keeps_its_measured_quality(pair):
    measured = {**PLANAR, **EVD, **WXBS, **SCANNET}[pair]
    row = measure(SLIME + (",views=off" if pair in PLAIN_RUN else ""), pair)
    assert not shortfalls(row, measured), (pair, row)


def test_slime_solves_the_extreme_viewpoint_pairs():
    """All three EVD pairs solved (mAA > 0), their mean mAA at 85% of the mean of their gates' values."""
    maa = [measure(SLIME, pair).maa for pair in EVD]
    assert all(m > 0 for m in maa) and np.mean(maa) >= COUNT_MARGIN * np.mean([v["maa"] for v in EVD.values()]), maa


def test_slime_pose_accuracy_on_scannet():
    errors = [measure(SLIME, pair).pose_error for pair in SCANNET]
    auc = pose_auc(np.array(errors, float), (20.0,))[20.0]
    assert auc >= COUNT_MARGIN * SCANNET_POSE_AUC20, (auc, errors)
