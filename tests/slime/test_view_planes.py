"""Simulated views end to end on a real tilted pair (graf 1 -> 3, exact GT): Slime's view planes, of image 0 or
of image 1, map back to the original frames, a base pipeline alone pools its views' matches, and the views step
records what it tried, what it decided and why."""

import re

import cv2
import numpy as np
import pytest

from slime_match.config import make_config
from slime_match.eval.metrics import correct_matches_homography
from slime_match.geometry.homography import project
from slime_match.matcher import Matcher

from .helpers import WEIGHT_FREE
from .test_pipeline import graf_small  # noqa: F401  (the module fixture)


def _correct(result, h) -> np.ndarray:
    return correct_matches_homography(result.keypoints0, result.keypoints1, h)


def _plane_error(stages, plane: int, h: np.ndarray) -> float:
    """Median px distance between a plane's homography and ``h`` at the plane's image-0 block matches."""
    points = stages["block_matches_xy0"][stages["block_matches_plane"] == plane]
    mine, _ = project(stages["planes_H"][plane], points)
    truth, _ = project(h, points)
    return float(np.median(np.linalg.norm(mine - truth, axis=1)))


def test_slime_view_planes_hold_the_pairs_geometry(graf_small):  # noqa: F811
    a, b, h = graf_small
    result = Matcher(make_config("slime", views="always", scales=(1, 2), keep_stages=True,
                                 **{"views.tilts": (2.0,), "views.images": "image0"}, **WEIGHT_FREE))(a, b)
    views = result.summary["decisions"]["views"]
    found, reason, plain_tilt = views.pop("tried"), views.pop("reason"), views.pop("plain_tilt")
    assert views == {"mode": "always", "images": "image0", "tilts": [2.0], "views": 5, "decision": "kept"}
    assert plain_tilt["tilt"] >= 1.0 and plain_tilt["matches"] >= 10 and plain_tilt["planes"] >= 2  # a plain F^theta
    assert re.fullmatch(r"every view tried; image 0's views hold the most: enough matches consistent with the "
                        r"planes' epipolar geometry \(F\^theta\): \d+ >= 100", reason), reason
    assert found[0]["support"] >= found[0]["ftheta_matches"]
    assert result.summary["counts"]["views"] == 5
    stages = result.stages
    from_view = stages["planes_pairs"][:, 0] >= len(stages["blocks0"])
    assert from_view.sum() >= 5, "the views of a 40-degree viewpoint change give planes"
    assert found[0]["image"] == 0 and found[0]["tilt"] == 2.0 and found[0]["views"] == 5
    assert found[0]["planes"] == from_view.sum()
    on_view_planes = np.zeros(len(stages["table_xy0"]), bool)  # F^theta's matches on the views' planes
    for s in np.flatnonzero(from_view[stages["ftheta_plane"]]):
        on_view_planes[stages["ftheta_indices"][stages["ftheta_indptr"][s]:stages["ftheta_indptr"][s + 1]]] = True
    assert found[0]["ftheta_matches"] == on_view_planes.sum() > 0
    by_angle = found[0]["ftheta_by_angle"]  # the views that found them: ASIFT's angles at tilt 2 (36 deg apart)
    assert by_angle and set(by_angle) <= {"0", "36", "72", "108", "144"}
    assert max(by_angle.values()) <= found[0]["ftheta_matches"] <= sum(by_angle.values())
    views = stages["planes_view0"]  # each plane's image-0 block: its view and its outline in original px
    assert np.all(views[from_view, 0] == 2.0) and np.all(views[~from_view] == [1.0, 0.0])
    assert np.all(stages["planes_view1"] == [1.0, 0.0])
    boxes = stages["blocks0"][stages["planes_pairs"][~from_view, 0]]
    np.testing.assert_allclose(stages["planes_corners0"][~from_view],
                               boxes[:, [0, 1, 2, 1, 2, 3, 0, 3]].reshape(-1, 4, 2), atol=1e-9)
    for plane in np.flatnonzero(from_view):  # a view plane's matches lie in its block's outline in image 0
        quad = stages["planes_corners0"][plane].astype(np.float32)
        points = stages["block_matches_xy0"][stages["block_matches_plane"] == plane]
        assert all(cv2.pointPolygonTest(quad, (float(x), float(y)), True) > -1.0 for x, y in points)
    in_view = from_view[stages["block_matches_plane"]]
    xy0, xy1 = stages["block_matches_xy0"][in_view], stages["block_matches_xy1"][in_view]
    ok = correct_matches_homography(xy0, xy1, h)
    assert ok.mean() >= 0.8, ok.mean()  # mapped back through the view's affine map: the GT holds
    for plane in np.flatnonzero(from_view)[:3]:  # each view plane's homography is the pair's, where it holds
        assert _plane_error(stages, plane, h) < 5.0
    ok = _correct(result, h)
    assert ok.mean() >= 0.9 and ok.sum() > 500


def test_views_of_image_1_hold_the_pairs_geometry_with_the_images_exchanged(graf_small):  # noqa: F811
    """graf 3 -> 1: the views of image 1 (graf 1) compensate the tilt as image 0's views do for graf 1 -> 3;
    their planes map image 0 to image 1 like every plane, and their blocks are image 1's."""
    a, b, h = graf_small
    inverse = np.linalg.inv(h)
    result = Matcher(make_config("slime", views="always", scales=(1, 2), keep_stages=True,
                                 **{"views.tilts": (2.0,), "views.images": "image1"}, **WEIGHT_FREE))(b, a)
    record = result.summary["decisions"]["views"]
    assert record["images"] == "image1" and record["decision"] == "kept"
    step, = record["tried"]
    assert (step["image"], step["tilt"], step["views"]) == (1, 2.0, 5) and step["ftheta_matches"] > 0
    stages = result.stages
    from_view = stages["planes_pairs"][:, 1] >= len(stages["blocks1"])
    assert from_view.sum() == step["planes"] >= 5
    assert np.all(stages["planes_pairs"][:, 0] < len(stages["blocks0"]))  # image 0's own blocks
    assert np.all(stages["planes_view1"][from_view, 0] == 2.0) and np.all(stages["planes_view0"] == [1.0, 0.0])
    for plane in np.flatnonzero(from_view):  # a view plane's matches lie in its block's outline in image 1
        quad = stages["planes_corners1"][plane].astype(np.float32)
        points = stages["block_matches_xy1"][stages["block_matches_plane"] == plane]
        assert all(cv2.pointPolygonTest(quad, (float(x), float(y)), True) > -1.0 for x, y in points)
    in_view = from_view[stages["block_matches_plane"]]
    ok = correct_matches_homography(stages["block_matches_xy0"][in_view], stages["block_matches_xy1"][in_view],
                                    inverse)
    assert ok.mean() >= 0.8, ok.mean()
    for plane in np.flatnonzero(from_view)[:3]:  # image 0 -> image 1, as the pair's GT
        assert _plane_error(stages, plane, inverse) < 5.0
    ok = _correct(result, inverse)
    assert ok.mean() >= 0.9 and ok.sum() > 500


def test_views_probed_on_their_finest_level_pair_only_those_above_the_floor(graf_small):  # noqa: F811
    """With level matching, each view's finest level is matched against image 1 first: the views whose probe
    holds ``views.min_probe`` epipolar-consistent matches are paired, the others are not; a floor every view
    passes gives exactly the unprobed result (the probe's matches are the level pair's own). A screen on
    fewer keypoints first leaves the views under its floor unprobed."""
    a, b, _ = graf_small

    def run(min_probe: int, screen: int = 0):
        config = make_config("slime", views="always", scales=(1, 2), keep_stages=True, block_matching="levels",
                             **{"views.tilts": (2.0,), "views.images": "image0", "views.min_probe": min_probe,
                                "views.screen_keypoints": screen}, **WEIGHT_FREE)
        result = Matcher(config)(a, b)
        step, = result.summary["decisions"]["views"]["tried"]
        return result, step

    unprobed, step = run(0)
    assert "probes" not in step and "paired" not in step and step["views"] == 5
    # a screen on more keypoints than the levels hold is the probe itself: every view passes it
    everyone, step = run(1, screen=10**6)
    probes = step["probes"]
    assert set(probes) == {"0", "36", "72", "108", "144"} and min(probes.values()) >= 1 and step["paired"] == 5
    assert step["screens"] == probes
    for name in ("keypoints0", "keypoints1", "scores"):
        np.testing.assert_array_equal(getattr(everyone, name), getattr(unprobed, name))
    floor = sorted(probes.values())[-2]  # the two strongest views pass
    some, step = run(floor)
    assert step["probes"] == probes and step["paired"] == 2 and step["screens"] == {}
    passed = {float(angle) for angle, count in probes.items() if count >= floor}
    stages = some.stages
    from_view = stages["planes_pairs"][:, 0] >= len(stages["blocks0"])
    assert from_view.any() and set(stages["planes_view0"][from_view, 1]) <= passed
    _, step = run(max(probes.values()) + 1)
    assert step["paired"] == 0 and step["planes"] == 0
    # on 2 keypoints a side no screen has the 8 matches a fundamental matrix needs: none probed in full, none paired
    _, step = run(1, screen=2)
    assert step["screens"] == dict.fromkeys(probes, 0)
    assert step["probes"] == {} and step["paired"] == 0 and step["planes"] == 0


def test_auto_views_stop_when_the_plain_run_agrees_and_leave_it_when_they_find_nothing_stronger(graf_small):  # noqa: F811
    a, b, _ = graf_small
    options = {"scales": (1, 2), **WEIGHT_FREE}
    result = Matcher(make_config("slime", **options))(a, b)
    views = result.summary["decisions"]["views"]
    assert views["mode"] == "auto" and views["views"] == 0 and views["tilts"] == []
    assert views["decision"] == "not needed" and "tried" not in views
    assert re.fullmatch(r"enough matches consistent with the planes' epipolar geometry \(F\^theta\): \d+ >= 100",
                        views["reason"]), views["reason"]
    off = Matcher(make_config("slime", views="off", **options))(a, b)
    assert off.summary["decisions"]["views"]["reason"] == "views off"
    assert off.summary["decisions"]["views"]["decision"] == "off"
    # views that never reach the support asked for are tried, and their planes dropped: the plain run's matches
    unreached = Matcher(make_config("slime", **{"views.tilts": (2.0,), "views.min_support": 10**9}, **options))(a, b)
    record = unreached.summary["decisions"]["views"]
    assert record["views"] == 10 and record["tilts"] == [2.0] and record["decision"] == "dropped" and re.fullmatch(
        r"every view tried, and F\^theta holds at best \d+ matches, \d+ on the views' own planes and \d+ more than "
        r"the images' own planes' \(asked: 1000000000 on the views' planes, and 1000000000 in all or 1000000000 "
        r"more\): the planes of the images alone are kept", record["reason"])
    assert [step["image"] for step in record["tried"]] == [0, 1]  # both images' views, by default
    for step in record["tried"]:
        assert step["planes"] > 0 and step["ftheta_matches"] == 0 and step["ftheta_by_angle"] == {}  # dropped
        assert 0 <= step["on_views"] <= step["support"]
    for other in (result, unreached):  # auto without views, or with views dropped = off
        np.testing.assert_array_equal(other.keypoints0, off.keypoints0)
        np.testing.assert_array_equal(other.keypoints1, off.keypoints1)
        np.testing.assert_array_equal(other.scores, off.scores)


def test_base_pipeline_pools_its_views_matches(graf_small):  # noqa: F811
    a, b, h = graf_small
    plain = Matcher(make_config("hz+", views="off", **WEIGHT_FREE))(a, b)
    viewed = Matcher(make_config("hz+", views="always", **{"views.tilts": (2.0,)}, **WEIGHT_FREE))(a, b)
    assert viewed.summary["decisions"]["views"]["views"] == 10 and viewed.summary["counts"]["views"] == 10
    assert len(viewed) > len(plain)
    assert _correct(viewed, h).sum() > _correct(plain, h).sum()
    assert np.all(np.diff(viewed.scores) >= 0)  # pooled matches sorted by score
    height, width = a.shape[:2]
    assert np.all((viewed.keypoints0 >= -0.5) & (viewed.keypoints0 <= [width - 0.5, height - 0.5]))
    turned = Matcher(make_config("hz+", views="always", **{"views.tilts": (2.0,), "views.images": "image1"},
                                 **WEIGHT_FREE))(b, a)  # graf 3 -> 1: image 1's views pool the same way
    plain_turned = Matcher(make_config("hz+", views="off", **WEIGHT_FREE))(b, a)
    assert [step["image"] for step in turned.summary["decisions"]["views"]["tried"]] == [1]
    inverse = np.linalg.inv(h)
    assert _correct(turned, inverse).sum() > _correct(plain_turned, inverse).sum()
    assert np.all((turned.keypoints1 >= -0.5) & (turned.keypoints1 <= [width - 0.5, height - 0.5]))
    auto = Matcher(make_config("hz+", **WEIGHT_FREE))(a, b)
    record = auto.summary["decisions"]["views"]
    assert record["mode"] == "auto" and re.fullmatch(
        r"enough matches consistent with one epipolar geometry \(a fundamental matrix F\): \d+ >= 50", record["reason"])


@pytest.mark.parametrize("bad", [{"views": "sometimes"}, {"views.tilts": (0.5,)}])
def test_bad_view_options_are_refused(bad):
    from slime_match.errors import ConfigError

    with pytest.raises(ConfigError):
        make_config("slime", **bad)
