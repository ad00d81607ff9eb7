"""The quarter-turn check of bases upright by design: the turned frame maps pixels as np.rot90 moves them, the
check reads the turn of a turned copy, and Slime on ALIKED + LightGlue matches a turned pair as the upright one,
in the turned image's own pixels."""

import cv2
import numpy as np
import pytest
import torch
from conftest import DATA, require, require_learned_weights, rotated_astronaut
from scipy.spatial import cKDTree

import slime_match as sm
from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.geometry.frames import Frame
from slime_match.io import load_image
from slime_match.pipelines import make_base_pipeline
from slime_match.quarter_turns import check_quarter_turns, chosen_turn, turned_frame

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_turned_frame_maps_pixels_as_rot90_moves_them(k):
    rng = np.random.default_rng(k)
    original = rng.random((5, 7))  # (H, W)
    turned = np.rot90(original, k)
    frame = turned_frame(Frame(), (7, 5), k)
    ys, xs = np.mgrid[0:5, 0:7]
    xy = np.stack([xs.ravel(), ys.ravel()], 1).astype(float)
    moved = np.rint(frame.from_original(xy)).astype(int)
    assert np.array_equal(turned[moved[:, 1], moved[:, 0]], original[ys.ravel(), xs.ravel()])
    assert np.allclose(frame.to_original(frame.from_original(xy)), xy)


def test_turned_frame_of_a_resized_image_swaps_the_factors_of_an_odd_turn():
    frame = turned_frame(Frame((0.5, 0.25)), (8, 16), 1)  # an 8 x 16 original matched at 4 x 4
    assert frame.factor == (0.25, 0.5)
    # the original's top-right pixel centre (7, 0) comes to the turned working image's top-left corner region
    assert np.allclose(frame.from_original([[7.5, -0.5]]), [[-0.5, -0.5]])


def _turn_homography(k: int, size: int = 384) -> np.ndarray:
    """(3, 3) map of pixels of a size x size image to those of ``np.rot90(image, k)``."""
    last = size - 1.0
    return {0: np.eye(3), 1: np.array([[0, 1, 0], [-1, 0, last], [0, 0, 1.0]]),
            2: np.array([[-1, 0, last], [0, -1, last], [0, 0, 1.0]]),
            3: np.array([[0, -1, last], [1, 0, 0], [0, 0, 1.0]])}[k]


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_the_check_reads_the_turn_back(k):
    require_learned_weights("aliked-n16", "lightglue-aliked")
    image0, image1, _ = rotated_astronaut()
    pipeline = make_base_pipeline(make_config("slime-aliked").base, torch.device("cpu"))
    turn = check_quarter_turns(pipeline, image0, np.ascontiguousarray(np.rot90(image1, k)))
    assert turn.quarter_turns == (4 - k) % 4, turn
    taken = turn.inliers[turn.quarter_turns]
    assert all(taken >= 2 * n for i, n in enumerate(turn.inliers) if i != turn.quarter_turns), turn
    assert turn.as_dict()["degrees"] == 90 * turn.quarter_turns and "consistent matches" in turn.reason


@pytest.mark.parametrize(("inliers", "turn"), [
    ((242, 21, 9, 10), 0),  # an upright planar pair
    ((10, 20, 12, 8), 0),  # a hard upright pair: every reading under the floor
    ((0, 39, 0, 0), 0),  # under the floor
    ((30, 59, 0, 0), 0),  # under twice a weak upright reading
    ((30, 60, 0, 0), 1),
    ((0, 3, 72, 0), 2),
    ((127, 180, 16, 8), 1),  # a base partly following the turn: above the floor a lead of 40 suffices
    ((100, 139, 0, 0), 0),  # a lead under 40
    ((100, 0, 0, 140), 3),
])
def test_a_turn_is_taken_only_as_the_clear_winner(inliers, turn):
    assert chosen_turn(inliers) == turn


def test_the_check_turns_back_a_pair_the_base_partly_follows_turned():
    """Graf 1->4 with image 1 turned 90 degrees clockwise: ALIKED + LightGlue partly follow the turn of this
    foreshortened view, so the upright reading passes the floor, yet the turn back leads it by more than 40."""
    require_learned_weights("aliked-n16", "lightglue-aliked")
    graf = require(DATA / "oxford_graf")
    image0, image1 = load_image(graf / "img1.png"), load_image(graf / "img4.png")
    pipeline = make_base_pipeline(make_config("slime-aliked").base, torch.device("cpu"))
    turn = check_quarter_turns(pipeline, image0, np.ascontiguousarray(np.rot90(image1, 3)))
    assert turn.quarter_turns == 1, turn
    assert turn.inliers[0] > 40, turn  # the case the lead rule is for


def test_slime_on_aliked_matches_a_turned_pair_as_the_upright_one():
    """A quarter turn of image 1 gives the upright pair's matches, in the turned image's pixels."""
    require_learned_weights("aliked-n16", "lightglue-aliked")
    image0, image1, H = rotated_astronaut()
    upright = sm.match(image0, image1, "slime-aliked", views="off", device="cpu")
    turned = sm.match(image0, np.rot90(image1, 1), "slime-aliked", views="off", device="cpu")
    assert upright.summary["decisions"]["quarter_turns"]["degrees"] == 0
    assert turned.summary["decisions"]["quarter_turns"]["degrees"] == 270
    assert turned.summary["working_sizes"] == upright.summary["working_sizes"]
    assert len(turned.scores) == len(upright.scores) > 1000
    # the same matches, in an order that the networks' float rounding on the turned image may change among ties
    expected = cv2.perspectiveTransform(upright.keypoints1[None], _turn_homography(1))[0]
    distance, _ = cKDTree(np.hstack([upright.keypoints0, expected])).query(
        np.hstack([turned.keypoints0, turned.keypoints1]))
    assert np.mean(distance < 0.01) > 0.99
    projected = cv2.perspectiveTransform(turned.keypoints0[None], _turn_homography(1) @ H)[0]
    assert np.mean(np.linalg.norm(projected - turned.keypoints1, axis=1) < 3.0) > 0.85


def test_quarter_turns_is_a_slime_option():
    assert make_config("slime-aliked", quarter_turns="off").quarter_turns == "off"
    with pytest.raises(ConfigError, match="is a Slime option"):
        make_config("aliked-lg", quarter_turns="off")
    with pytest.raises(ConfigError, match="quarter_turns"):
        make_config("slime-aliked", quarter_turns="sometimes")
