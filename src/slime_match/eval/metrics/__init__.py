"""Evaluation metrics of the paper (Sec. "Error metrics") and of the standard pose benchmarks.

* correct matches (:mod:`.correctness`): planar (two-sided reprojection error), non-planar (max epipolar
  distance plus local consistency with the hand-taken GT correspondences), rectified stereo (disparity);
* coverage (:mod:`.coverage`): dilated area of the correct keypoints over the valid area, minimum of the two
  images;
* accuracy (:mod:`.accuracy`): mean error of the estimated model over the valid pixels (homography
  reprojection, or the area between estimated and GT epipolar lines over the image diagonal), aggregated by
  mAA (Eq. acc_formula);
* pose (:mod:`.pose`): LoFTR protocol (essential matrix RANSAC in normalised coordinates, angular errors,
  AUC@5/10/20).
* standard protocols of the hard sets (:mod:`.protocols`, imported as a module): EVD homography and WxBS
  fundamental matrix by OpenCV MAGSAC++ on the raw matches, pair mAA.

All coordinates are pixels ``(x, y)`` with the centre of the top-left pixel at ``(0, 0)``; image shapes are
``(height, width)``; masks are boolean, ``valid`` masks True = usable, ``mask0/mask1`` True = excluded.
"""

from slime_match.eval.metrics.accuracy import (
    epipolar_line_area,
    failure_counts,
    fundamental_accuracy_error,
    homography_accuracy_error,
    mean_average_accuracy,
)
from slime_match.eval.metrics.config import DEFAULTS, MetricConfig
from slime_match.eval.metrics.correctness import (
    correct_matches_disparity,
    correct_matches_fundamental,
    correct_matches_homography,
    disparity_error,
    in_mask,
)
from slime_match.eval.metrics.coverage import (
    coverage,
    dilated_mask,
    valid_area_homography,
    valid_area_nonplanar,
)
from slime_match.eval.metrics.pose import (
    estimate_pose_essential,
    pose_auc,
    pose_errors_sweep,
    pose_from_fundamental,
    relative_pose_error,
)

__all__ = [
    "DEFAULTS",
    "MetricConfig",
    "correct_matches_disparity",
    "correct_matches_fundamental",
    "correct_matches_homography",
    "coverage",
    "dilated_mask",
    "disparity_error",
    "epipolar_line_area",
    "estimate_pose_essential",
    "failure_counts",
    "fundamental_accuracy_error",
    "homography_accuracy_error",
    "in_mask",
    "mean_average_accuracy",
    "pose_auc",
    "pose_errors_sweep",
    "pose_from_fundamental",
    "relative_pose_error",
    "valid_area_homography",
    "valid_area_nonplanar",
]
