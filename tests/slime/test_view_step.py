"""The views step's policy (slime.view_step.add_views) on stand-in plane states whose F^theta support is given:
when views are tried, which image's branch is kept, and that the two images' views are never pooled."""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from slime_match.slime import view_step
from slime_match.slime.tile_sets import TileSets
from slime_match.views import ViewConfig


@dataclass
class _Sets:
    """F^theta with ``support`` distinct matches."""

    support: int

    def union(self) -> np.ndarray:
        return np.ones(self.support, bool)


@dataclass
class _Selection:
    ftheta: _Sets
    on_views: int


@dataclass
class _Planes:
    H: list


@dataclass
class _Found:
    """The views of one (image, tilt): how many, their planes, the F^theta support they add to a branch and how
    much of it lies on the images' own planes (``moved``: the vote's doing, not the views' planes')."""

    image: int
    views: int
    planes: _Planes
    gain: int
    moved: int = 0
    probes: dict = field(default_factory=dict)
    screens: dict = field(default_factory=dict)
    paired: int = 0


@dataclass
class _State:
    """A plane state: its F^theta support, how much of it its views' planes hold, and the (image, tilt) steps
    whose planes it holds."""

    support: int
    steps: tuple = ()
    planes: _Planes = field(default_factory=lambda: _Planes([0] * 10))
    on_views: int = 0

    @property
    def selection(self) -> _Selection:
        return _Selection(_Sets(self.support), self.on_views)

    def with_views(self, found: _Found, select) -> _State:
        return _State(self.support + found.gain, self.steps + (found.image,),
                      _Planes(self.planes.H + found.planes.H), self.on_views + found.gain - found.moved)


@pytest.fixture(autouse=True)
def _no_tile_sets(monkeypatch):
    """The stand-in states hold no tile sets: each kept step's F^theta count is its planes' count, and the
    views' share of a branch's F^theta is the stand-in's."""
    monkeypatch.setattr(view_step, "_in_ftheta", lambda state, image, start, stop: (stop - start, {}))
    monkeypatch.setattr(view_step, "_support_from", lambda selection, first: selection.on_views)


def _finder(gains: dict[tuple[int, float], int], calls: list, moved: dict[tuple[int, float], int]):
    def find(image: int, tilt: float) -> _Found:
        calls.append((image, tilt))
        return _Found(image, 5 if tilt == 2 else 10, _Planes([0] * 3), gains[image, tilt], moved.get((image, tilt), 0))
    return find


def _run(mode: str, images: str, plain: int, gains: dict[tuple[int, float], int], gain: float = 1.0,
         moved: dict[tuple[int, float], int] | None = None, plain_tilt: view_step.PlainTilt | None = None, **views):
    calls = []
    state, record = view_step.add_views(_State(plain), ViewConfig(mode=mode, images=images, **views),
                                        _finder(gains, calls, moved or {}), select=None, gain=gain,
                                        plain_tilt=plain_tilt)
    return state, record, calls


def _tilt(tilt: float, matches: int, planes: int = 3) -> view_step.PlainTilt:
    return view_step.PlainTilt(tilt, matches, planes)


GAINS = {(0, 2.0): 20, (1, 2.0): 90, (0, 4.0): 30, (1, 4.0): 5}


def test_enough_plain_geometry_needs_no_view():
    state, record, calls = _run("auto", "both", 100, GAINS)
    assert calls == [] and state.steps == () and record.decision == "not needed" and record.tried == []


@pytest.mark.parametrize("plain_tilt", [_tilt(8.0, 46), _tilt(12.0, view_step.TILT_MATCHES - 1),
                                        _tilt(12.0, 46, planes=1), None])
def test_enough_matches_at_a_measured_tilt_within_the_bases_reach_need_no_view(plain_tilt):
    _, record, calls = _run("auto", "both", 100, GAINS, plain_tilt=plain_tilt)
    assert calls == [] and record.decision == "not needed"


def test_enough_matches_on_a_scene_foreshortened_beyond_the_bases_reach_get_views():
    gains = {(0, 2.0): 10, (1, 2.0): 0, (0, 4.0): 40, (1, 4.0): 0}
    state, record, calls = _run("auto", "both", 300, gains, gain=0.35, plain_tilt=_tilt(11.4, 397, planes=12))
    assert calls == [(0, 2.0), (1, 2.0), (0, 4.0)]  # image 1's views hold nothing at tilt 2: image 0's go on
    assert record.decision == "kept" and state.steps == (0, 0) and state.support == 350
    assert record.reason.startswith("image 0's views: 50 matches on their own planes; enough")
    weak = {(image, tilt): 5 for image in (0, 1) for tilt in (2.0, 4.0, 8.0)}
    _, record, calls = _run("auto", "both", 300, weak, gain=0.35, plain_tilt=_tilt(11.4, 397))
    assert record.decision == "dropped" and record.tilts == [2.0, 4.0, 8.0]  # the views' planes hold too little
    _, record, calls = _run("auto", "both", 300, gains, plain_tilt=_tilt(11.4, 397), max_tilt=float("inf"))
    assert calls == [] and record.decision == "not needed"


def test_a_scene_foreshortened_beyond_the_bases_reach_gets_the_steep_tilts_after_the_others():
    gains = {(0, 2.0): 0, (1, 2.0): 0, (0, 4.0): 0, (1, 4.0): 0, (0, 6.0): 0, (1, 6.0): 0, (0, 8.0): 120,
             (1, 8.0): 0}
    state, record, calls = _run("auto", "both", 11, gains, gain=0.35, plain_tilt=_tilt(10.7, 11))
    assert calls == [(0, 2.0), (1, 2.0), (0, 4.0), (1, 4.0), (0, 8.0), (1, 8.0)]
    assert record.decision == "kept" and state.steps == (0, 0, 0) and record.tilts == [2.0, 4.0, 8.0]
    assert record.reason.endswith("the plain matches' affine map reads a tilt of 10.70 > 8.00 (views.max_tilt): "
                                  "views tried whatever F^theta held, tilts 8 after the others")
    for plain_tilt in (_tilt(7.9, 46), None):  # within the base's reach, or not measured: the tilts alone
        _, record, calls = _run("auto", "both", 11, gains, gain=0.35, plain_tilt=plain_tilt)
        assert [tilt for _, tilt in calls] == [2.0, 2.0, 4.0, 4.0] and record.decision == "dropped"
    _, _, calls = _run("auto", "both", 11, gains, gain=0.35, plain_tilt=_tilt(10.7, 11), steep_tilts=(4.0, 6.0))
    assert [tilt for _, tilt in calls] == [2.0, 2.0, 4.0, 4.0, 6.0, 6.0]  # a steep tilt among the tilts runs once
    gains = gains | {(0, 2.0): 150}
    _, record, calls = _run("auto", "both", 11, gains, gain=0.35, plain_tilt=_tilt(10.7, 11))
    assert calls == [(0, 2.0), (1, 2.0)] and record.decision == "kept"  # kept at tilt 2: no steeper tilt


def test_too_few_matches_that_show_no_tilt_need_no_view():
    state, record, calls = _run("auto", "both", 60, GAINS, plain_tilt=_tilt(1.3, 46))
    assert calls == [] and state.steps == () and record.decision == "not needed" and record.tried == []
    assert record.reason == ("too few matches consistent with the planes' epipolar geometry (F^theta): 60 < 100; "
                             "46 of them, on 3 planes, lie on one affine map of tilt 1.30 < 1.41 (views.min_tilt): "
                             "the scene is not foreshortened where the images match, and views undo "
                             "foreshortening")
    assert record.as_dict()["plain_tilt"] == {"tilt": 1.3, "matches": 46, "planes": 3, "measured": True}


@pytest.mark.parametrize("keypoints", [(0, 900), (900, 7)])
def test_an_image_with_fewer_keypoints_than_a_plane_needs_gets_no_view(keypoints):
    calls = []
    _, record = view_step.add_views(_State(0), ViewConfig(mode="auto"), _finder(GAINS, calls, {}), select=None,
                                    keypoints=keypoints, min_matches=8)
    image = keypoints.index(min(keypoints))
    assert calls == [] and record.decision == "not needed" and record.reason.endswith(
        f"the blocks of image {image} hold at most {keypoints[image]} keypoints, fewer than the 8 matches a block "
        "plane needs: the other image's views are matched against them, and its own views hold no texture it lacks")
    _, record = view_step.add_views(_State(0), ViewConfig(mode="auto"), _finder(GAINS, calls, {}), select=None,
                                    keypoints=(8, 8), min_matches=8)
    assert calls[:2] == [(0, 2.0), (1, 2.0)]  # as many as a plane needs: views are tried


@pytest.mark.parametrize(("plain_tilt", "views"), [
    (_tilt(2.0, 46), {}),  # foreshortened where it matched: the views' first tilt undoes 1.41-2.83
    (_tilt(1.1, view_step.TILT_MATCHES - 1), {}),  # too few matches on the map to measure a tilt
    (_tilt(1.1, 46, planes=1), {}),  # one plane's matches: they fit an affine map whatever they are
    (_tilt(float("nan"), 0, 0), {}),  # no affine map fits
    (None, {}),  # not measured
    (_tilt(1.1, 46), {"min_tilt": 1.0}),  # views whatever the tilt
])
def test_too_few_matches_with_a_tilt_or_none_measured_get_views(plain_tilt, views):
    _, record, calls = _run("auto", "both", 60, GAINS, plain_tilt=plain_tilt, **views)
    assert calls[:2] == [(0, 2.0), (1, 2.0)] and record.decision != "not needed"
    assert ("plain_tilt" in record.as_dict()) == (plain_tilt is not None and plain_tilt.matches > 0)


def test_always_tries_views_whatever_the_tilt():
    _, record, calls = _run("always", "both", 60, GAINS, plain_tilt=_tilt(1.1, 46))
    assert len(calls) == 4 and record.decision == "kept" and record.plain_tilt["tilt"] == 1.1


def test_off_tries_nothing():
    state, record, calls = _run("off", "both", 0, GAINS)
    assert calls == [] and state.steps == () and record.decision == "off"


def test_auto_keeps_the_first_branch_that_reaches_the_support_and_never_pools_the_images():
    gains = GAINS | {(1, 2.0): 100}
    state, record, calls = _run("auto", "both", 30, gains)  # image 1's tilt 2 reaches 30 + 100 >= 100
    assert calls == [(0, 2.0), (1, 2.0)]
    assert state.steps == (1,) and state.support == 130  # image 0's views are not in it
    assert record.decision == "kept"
    assert record.reason.startswith("image 1's views: 100 matches on their own planes; enough")
    assert [(t.image, t.support, t.ftheta_matches) for t in record.tried] == [(0, 50, 0), (1, 130, 3)]


def test_a_branch_accumulates_its_own_tilts():
    gains = GAINS | {(0, 2.0): 40, (0, 4.0): 60}
    state, record, calls = _run("auto", "image0", 10, gains)  # image 0: 10 + 40 < 100, then + 60 >= 100
    assert calls == [(0, 2.0), (0, 4.0)] and state.steps == (0, 0) and state.support == 110
    assert record.decision == "kept" and [t.ftheta_matches for t in record.tried] == [3, 3]


def test_the_images_are_compared_at_the_same_tilt_not_the_first_to_reach_the_support():
    gains = GAINS | {(0, 2.0): 110, (1, 2.0): 180}
    state, record, calls = _run("auto", "both", 0, gains)  # image 0: 110, image 1: 180, both >= 100
    assert calls == [(0, 2.0), (1, 2.0)] and state.steps == (1,) and state.support == 180
    assert [t.support for t in record.tried] == [110, 180] and record.reason.startswith("image 1's views")


@pytest.mark.parametrize("plain", [0, 30])
def test_later_tilts_continue_the_leading_branch_only_when_its_views_added_more_than_twice(plain):
    gains = {(0, 2.0): 50, (1, 2.0): 20, (0, 4.0): 60, (1, 4.0): 500}
    state, record, calls = _run("auto", "both", plain, gains)
    assert calls == [(0, 2.0), (1, 2.0), (0, 4.0)] and state.steps == (0, 0) and state.support == plain + 110
    assert [(t.image, t.tilt, t.support, t.ftheta_matches) for t in record.tried] == [
        (0, 2.0, plain + 50, 3), (1, 2.0, plain + 20, 0), (0, 4.0, plain + 110, 3)]


@pytest.mark.parametrize("gains", [{(0, 2.0): 50, (1, 2.0): 40, (0, 4.0): 60, (1, 4.0): 500},
                                   {(0, 2.0): 0, (1, 2.0): 0, (0, 4.0): 60, (1, 4.0): 500}])
def test_a_lead_within_a_factor_of_two_continues_both_branches(gains):
    state, record, calls = _run("auto", "both", 0, gains)  # image 1 overtakes at tilt 4
    assert calls == [(0, 2.0), (1, 2.0), (0, 4.0), (1, 4.0)] and state.steps == (1, 1)
    assert record.decision == "kept" and record.reason.startswith("image 1's views")


def test_auto_drops_the_views_when_no_branch_reaches_the_support():
    state, record, calls = _run("auto", "both", 0, GAINS)  # image 1 leads at tilt 2 (90) and ends at 95
    assert calls == [(0, 2.0), (1, 2.0), (1, 4.0)]
    assert state.steps == () and state.support == 0 and record.decision == "dropped"
    assert "at best 95 matches, 95 on the views' own planes and 95 more" in record.reason
    assert all(t.ftheta_matches == 0 for t in record.tried)


def test_a_branch_under_the_support_is_kept_when_its_views_added_the_bases_gain():
    gains = {(0, 2.0): 20, (1, 2.0): 30, (0, 4.0): 20, (1, 4.0): 5}
    state, record, calls = _run("auto", "both", 50, gains, gain=0.35)  # image 0: 40 added at tilt 4, 90 in all
    assert calls == [(0, 2.0), (1, 2.0), (0, 4.0), (1, 4.0)] and state.steps == (0, 0) and state.support == 90
    assert record.decision == "kept" and record.reason.startswith("image 0's views: 40 matches on their own planes; "
                                                                  "they added 40 >= 35")


def test_a_branch_whose_views_added_less_than_the_gain_is_dropped_whatever_the_plain_support():
    state, record, _ = _run("auto", "both", 90, {(0, 2.0): 5, (1, 2.0): 0, (0, 4.0): 4, (1, 4.0): 0},
                                gain=0.35)  # 99 < 100 in all, 9 < 35 added
    assert state.steps == () and record.decision == "dropped" and "9 more" in record.reason


@pytest.mark.parametrize("gain", [1.0, 0.35])
def test_a_branch_whose_matches_the_views_only_moved_onto_the_images_own_planes_is_dropped(gain):
    gains = {(0, 2.0): 10, (1, 2.0): 60, (0, 4.0): 5, (1, 4.0): 10}
    moved = {(1, 2.0): 60}  # image 1's branch reaches 100 >= 100 at tilt 2, none on its views' planes
    state, record, calls = _run("auto", "both", 40, gains, gain=gain, moved=moved)
    assert state.steps == () and record.decision == "dropped"
    # the next tilt continues image 0, whose views' planes hold the most, not image 1, whose F^theta holds the most
    assert calls == [(0, 2.0), (1, 2.0), (0, 4.0)]
    assert [t.on_views for t in record.tried] == [10, 0, 15]
    assert "at best 55 matches, 15 on the views' own planes" in record.reason


def test_the_leader_is_one_of_the_branches_that_ran_the_tilt():
    gains = {(0, 2.0): 70, (1, 2.0): 50, (1, 4.0): 70}
    moved = {(0, 2.0): 70}  # image 0: 110 at tilt 2, none on its views' planes; image 1: 160 at tilt 4
    state, record, calls = _run("auto", "both", 40, gains, moved=moved)
    assert calls == [(0, 2.0), (1, 2.0), (1, 4.0)] and state.steps == (1, 1) and state.support == 160
    assert record.decision == "kept" and record.reason.startswith("image 1's views: 120 matches on their own planes")


def test_a_branch_is_kept_once_its_views_planes_hold_the_gain():
    gains = {(0, 2.0): 10, (1, 2.0): 80, (0, 4.0): 5, (1, 4.0): 60}
    moved = {(1, 2.0): 40}  # image 1: 40 of 120 on its views' planes at tilt 2, 100 of 180 at tilt 4
    state, record, calls = _run("auto", "both", 40, gains, moved=moved)
    assert calls == [(0, 2.0), (1, 2.0), (1, 4.0)] and state.steps == (1, 1) and state.support == 180
    assert [t.on_views for t in record.tried] == [10, 40, 100]
    assert record.decision == "kept" and record.reason.startswith("image 1's views: 100 matches on their own planes")


def test_always_tries_every_step_and_keeps_the_strongest_branch():
    state, record, calls = _run("always", "both", 100, GAINS)
    assert calls == [(0, 2.0), (1, 2.0), (0, 4.0), (1, 4.0)] and state.steps == (1, 1) and state.support == 195
    assert record.decision == "kept" and record.reason.startswith("every view tried; image 1's views hold the most")


def _plain_state(xy0: np.ndarray, xy1: np.ndarray, plane_of_match: np.ndarray) -> SimpleNamespace:
    """A plain state whose F^theta holds one tile set per plane, each of its plane's matches."""
    planes = np.unique(plane_of_match)
    membership = sp.csr_matrix(plane_of_match[None, :] == planes[:, None])
    ftheta = TileSets.from_csr(membership, planes, np.zeros_like(planes), np.zeros_like(planes))
    return SimpleNamespace(selection=SimpleNamespace(ftheta=ftheta), planes=SimpleNamespace(
        table=SimpleNamespace(xy0=xy0, xy1=xy1)))


def test_the_plain_tilt_counts_the_matches_and_planes_on_the_affine_map():
    rng = np.random.default_rng(1)
    xy0 = rng.uniform(0, 500, (50, 2))
    xy1 = xy0 @ np.diag([1 / 1.25, 1.0]) + 20.0
    xy1[40:] = rng.uniform(0, 500, (10, 2))  # plane 7's matches: none on the map of planes 2 and 4
    plane_of_match = np.repeat([2, 4, 7], [20, 20, 10])
    measured = view_step.PlainTilt.of(_plain_state(xy0, xy1, plane_of_match), (500, 500))
    assert measured.tilt == pytest.approx(1.25, rel=1e-6) and measured.matches == 40 and measured.planes == 2
    assert measured.measured
    one_plane = view_step.PlainTilt.of(_plain_state(xy0[:20], xy1[:20], plane_of_match[:20]), (500, 500))
    assert one_plane.matches == 20 and one_plane.planes == 1 and not one_plane.measured
