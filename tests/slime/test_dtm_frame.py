"""The global DTM's frame: image 0 compared in image 1's frame under a strong tilt."""

import re

import numpy as np
import pytest

from slime_match.errors import ConfigError
from slime_match.slime.dtm_frame import dtm_frame
from slime_match.slime.pipeline import SlimeConfig
from slime_match.slime.refine import TileMatches, final_matches, global_dtm


def rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def tilted(tilt: float) -> np.ndarray:
    """(2, 2) a rotation, a squeeze by ``tilt`` and another rotation: singular values 1 and 1 / tilt."""
    return rotation(0.2) @ np.diag([1.0, 1.0 / tilt]) @ rotation(-0.1)


def tilted_plane_and_wrong_cluster(tilt: float, seed: int):
    """200 correct matches spread over image 0 and squeezed by ``tilt`` in image 1, and a compact cluster of
    120 wrong matches that agree with one another (a rotated, scaled patch elsewhere): the structure of an
    extreme-viewpoint pair's last candidates."""
    rng = np.random.default_rng(seed)
    x0 = rng.uniform(0, 600, (200, 2))
    x1 = x0 @ tilted(tilt).T + [100, 300] + rng.normal(0, 0.7, (200, 2))
    w0 = rng.uniform(200, 300, (120, 2))
    w1 = (w0 - 250) @ rotation(1.0).T * 0.8 + [500, 500] + rng.normal(0, 0.7, (120, 2))
    return np.vstack([x0, w0]), np.vstack([x1, w1]), rng.uniform(0, 1, 320)


@pytest.mark.parametrize("tilt", [3.0, 8.0])
def test_the_frame_measures_the_tilt_and_maps_image_0_onto_image_1(tilt):
    rng = np.random.default_rng(0)
    x0 = rng.uniform(0, 600, (300, 2))
    x1 = x0 @ (0.9 * tilted(tilt)).T + [300, 250] + rng.normal(0, 0.5, (300, 2))
    x1[:90] = rng.uniform(0, 800, (90, 2))  # 30% outliers
    frame = dtm_frame(x0, x1, (600, 600), (800, 800))
    assert frame.tilt == pytest.approx(tilt, rel=0.03)
    assert frame.affine is not None and frame.reason.startswith("image 1's frame")
    shift = frame.map(x0[90:]) - x1[90:]  # image 1's frame up to the shift that keeps it at the origin
    assert np.abs(shift - np.median(shift, 0)).max() < 3
    mapped_corners = frame.map(np.array([[0.0, 0], [599, 0], [0, 599], [599, 599]]))
    assert mapped_corners.min() == pytest.approx(0, abs=1e-6)
    assert np.all(mapped_corners.max(0) <= np.array(frame.size[::-1]) - 1 + 1e-6)


def test_similar_views_keep_their_own_frames():
    rng = np.random.default_rng(1)
    x0 = rng.uniform(0, 600, (300, 2))
    x1 = x0 @ (1.3 * rotation(0.7)).T + [40, -20]
    frame = dtm_frame(x0, x1, (600, 600), (900, 900))
    assert frame.affine is None and frame.size == (600, 600)
    assert frame.tilt == pytest.approx(1.0, abs=0.01)
    assert frame.reason == ("image 0's own frame: the matches' affine map stretches one direction 1.0 times more than "
                            "the other (its tilt), not more than 2 (dtm_max_tilt)")
    assert dtm_frame(x0, x1 @ np.diag([1, 1 / 1.8]), (600, 600), (900, 900)).affine is None
    assert np.isnan(dtm_frame(x0, x1, (600, 600), (900, 900), max_tilt=np.inf).tilt)


def test_degenerate_or_too_few_matches_keep_the_own_frame():
    x0 = np.stack([np.linspace(0, 500, 50), np.linspace(0, 300, 50)], 1)  # on a line: no affine map
    x1 = x0 * 1.2
    assert dtm_frame(x0, x1, (400, 600), (400, 600)).affine is None
    assert dtm_frame(x0[:2], x1[:2], (400, 600), (400, 600)).affine is None


@pytest.mark.parametrize("seed", [0, 1])
def test_under_a_strong_tilt_the_global_dtm_keeps_the_plane_not_the_compact_wrong_cluster(seed):
    xy0, xy1, scores = tilted_plane_and_wrong_cluster(12.0, seed)
    correct = lambda k0, k1: np.linalg.norm(k0 @ tilted(12.0).T + [100, 300] - k1, axis=1) < 3
    k0, k1, _, frame = global_dtm(xy0, xy1, scores, (600, 600), (800, 800))
    assert frame.affine is not None and correct(k0, k1).sum() >= 190 and not (~correct(k0, k1)).any()
    k0, k1, _, frame = global_dtm(xy0, xy1, scores, (600, 600), (800, 800), max_tilt=np.inf)  # the paper's
    assert frame.affine is None and correct(k0, k1).sum() < 20


def test_final_matches_record_the_frame_and_its_reason():
    xy0, xy1, scores = tilted_plane_and_wrong_cluster(12.0, 0)
    tiles = TileMatches(xy0[:0], xy1[:0], scores[:0])
    final = final_matches(xy0, xy1, scores, tiles, (600, 600), (800, 800), True)
    assert re.fullmatch(r"image 1's frame: the matches' affine map stretches one direction 1\d\.\d times more than "
                        r"the other \(its tilt\), more than 2 \(dtm_max_tilt\)", final.dtm_frame), final.dtm_frame
    assert final_matches(xy0, xy1, scores, tiles, (600, 600), (800, 800), False).dtm_frame == ""


def test_the_tilt_bound_is_checked():
    with pytest.raises(ConfigError, match="dtm_max_tilt"):
        SlimeConfig(dtm_max_tilt=0.5)
    assert SlimeConfig(dtm_max_tilt=float("inf")).dtm_max_tilt == float("inf")
