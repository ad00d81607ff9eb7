"""The frame in which the global DTM compares the two images' neighbourhoods (ours, Sec. 3.8).

DTM compares Delaunay neighbourhoods, which a similarity keeps but a strong affine stretch does not: under
the tilt of an extreme viewpoint (one image foreshortened several times more in one direction than in the
other) the triangulations of the correct matches disagree between the images and DTM keeps a small wrong
cluster instead. When the matches' robust global affine map stretches one direction more than ``max_tilt``
times the other, image 0's points are mapped by it into image 1's frame before DTM, so both triangulations
are built on similarly shaped point sets; below that, the images' own frames are kept (the paper's DTM).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..matching.delaunay import MAX_SIDE
from .match_tilt import match_tilt

__all__ = ["DTM_MAX_TILT", "DTMFrame", "dtm_frame"]

DTM_MAX_TILT = 2.0  # above this tilt of the matches' affine map, image 0 is compared in image 1's frame
DEGENERATE_TILT = 64.0  # a fit stretched beyond this, or on matches this elongated in image 0, is degenerate


@dataclass
class DTMFrame:
    """Where DTM compares the matches: image 0's points through ``affine`` in a frame of ``size``.

    Attributes:
        affine: (2, 3) map of image 0's px into the compared frame; None: image 0's own frame.
        size: (H, W) of that frame in px.
        tilt: the matches' affine map's larger over smaller singular value (nan without a fit).
        reason: the choice and why, in words.
    """

    affine: np.ndarray | None
    size: tuple[int, int]
    tilt: float
    reason: str

    def map(self, xy0: np.ndarray) -> np.ndarray:
        """(K, 2) image-0 px in the compared frame."""
        return xy0 if self.affine is None else xy0 @ self.affine[:, :2].T + self.affine[:, 2]


def dtm_frame(xy0: np.ndarray, xy1: np.ndarray, size0: tuple[int, int], size1: tuple[int, int],
              max_tilt: float = DTM_MAX_TILT) -> DTMFrame:
    """The frame for DTM on the (K, 2), (K, 2) matches of images of (H, W) ``size0`` and ``size1``, from the
    matches' robust global affine map (:func:`~.match_tilt.match_tilt`): it only has to undo the stretch."""
    own = tuple(int(s) for s in size0)
    if not np.isfinite(max_tilt) or len(xy0) < 3:
        return DTMFrame(None, own, float("nan"), "image 0's own frame")
    xy0 = np.asarray(xy0, np.float64)
    fit = match_tilt(xy0, xy1, size1)
    affine, tilt = fit.affine, fit.tilt
    if affine is None:
        return DTMFrame(None, own, float("nan"), "image 0's own frame: no affine map fits the matches")
    if tilt <= max_tilt:
        return DTMFrame(None, own, tilt, f"image 0's own frame: {_stretch(tilt)}, not more than {max_tilt:g} "
                                         "(dtm_max_tilt)")
    support = xy0[fit.inliers]
    spread = np.linalg.svd(support - support.mean(0), compute_uv=False)
    if tilt > DEGENERATE_TILT or spread[1] * DEGENERATE_TILT < spread[0]:  # nearly on a line: any stretch fits
        return DTMFrame(None, own, tilt, "image 0's own frame: the matches lie nearly on a line, so the stretch of "
                                         f"their affine map means nothing ({_stretch(tilt)})")
    height, width = own
    corners = np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], np.float64)
    corners = corners @ affine[:, :2].T + affine[:, 2]
    low = corners.min(0)
    extent = np.ceil(corners.max(0) - low).astype(int) + 1
    if extent.max() + 1 > MAX_SIDE:
        return DTMFrame(None, own, tilt, f"image 0's own frame: image 1's frame would span {extent.max()} px")
    shifted = affine.copy()
    shifted[:, 2] -= low
    return DTMFrame(shifted, (int(extent[1]), int(extent[0])), tilt,
                    f"image 1's frame: {_stretch(tilt)}, more than {max_tilt:g} (dtm_max_tilt)")


def _stretch(tilt: float) -> str:
    """The tilt of the matches' affine map in words."""
    return f"the matches' affine map stretches one direction {tilt:.1f} times more than the other (its tilt)"
