"""The simulated views step of Slime (ours, between Secs. 3.3 and 3.4): more block planes from ASIFT views of
either image, added tilt after tilt, and a stated policy for when to stop and which image's views to keep.

The step takes the plane state of the plain run (block planes, expansion, selection, both images' blocks) and
returns the state to continue from, with a :class:`~slime_match.views.ViewRecord` of what it tried and why it
stopped. The policy, by ``ViewConfig.mode``:

- "off": no view; the plain state.
- "always": every tilt of every viewed image; the image whose branch gives F^theta (the planes the epipolar
  vote kept, Secs. 3.6-3.7) the most matches is kept.
- "auto": nothing when the plain F^theta holds ``min_support`` matches, unless their tilt (below) is over
  ``max_tilt``: the scene is then foreshortened beyond what the base matches alone, so its matches hold only the
  part of it seen least obliquely; nothing when every block of one image
  holds fewer keypoints than a block plane needs matches (a blank or featureless image: the other image's views
  are matched against its blocks, and its own views hold no texture it lacks); nothing either when F^theta holds
  fewer but their tilt (:class:`PlainTilt`: the stretch of their affine map, measured on ``TILT_MATCHES`` matches
  of ``TILT_PLANES`` planes at least) is under ``min_tilt`` (sqrt 2, the lower edge of the first views' range:
  ASIFT's tilt-2 views undo tilts from sqrt 2 to 2 sqrt 2): the base then matched the scene where it is not
  foreshortened, so what keeps its matches few is appearance or overlap, which views do not change. Without such a
  measure (no F^theta, too few matches on one affine map, or one plane's) views are tried. Else the first tilt of
  every viewed image, each image's views joining that image's own branch of the plain state; the branch whose
  F^theta holds the most matches leads. With ``gain`` = ``min_support`` times the base's ``slime_view_gain`` (1
  for the handcrafted bases; 0.35 for the learned ones, which match the same planes about three times more
  sparsely and reach fewer matches on a correct geometry), the leader is kept once the views' own planes hold
  ``gain`` of its F^theta matches and its F^theta holds ``min_support`` or ``gain`` more than the plain one
  (matches the views only moved onto the images' own planes, through the vote, are no sign that the views found
  the scene's geometry); until then the next tilt (``tilts``, then ``steep_tilts`` where the plain tilt is over
  ``max_tilt``) continues every branch whose views' own planes hold at least
  half the F^theta matches of the branch whose views' planes hold the most (for the same reason counted on the
  views' planes only; a lead within a factor of two is noise, not a sign of which image the scene's tilt
  compresses; every branch when no views' planes hold any), and the leader is chosen among the branches that ran
  the tilt. When no branch reaches it, the plain state is kept (views that found no stronger geometry would only
  compete with the images' own planes).

Why branches: a scene's tilt is undone by compressing one image or the other, so the two images' view planes
are never pooled (the wrong image's views would only add planes that compete with the right one's in the
vote), and the images are compared at the same tilt rather than the first to reach the support winning: the
views that compress the wrong image move further from the other image and gain less consistent geometry.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..views import ViewConfig, ViewRecord, ViewTry
from .block_planes import BlockPlanes
from .blocks import Block
from .expansion import Expansion
from .match_tilt import match_tilt
from .selection import PlaneSelection
from .tile_sets import TileSets
from .view_planes import ViewPlanes

__all__ = ["TILT_MATCHES", "TILT_PLANES", "PlainTilt", "PlaneState", "add_views", "geometry_support"]

TILT_MATCHES = 10  # F^theta matches on one affine map that measure a tilt: of up to 100 random matches, 8 at most fit one
TILT_PLANES = 2  # planes those matches come from: one plane's matches fit an affine map whatever they are


@dataclass
class PlaneState:
    """The block planes (image 0 -> image 1), their expansion and selection (Secs. 3.4-3.7), and the blocks of
    each image that the planes' block indices point into (the image's own, then its views')."""

    planes: BlockPlanes
    expansion: Expansion
    selection: PlaneSelection
    blocks0: list[Block]
    blocks1: list[Block]

    def with_views(self, found: ViewPlanes,
                   select: Callable[[BlockPlanes], tuple[Expansion, PlaneSelection]]) -> PlaneState:
        """This state's planes joined by the views' planes, selected again."""
        blocks0, blocks1 = list(self.blocks0), list(self.blocks1)
        viewed = (blocks0, blocks1)[found.image]
        offset = len(viewed)
        viewed += found.blocks
        planes = self.planes.joined(found.planes, *((offset, 0) if found.image == 0 else (0, offset)))
        return PlaneState(planes, *select(planes), blocks0, blocks1)


@dataclass(frozen=True)
class PlainTilt:
    """The tilt of the plain F^theta's matches: their affine map's larger over smaller singular value (nan
    when none fits), how many of the matches it holds and on how many planes of F^theta they lie."""

    tilt: float
    matches: int
    planes: int

    @classmethod
    def of(cls, state: PlaneState, size1: tuple[int, int]) -> PlainTilt:
        """The tilt of ``state``'s F^theta (:func:`~.match_tilt.match_tilt`), image 1 of (H, W) ``size1``."""
        ftheta, table = state.selection.ftheta, state.planes.table
        matches = np.flatnonzero(ftheta.union())
        fit = match_tilt(table.xy0[matches], table.xy1[matches], size1)
        on_map = np.zeros(ftheta.n_matches, bool)
        on_map[matches[fit.inliers]] = True
        planes = np.unique(ftheta.plane[ftheta.set_of_entry[on_map[ftheta.indices]]])
        return cls(fit.tilt, fit.support, len(planes))

    @property
    def measured(self) -> bool:
        """Whether the tilt is the scene's: ``TILT_MATCHES`` on the affine map, from ``TILT_PLANES`` planes."""
        return self.matches >= TILT_MATCHES and self.planes >= TILT_PLANES


def _support(selection: PlaneSelection) -> int:
    """The distinct matches of F^theta."""
    return int(selection.ftheta.union().sum())


def _sets_on_planes(ftheta: TileSets, start: int, stop: int | None = None) -> np.ndarray:
    """The indices of F^theta's tile sets on the planes ``start <= l < stop`` (no upper bound: None)."""
    return np.flatnonzero((ftheta.plane >= start) & (ftheta.plane < (np.inf if stop is None else stop)))


def _support_from(selection: PlaneSelection, first: int) -> int:
    """The distinct matches of F^theta on the planes ``l >= first`` (a branch's views' planes)."""
    return int(selection.ftheta.subset(_sets_on_planes(selection.ftheta, first)).union().sum())


def geometry_support(selection: PlaneSelection, min_support: int) -> tuple[bool, str]:
    """Whether F^theta holds ``min_support`` matches (enough geometry: no more views), and the count in words."""
    support = _support(selection)
    enough = support >= min_support
    return enough, (f"{'enough' if enough else 'too few'} matches consistent with the planes' epipolar geometry "
                    f"(F^theta): {support} {'>=' if enough else '<'} {min_support}")


def add_views(plain: PlaneState, views: ViewConfig, find: Callable[[int, float], ViewPlanes],
              select: Callable[[BlockPlanes], tuple[Expansion, PlaneSelection]],
              gain: float = 1.0, plain_tilt: PlainTilt | None = None, keypoints: tuple[int, int] | None = None,
              min_matches: int = 8) -> tuple[PlaneState, ViewRecord]:
    """The views step under the module's policy.

    Args:
        plain: the plain run's plane state.
        views: the mode, the tilts, the viewed images and the support ``auto`` asks for.
        find: the planes of the views of (image, tilt) (``view_planes``).
        select: Secs. 3.4-3.7 on block planes (expansion, then the selection of F^theta).
        gain: the fraction of ``views.min_support`` that a branch's views must add to the plain F^theta to be
            kept under ``views.min_support`` (the base pipeline's ``slime_view_gain``).
        plain_tilt: the tilt of the plain F^theta's matches; None: not measured (views as without a tilt).
        keypoints: the most keypoints one block of each image holds (in its core); None: not counted.
        min_matches: the matches a block plane needs (``SlimeConfig.min_plane_matches``).

    Returns:
        The state to continue from (the plain one, or one image's branch) and what was tried, decided and why.
    """
    record = ViewRecord(views.mode, views.images)
    if views.mode == "off":
        return plain, record
    enough, record.reason = geometry_support(plain.selection, views.min_support)
    plain_support = _support(plain.selection)
    min_gain = math.ceil(gain * views.min_support)
    if plain_tilt is not None and np.isfinite(plain_tilt.tilt):
        record.plain_tilt = {"tilt": round(plain_tilt.tilt, 3), "matches": plain_tilt.matches,
                             "planes": plain_tilt.planes, "measured": plain_tilt.measured}
    steep = plain_tilt is not None and plain_tilt.measured and plain_tilt.tilt > views.max_tilt
    if views.mode == "auto" and enough and not steep:
        record.decision = "not needed"
        return plain, record
    if views.mode == "auto" and keypoints is not None and min(keypoints) < min_matches:
        image = int(np.argmin(keypoints))
        record.decision = "not needed"
        record.reason += (f"; the blocks of image {image} hold at most {keypoints[image]} keypoints, fewer than the "
                          f"{min_matches} matches a block plane needs: the other image's views are matched against "
                          "them, and its own views hold no texture it lacks")
        return plain, record
    if views.mode == "auto" and plain_tilt is not None and plain_tilt.measured and plain_tilt.tilt < views.min_tilt:
        record.decision = "not needed"
        record.reason += (f"; {plain_tilt.matches} of them, on {plain_tilt.planes} planes, lie on one affine map of "
                          f"tilt {plain_tilt.tilt:.2f} < {views.min_tilt:.2f} (views.min_tilt): the scene is not "
                          "foreshortened where the images match, and views undo foreshortening")
        return plain, record
    branches: dict[int, PlaneState] = {}
    supports: dict[int, int] = {}  # per image: the distinct matches of its branch's F^theta
    on_views: dict[int, int] = {}  # per image: those on its views' planes
    ranges: dict[int, list[tuple[int, int]]] = {}  # per image: the plane ranges of its steps in its branch
    leader, contenders = None, views.viewed
    steeper = views.steep_tilts if steep and views.mode == "auto" else ()
    schedule = views.tilts + tuple(t for t in steeper if t not in views.tilts)
    for tilt in schedule:
        for image in contenders:
            state = branches.get(image, plain)
            found = find(image, tilt)
            ranges.setdefault(image, []).append((len(state.planes.H), len(state.planes.H) + len(found.planes.H)))
            branches[image] = state = state.with_views(found, select)
            supports[image] = _support(state.selection)
            on_views[image] = _support_from(state.selection, len(plain.planes.H))
            record.tried.append(ViewTry(image, tilt, found.views, planes=len(found.planes.H),
                                        support=supports[image], on_views=on_views[image], probes=found.probes,
                                        screens=found.screens, paired=found.paired))
        leader = max(contenders, key=lambda i: (supports[i], -i))
        enough, reason = geometry_support(branches[leader].selection, views.min_support)
        added = max(0, supports[leader] - plain_support)  # the leader's gain over the plain F^theta
        if views.mode == "auto" and on_views[leader] >= min_gain and (enough or added >= min_gain):
            if not enough:
                reason = (f"they added {added} >= {min_gain} matches to the images' own F^theta "
                          f"({plain_support}; {reason})")
            record.decision = "kept"
            record.reason = f"image {leader}'s views: {on_views[leader]} matches on their own planes; {reason}"
            break
        if views.mode == "auto":
            most = max(on_views[image] for image in contenders)
            contenders = tuple(image for image in contenders if 2 * on_views[image] >= most)
    else:
        if views.mode == "always" and leader is not None:
            record.decision, record.reason = "kept", f"every view tried; image {leader}'s views hold the most: {reason}"
        else:
            best = (f"at best {supports[leader]} matches, {on_views[leader]} on the views' own planes and "
                    f"{added} more than the images' own planes' (asked: {min_gain} on the views' planes, "
                    f"and {views.min_support} in all or {min_gain} more)" if leader is not None else "no view")
            leader, record.decision = None, "dropped"
            record.reason = f"every view tried, and F^theta holds {best}: the planes of the images alone are kept"
    if steep and views.mode == "auto":
        record.reason += (f"; the plain matches' affine map reads a tilt of {plain_tilt.tilt:.2f} > "
                          f"{views.max_tilt:.2f} (views.max_tilt): views tried whatever F^theta held"
                          + (f", tilts {', '.join(f'{t:g}' for t in steeper)} after the others" if steeper else ""))
    final = plain if leader is None else branches[leader]
    steps = iter(ranges.get(leader, []))
    for step in record.tried:
        if step.image == leader:
            step.ftheta_matches, step.ftheta_by_angle = _in_ftheta(final, leader, *next(steps))
        else:
            step.ftheta_matches = 0
    return final, record


def _in_ftheta(state: PlaneState, image: int, start: int, stop: int) -> tuple[int, dict[str, int]]:
    """The distinct F^theta matches on the planes ``start <= l < stop`` (one step's views of ``image``; none
    when those planes were dropped), in all and per view angle (degrees) that holds some."""
    ftheta: TileSets = state.selection.ftheta
    ours = _sets_on_planes(ftheta, start, stop)
    blocks, of_plane = (state.blocks0, state.blocks1)[image], state.planes.level_matches.pairs[:, image]
    angles = np.array([blocks[of_plane[plane]].view.angle for plane in ftheta.plane[ours]])
    by_angle = {f"{angle:g}": int(ftheta.subset(ours[angles == angle]).union().sum()) for angle in np.unique(angles)}
    return int(ftheta.subset(ours).union().sum()), by_angle
