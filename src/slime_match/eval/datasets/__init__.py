"""Readers of evaluation datasets: each yields :class:`Pair` objects with their ground truth.

Conventions: pixel coordinates are ``(x, y)`` with the centre of the top-left pixel at ``(0, 0)``; every
ground-truth quantity refers to the image files as stored (the "original frame"). ``H`` maps image 0 to
image 1, ``F`` satisfies ``x1^T F x0 = 0``, ``(R, t)`` maps camera-0 coordinates to camera-1 coordinates
(``X1 = R X0 + t``), masks are boolean with True = excluded.

Protocol resizing (MegaDepth longest side <= 1200 px, ScanNet 640x480) is described by ``Pair.max_side`` /
``Pair.size``; :func:`slime_match.resize.resize_image` resizes an image accordingly and returns its frame,
whose ``to_original`` brings coordinates back to the original frame.

Modules: :mod:`.pair` (the Pair, GT geometry, rotated views), :mod:`.files` (folder reading helpers), one
reader module per format family (:mod:`.planar`, :mod:`.wxbs`, :mod:`.pose`, :mod:`.motorcycle`) and
:mod:`.load` (dataset specs); :mod:`.viewpoints` writes synthetic extreme-viewpoint pairs in the EVD layout.
"""

from slime_match.eval.datasets.load import default_data_root, load_dataset
from slime_match.eval.datasets.motorcycle import read_motorcycle
from slime_match.eval.datasets.pair import (
    KINDS,
    Pair,
    fundamental_from_corrs,
    fundamental_from_pose,
    rotate_image,
    rotated_pair,
    scale_intrinsics,
    skew,
    transform_view,
)
from slime_match.eval.datasets.planar import read_evd, read_hpatches, read_oxford, read_planar
from slime_match.eval.datasets.pose import (
    MEGADEPTH_MAX_SIDE,
    SCANNET_SIZE,
    read_megadepth1500,
    read_scannet1500,
    read_scannet_pairs,
)
from slime_match.eval.datasets.wxbs import read_wxbs

__all__ = [
    "KINDS",
    "MEGADEPTH_MAX_SIDE",
    "SCANNET_SIZE",
    "Pair",
    "default_data_root",
    "fundamental_from_corrs",
    "fundamental_from_pose",
    "load_dataset",
    "read_evd",
    "read_hpatches",
    "read_megadepth1500",
    "read_motorcycle",
    "read_oxford",
    "read_planar",
    "read_scannet1500",
    "read_scannet_pairs",
    "read_wxbs",
    "rotate_image",
    "rotated_pair",
    "scale_intrinsics",
    "skew",
    "transform_view",
]
