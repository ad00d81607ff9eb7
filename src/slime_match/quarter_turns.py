"""Quarter turns for bases whose features are upright by design: how far image 1 is turned against image 0.

ALIKED (n16, n32), DISK and XFeat describe every keypoint upright, so between images turned by 90, 180 or 270
degrees their matcher finds next to nothing, and Slime's orientation re-run (Sec. 3.3 of the paper) has no first
matches to read orientations from. Before Slime runs on such a base, the base matches small copies of the two
images (longer side :data:`CHECK_SIDE` px, the :data:`CHECK_KEYPOINTS` strongest keypoints) with image 1 under
each quarter turn, and counts the matches one fundamental matrix explains (OpenCV MAGSAC++,
:data:`CHECK_THRESHOLD` px). A turn replaces the upright reading only when it is the clear winner
(:func:`chosen_turn`): the most consistent matches, at least :data:`MIN_TURN_INLIERS` of them, and a lead over
the upright reading of as many as the upright has (twice its count) or :data:`MIN_TURN_INLIERS`, whichever is
less. Wrong turns of upright pairs reach a few to about 35 consistent matches at this size (a fundamental matrix
explains some of any few dozen matches), the right turn of a planar pair hundreds; the floor keeps a hard
upright pair whose every reading is weak upright. An upright reading above the floor is no noise but the base
partly following the turn (ALIKED on graf 1->4 with image 1 turned by 90 degrees clockwise: 127 upright, 180
under the right turn), so there a lead of :data:`MIN_TURN_INLIERS`, more than a wrong reading reaches, suffices.
Slime then matches image 1 turned, and the matches come back in its own pixels (``Frame.view`` holds the turn).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from .geometry.frames import Frame
from .resize import resize_image
from .types import Features

CHECK_SIDE = 384  # px, longer side of the images the check matches
CHECK_KEYPOINTS = 512  # strongest keypoints per image in the check
CHECK_THRESHOLD = 2.0  # px at CHECK_SIDE, MAGSAC++'s inlier threshold
MIN_TURN_INLIERS = 40  # consistent matches a turn needs, and the most lead over the upright's it needs


@dataclass(frozen=True)
class QuarterTurn:
    """The quarter-turn check of one pair.

    Attributes:
        quarter_turns: how many quarter turns counterclockwise (``np.rot90``'s ``k``) image 1 is matched under:
            0 (upright) to 3.
        inliers: (4,) consistent matches of the check under 0, 1, 2 and 3 quarter turns.
        reason: the decision in words.
    """

    quarter_turns: int
    inliers: tuple[int, int, int, int]
    reason: str

    def as_dict(self) -> dict:
        return {"degrees": 90 * self.quarter_turns, **asdict(self)}


def check_quarter_turns(pipeline, image0: np.ndarray, image1: np.ndarray, seed: int = 0) -> QuarterTurn:
    """The quarter turn of (H, W, 3) ``image1`` under which ``pipeline`` matches it best with ``image0``."""
    small0, small1 = _small(image0), _small(image1)
    features0 = _strongest(pipeline.extract(small0))
    inliers = []
    for k in range(4):
        turned = np.ascontiguousarray(np.rot90(small1, k))
        features1 = _strongest(pipeline.extract(turned))
        matches = pipeline.match(features0, features1, small0.shape[:2], turned.shape[:2])
        xy0 = features0.xy.detach().cpu().numpy().astype(np.float64)[matches.idx0]
        xy1 = features1.xy.detach().cpu().numpy().astype(np.float64)[matches.idx1]
        inliers.append(_consistent(xy0, xy1, seed))
    turn = chosen_turn(inliers)
    counts = ", ".join(f"{90 * k} deg {n}" for k, n in enumerate(inliers))
    if turn:
        reason = (f"image 1 turned by {90 * turn} degrees: its matches agree most there ({counts} consistent "
                  "matches of a small copy)")
    else:
        reason = f"upright: no turn is a clear winner ({counts} consistent matches of a small copy)"
    return QuarterTurn(turn, tuple(inliers), reason)  # type: ignore[arg-type]


def chosen_turn(inliers: Sequence[int]) -> int:
    """The quarter turn (0-3) that the check's readings choose: ``inliers`` (4,) consistent matches under 0, 1,
    2 and 3 quarter turns. The turn with the most, when it holds at least :data:`MIN_TURN_INLIERS` and leads the
    upright reading by ``min(upright, MIN_TURN_INLIERS)``; else 0 (upright)."""
    best = int(np.argmax(inliers))
    upright = inliers[0]
    lead = inliers[best] - upright
    return best if best != 0 and inliers[best] >= MIN_TURN_INLIERS and lead >= min(upright, MIN_TURN_INLIERS) else 0


def turned_frame(frame: Frame, original_size: tuple[int, int], quarter_turns: int) -> Frame:
    """The frame of a working image (``frame``: a resize of the (W, H) original, no crop, no view) turned by
    ``quarter_turns`` quarter turns counterclockwise, as ``np.rot90`` turns it."""
    if quarter_turns % 4 == 0:
        return frame
    width, height = original_size
    turn = {1: (0.0, 1.0, 0.0, -1.0, 0.0, width - 1.0),
            2: (-1.0, 0.0, width - 1.0, 0.0, -1.0, height - 1.0),
            3: (0.0, -1.0, height - 1.0, 1.0, 0.0, 0.0)}[quarter_turns % 4]
    fx, fy = frame.factor
    return Frame((fy, fx) if quarter_turns % 2 else (fx, fy), view=turn)


def _small(image: np.ndarray) -> np.ndarray:
    """The image shrunk so that its longer side is at most :data:`CHECK_SIDE` px."""
    factor = CHECK_SIDE / max(image.shape[:2])
    return image if factor >= 1.0 else resize_image(image, factor=factor)[0]


def _strongest(features: Features) -> Features:
    if len(features) <= CHECK_KEYPOINTS:
        return features
    return features.subset(features.strongest(CHECK_KEYPOINTS))


def _consistent(xy0: np.ndarray, xy1: np.ndarray, seed: int) -> int:
    """Matches one fundamental matrix explains (OpenCV MAGSAC++), 0 for fewer than 8 matches."""
    if len(xy0) < 8:
        return 0
    cv2.setRNGSeed(seed)
    _, mask = cv2.findFundamentalMat(xy0, xy1, cv2.USAC_MAGSAC, CHECK_THRESHOLD, 0.999, 10000)
    return 0 if mask is None else int(mask.sum())
