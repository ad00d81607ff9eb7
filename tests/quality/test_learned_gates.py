"""Quality gates of Slime on ALIKED + LightGlue (``slime-aliked``) and of ALIKED + LightGlue alone, at their
presets, on real pairs with ground truth; they need the learned weights (``scripts/fetch_learned_weights.py``)
and skip, naming the files, without them.

The same rule as Slime's gates (:mod:`.test_slime_gates`): correct matches, coverage and protocol mAA keep 85%
of the measured value, precision stays within 3 points. Pairs solved without simulated views (those cost
minutes): a planar viewpoint pair, and two WxBS pairs (wide baseline with appearance change, where Slime on
ALIKED is ahead of both Slime on Hz+ and ALIKED alone) whose mAA moved by at most 0.04 over RANSAC seeds 0, 1
and 2 (flood moved by 0.12, tyn by 0.47: such pairs would make a gate of chance).

Measured with ``python tests/quality/gates.py METHOD PAIR ...`` on a 2-core x86-64 CPU.
"""

import pytest
from conftest import DATA, require, require_learned_weights

from .gates import measure, shortfalls

MEASURED = {
    "slime-aliked": {
        "graf/1-4": {"correct": 7191, "precision": 0.966, "coverage": 0.931},
        "wxbs/rovenki": {"correct": 1175, "precision": 0.586, "maa": 0.932},
        "wxbs/zanky": {"correct": 558, "precision": 0.924, "maa": 0.596},
    },
    "aliked-lg": {
        "graf/1-3@45": {"correct": 676, "precision": 0.999, "coverage": 0.497},
    },
}


@pytest.mark.parametrize(("method", "pair"), [(m, p) for m, pairs in MEASURED.items() for p in pairs])
def test_learned_base_keeps_its_measured_quality(method, pair):
    require(DATA / "hard")
    require_learned_weights("aliked-n16", "lightglue-aliked")
    row = measure(method, pair)
    assert not shortfalls(row, MEASURED[method][pair]), (method, pair, row)
