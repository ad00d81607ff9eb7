"""The simulated views step of Slime (ours, between Secs. 3.3 and 3.4): more block planes from ASIFT views of
either image, added one (image, tilt) at a time, and a stated policy for when to stop and what to keep.

The step takes the plane state of the plain run (block planes, expansion, selection, both images' blocks) and
returns the state to continue from, with a :class:`~slime_match.views.ViewRecord` of what it tried and why it
stopped. The policy, by ``ViewConfig.mode``:

- "off": no view; the plain state.
- "always": every (image, tilt) of ``ViewConfig.schedule``; the state with all their planes.
- "auto": before each (image, tilt), stop when F^theta (the planes the epipolar vote kept, Secs. 3.6-3.7)
  holds ``min_support`` matches; after the last one, keep the views' planes only if F^theta has reached it,
  else go back to the plain state (views that found no stronger geometry would only compete with the images'
  own planes).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..views import ViewConfig, ViewRecord, ViewTry
from .block_planes import BlockPlanes
from .blocks import Block
from .expansion import Expansion
from .selection import PlaneSelection
from .tile_sets import TileSets
from .view_planes import ViewPlanes

__all__ = ["PlaneState", "add_views", "geometry_support"]


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


def geometry_support(selection: PlaneSelection, min_support: int) -> tuple[bool, str]:
    """Whether F^theta holds ``min_support`` matches (enough geometry: no more views), and the count in words."""
    support = int(selection.ftheta.union().sum())
    enough = support >= min_support
    return enough, (f"{'enough' if enough else 'too few'} matches consistent with the planes' epipolar geometry "
                    f"(F^theta): {support} {'>=' if enough else '<'} {min_support}")


def add_views(plain: PlaneState, views: ViewConfig, find: Callable[[int, float], ViewPlanes],
              select: Callable[[BlockPlanes], tuple[Expansion, PlaneSelection]]) -> tuple[PlaneState, ViewRecord]:
    """The views step under the module's policy.

    Args:
        plain: the plain run's plane state.
        views: the mode, the tilts and images (``ViewConfig.schedule``) and the support ``auto`` asks for.
        find: the planes of the views of (image, tilt) (``view_planes``).
        select: Secs. 3.4-3.7 on block planes (expansion, then the selection of F^theta).

    Returns:
        The state to continue from and what was tried, decided and why.
    """
    record = ViewRecord(views.mode, views.images)
    if views.mode == "off":
        return plain, record
    state, ranges = plain, []
    for image, tilt in views.schedule():
        if views.mode == "auto":
            enough, record.reason = geometry_support(state.selection, views.min_support)
            if enough:
                record.decision = "kept" if record.tried else "not needed"
                break
        found = find(image, tilt)
        ranges.append((len(state.planes.H), len(state.planes.H) + len(found.planes.H)))
        state = state.with_views(found, select)
        record.tried.append(ViewTry(image, tilt, found.views, planes=len(found.planes.H)))
    else:
        enough, reason = geometry_support(state.selection, views.min_support)
        record.decision = "kept"
        if views.mode == "always":
            record.reason = "every view tried"
        elif enough:
            record.reason = reason
        else:
            state, record.decision = plain, "dropped"
            record.reason = f"every view tried, and still {reason}: the planes of the images alone are kept"
    for step, (start, stop) in zip(record.tried, ranges):
        step.ftheta_matches, step.ftheta_by_angle = _in_ftheta(state, step.image, start, stop)
    return state, record


def _in_ftheta(state: PlaneState, image: int, start: int, stop: int) -> tuple[int, dict[str, int]]:
    """The distinct F^theta matches on the planes ``start <= l < stop`` (one step's views of ``image``; none
    when those planes were dropped), in all and per view angle (degrees) that holds some."""
    ftheta: TileSets = state.selection.ftheta
    ours = np.flatnonzero((ftheta.plane >= start) & (ftheta.plane < stop))
    blocks, of_plane = (state.blocks0, state.blocks1)[image], state.planes.level_matches.pairs[:, image]
    angles = np.array([blocks[of_plane[plane]].view.angle for plane in ftheta.plane[ours]])
    by_angle = {f"{angle:g}": int(ftheta.subset(ours[angles == angle]).union().sum()) for angle in np.unique(angles)}
    return int(ftheta.subset(ours).union().sum()), by_angle
