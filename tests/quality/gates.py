"""Quality gates: a method's matches on real pairs with ground truth, scored as ``slime bench`` scores them.

:func:`measure` runs a method spec of :mod:`slime_match.eval.methods` (the ``slime bench`` names, e.g.
``"slime"``, ``"hz+:descriptor=tfeat"``) on named pairs of the bundled data and returns one :class:`Row` per
pair; results are kept for the session, so that the gates of one method and set share one run. The pairs:

* planar (``graf/1-4``, ``hpatches/v_wormhole/1-4``, ``@90``/``@45`` suffix: image 1 rotated): correct matches,
  precision and coverage at 15 px, the paper's metrics (:func:`slime_match.eval.scoring.evaluate_pair`);
* ``evd/NAME`` and ``wxbs/NAME`` (the hard sets): the same, plus the mAA of the set's own protocol (OpenCV
  MAGSAC++ on the raw matches: EVD homography error over 1-15 px, WxBS recall of the hand-taken
  correspondences over 1-20 px), the mean over 10 orders of the matches: MAGSAC++ samples by index, and one
  order's mAA moves by up to 0.6 on some of these pairs when the matches are merely listed in another order;
* ``scannet/INDEX`` (the ScanNet sample at its 640x480 protocol size): correct matches and precision against
  the ground-truth epipolar geometry, and the pose error in degrees of the essential matrix at a 1 px RANSAC.

``python tests/quality/gates.py METHOD PAIR [PAIR ...]`` prints the rows: the measurements the gates'
thresholds come from.
"""

from __future__ import annotations

import functools
import json
import sys
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.datasets import Pair, load_dataset, rotated_pair
from slime_match.eval.methods import make_method
from slime_match.eval.predictions import load_pair_images, predict
from slime_match.eval.scoring import evaluate_pair, evaluate_protocol, pair_gt
from slime_match.io import load_image

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
HARD_SETS = {"evd": "hard/evd", "wxbs": "hard/wxbs"}
POSE_RANSAC_PX = 1.0
SCORING = BenchConfig(thresholds=["none"], essential_thresholds=[POSE_RANSAC_PX], homography_step=4,
                      protocol_orders=10)


@dataclass(frozen=True)
class Row:
    """One method on one pair: counts, precision, coverage (planar pairs; 0 elsewhere), the protocol's mAA over
    the matches' orders (hard sets; None elsewhere), the pose error in degrees (ScanNet; None elsewhere),
    seconds of matching."""

    matches: int
    correct: int
    precision: float
    coverage: float
    maa: float | None
    pose_error: float | None
    seconds: float


def load_pair(name: str) -> Pair:
    """The pair named ``set/pair[@angle]``: ``graf/1-4``, ``hpatches/v_wormhole/1-4@45``, ``evd/dum``,
    ``wxbs/zanky``, ``scannet/3`` (index in the sample's pair list)."""
    name, _, angle = name.partition("@")
    dataset, _, rest = name.partition("/")
    if dataset in HARD_SETS:
        spec = f"{dataset}:{DATA / HARD_SETS[dataset]}"
        pairs = {p.name: p for p in load_dataset(spec)}
    elif dataset == "scannet":
        pairs = dict(enumerate(load_dataset("scannet-sample", DATA)))
        rest = int(rest)
    else:
        pairs = {p.name.split("/", 1)[-1] if dataset == "graf" else p.name: p for p in load_dataset(dataset, DATA)}
    pair = replace(pairs[rest], name=name)
    if angle:
        pair = rotated_pair(replace(pair, image1=load_image(pair.image1)), float(angle))
    return pair


@functools.cache
def _method(spec: str):
    return make_method(spec, device="cpu", seed=0)


@functools.cache
def prediction(spec: str, name: str) -> dict:
    """Method ``spec``'s prediction on pair ``name`` (``eval.predictions.predict``'s arrays, seconds and
    decisions), computed once."""
    pair = load_pair(name)
    return predict(_method(spec), pair, load_pair_images(pair))


@functools.cache
def measure(spec: str, name: str) -> Row:
    """The :class:`Row` of method ``spec`` on pair ``name`` (see :func:`load_pair`), computed once."""
    pair = load_pair(name)
    images = load_pair_images(pair)
    pred = prediction(spec, name)
    raw = {spec: (pred["keypoints0"], pred["keypoints1"])}
    gt = pair_gt(pair, images)
    metrics = evaluate_pair(gt, raw, SCORING)[0][spec]["none"]
    dataset = name.partition("/")[0]
    maa = evaluate_protocol(dataset, gt, raw, SCORING)[spec]["maa_mean"] if dataset in HARD_SETS else None
    pose = metrics.get("pose_errors", {}).get(f"{POSE_RANSAC_PX:g}")
    return Row(matches=metrics["n_matches"], correct=metrics["n_correct"], precision=metrics["precision"],
               coverage=metrics["coverage"] if gt.planar else 0.0, maa=maa, pose_error=pose,
               seconds=float(pred["seconds"]))


COUNT_MARGIN = 0.85  # correct matches, coverage and mAA must keep 85% of the measured value
PRECISION_MARGIN = 0.03  # precision may lose 3 points


def shortfalls(row: Row, measured: dict[str, float]) -> list[str]:
    """What a :class:`Row` lost against the ``measured`` values of its gate (keys ``correct``, ``precision``,
    ``coverage``, ``maa``, any subset): empty when every value keeps its margin."""
    out = []
    for key, value in measured.items():
        got = getattr(row, key)
        bar = value - PRECISION_MARGIN if key == "precision" else COUNT_MARGIN * value
        if got is None or got < bar:
            out.append(f"{key} {got} < {bar:.4g} (measured {value})")
    return out


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    for pair_name in sys.argv[2:]:
        print(json.dumps({"method": sys.argv[1], "pair": pair_name, **asdict(measure(sys.argv[1], pair_name))}),
              flush=True)
