"""MatchResult's conventions of the field: a confidence (higher is better) beside the dissimilarity, and a dict
with the keys that kornia and vismatch users read."""

import numpy as np
import pytest

from slime_match.result import MatchResult, confidence_of
from slime_match.runs.hloc import similarity


def _result(**extra) -> MatchResult:
    return MatchResult(np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]), np.array([[1.5, 2.0], [3.5, 4.0], [9.0, 9.0]]),
                       np.array([0.0, 1.0, 3.0]), image_sizes=((10, 8), (10, 8)), **extra)


def test_confidence_is_one_over_one_plus_the_score_and_ranks_as_the_scores_do():
    scores = np.array([2.5, 0.0, 1.0, 0.1, 7.0, -0.2])
    confidence = confidence_of(scores)
    np.testing.assert_allclose(confidence, [1 / 3.5, 1.0, 0.5, 1 / 1.1, 0.125, 1.0])
    assert np.all((confidence > 0) & (confidence <= 1))
    kept = scores >= 0  # negative dissimilarities count as 0
    assert list(np.argsort(-confidence[kept], kind="stable")) == list(np.argsort(scores[kept], kind="stable"))
    np.testing.assert_allclose(_result().confidence, [1.0, 0.5, 0.25])
    np.testing.assert_allclose(similarity(scores), confidence.astype(np.float32))  # hloc's scores are the same


def test_to_dict_without_ransac_has_the_matches_and_no_model():
    d = _result().to_dict()
    assert d["num_matches"] == 3 and d["keypoints0"].shape == (3, 2)
    np.testing.assert_array_equal(d["matched_kpts1"], d["keypoints1"])
    np.testing.assert_allclose(d["confidence"], [1.0, 0.5, 0.25])
    assert d["inliers"] is None and d["inlier_kpts0"] is None and d["num_inliers"] is None
    assert d["H"] is None and d["F"] is None and d["image_sizes"] == ((10, 8), (10, 8))


@pytest.mark.parametrize("kind", ["homography", "fundamental"])
def test_to_dict_with_ransac_has_the_inliers_and_the_model_under_its_name(kind):
    model = np.arange(9.0).reshape(3, 3)
    d = _result(inliers=np.array([True, True, False]), geometry_kind=kind, model=model).to_dict()
    assert d["num_inliers"] == 2 and d["inlier_kpts0"].shape == (2, 2) and d["inlier_kpts1"].shape == (2, 2)
    np.testing.assert_array_equal(d["inlier_kpts1"], [[1.5, 2.0], [3.5, 4.0]])
    name, other = ("H", "F") if kind == "homography" else ("F", "H")
    np.testing.assert_array_equal(d[name], model)
    assert d[other] is None


def test_an_empty_result_gives_empty_arrays():
    d = MatchResult(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)).to_dict()
    assert d["num_matches"] == 0 and d["confidence"].shape == (0,) and d["keypoints0"].shape == (0, 2)


def test_indexed_gives_each_position_once_and_matches_by_index():
    result = MatchResult(np.array([[1.0, 2.0], [1.0, 2.0], [0.5, 9.0]]), np.array([[4.0, 4.0], [5.0, 5.0], [4.0, 4.0]]),
                         np.array([0.1, 0.2, 0.3]))
    keypoints0, keypoints1, matches = result.indexed()
    assert keypoints0.shape == (2, 2) and keypoints1.shape == (2, 2) and matches.shape == (3, 2)
    assert matches.dtype == np.int64
    np.testing.assert_array_equal(keypoints0[matches[:, 0]], result.keypoints0)
    np.testing.assert_array_equal(keypoints1[matches[:, 1]], result.keypoints1)
    empty = MatchResult(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)).indexed()
    assert empty[0].shape == (0, 2) and empty[2].shape == (0, 2)
