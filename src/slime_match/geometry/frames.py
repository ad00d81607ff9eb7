"""Pixel frames: the views of an original image that matching works in, and the maps between them.

Every frame is the original image resized by ``factor`` per axis and cut at ``origin``, with pixel centres at
integers and the image edges kept: an original point x is ``(x + 0.5) * factor - 0.5 - origin`` in the
frame. The frames in use:

* the working image: the original resized to its working size (``resize.resize_image``: ``min_side``,
  ``max_side``);
* a level: Slime's image resized for one block scale (``Block.level_frame``);
* a block or tile: its crop of the level, ``origin`` its box corner (``Block.frame``);
* a level or block of a simulated view (``views.View``): the same, of the view image, whose affine map from
  the original comes first (``view``).

Everything after Slime's block stage works in the (working) original frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Frame", "homographies_to_original", "stack_matrices"]


@dataclass(frozen=True)
class Frame:
    """A resized and cropped view of the original image.

    Attributes:
        factor: (fx, fy) frame px per original px (the frame's size over the original's, per axis); of a view,
            frame px per view px.
        origin: (x, y) position of the frame's pixel (0, 0) in the resized image (its crop corner).
        view: None, or the (6,) row-major 2x3 affine map original px -> view px of a simulated view
            (``views.View.affine``), applied before the resize.
    """

    factor: tuple[float, float] = (1.0, 1.0)
    origin: tuple[float, float] = (0.0, 0.0)
    view: tuple[float, ...] | None = None

    @classmethod
    def of_sizes(cls, size: tuple[int, int], original: tuple[int, int]) -> Frame:
        """The whole original image (W, H) resized to ``size`` (w, h)."""
        return cls((size[0] / original[0], size[1] / original[1]))

    def to_original(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) frame px -> (N, 2) original px."""
        xy = (np.asarray(xy, np.float64) + np.array(self.origin) + 0.5) / np.array(self.factor) - 0.5
        if self.view is None:
            return xy
        inverse = np.linalg.inv(_affine3(self.view))
        return xy @ inverse[:2, :2].T + inverse[:2, 2]

    def from_original(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) original px -> (N, 2) frame px."""
        xy = np.asarray(xy, np.float64)
        if self.view is not None:
            a = _affine3(self.view)
            xy = xy @ a[:2, :2].T + a[:2, 2]
        return (xy + 0.5) * np.array(self.factor) - 0.5 - np.array(self.origin)

    def matrix(self) -> np.ndarray:
        """(3, 3) homogeneous form of ``from_original``."""
        (fx, fy), (ox, oy) = self.factor, self.origin
        scale = np.array([[fx, 0.0, 0.5 * fx - 0.5 - ox], [0.0, fy, 0.5 * fy - 0.5 - oy], [0.0, 0.0, 1.0]])
        return scale if self.view is None else scale @ _affine3(self.view)


def _affine3(affine: tuple[float, ...]) -> np.ndarray:
    """(3, 3) homogeneous form of a (6,) row-major 2x3 affine map."""
    return np.vstack([np.reshape(np.asarray(affine, np.float64), (2, 3)), [0.0, 0.0, 1.0]])


def stack_matrices(frames: list[Frame]) -> np.ndarray:
    """(n, 3, 3) ``matrix()`` of each frame."""
    return np.stack([frame.matrix() for frame in frames]) if frames else np.zeros((0, 3, 3))


def homographies_to_original(h: np.ndarray, frames0: list[Frame] | Frame, frames1: list[Frame] | Frame
                             ) -> np.ndarray:
    """(..., 3, 3) homographies from frame(s) of image 0 to frame(s) of image 1, as homographies between the
    original images (one frame each, or one per homography)."""
    m0 = frames0.matrix() if isinstance(frames0, Frame) else stack_matrices(frames0)
    m1 = frames1.matrix() if isinstance(frames1, Frame) else stack_matrices(frames1)
    return np.linalg.inv(m1) @ np.asarray(h, np.float64) @ m0

