"""Multiscale image blocks and tiles (paper Sec. 3.1, Fig. "ob"; tiles: Sec. 3.5).

A block is a ``block_size`` (256) px window of a rescaled image.  Its outer ``padding`` (32) px on each
side only gives the detector context: keypoints count for a block only inside its *core*, the block minus
the padding (192 px).  Along an axis, the cores start every ``stride`` (128) px, so neighbouring cores
overlap by 64 px (1/3 of the core) before the stride adjustment.  The image is zero-padded by 32 px, so the
first block's box starts at -32 and its core at 0.

Rule implemented (one axis of length ``n`` px in the scaled image, core ``k = block_size - 2 padding``):
    * ``R = n - k``; if ``R <= 0`` a single block covers the axis;
    * ``steps = ceil(R / (stride + stride_tolerance))`` (fewest blocks with a stride of at most 152 px);
    * ``t = max(R / steps, stride - stride_tolerance)`` (stride in ``128 +- 24``);
    * core ``j`` starts at ``round(j t)`` and ends at ``min(round(j t) + k, n)``; the box is the core grown by
      the padding, clipped to ``[-padding, n + padding)``.  When ``t = R / steps`` the last core ends exactly
      at the image border; when the stride had to be raised to 104 px the last block is cut at the border
      (smaller than 256 px) instead of leaving an uncovered strip.
Scale ``s`` (blocks along the shorter side) resizes the image so that its shorter side is
``k + stride (s - 1)`` = 192, 320, 448 px for s = 1, 2, 3 (the longer side is rounded to whole pixels);
then ``R = 128 (s - 1)`` and exactly ``s`` blocks fit along the shorter side with stride 128.  Tiles use the
same rule on the original image (factor 1).

Worked examples (``make_blocks``; rows x columns per scale):
    * 640x480 (W x H): s=1: 256x192 px -> 1x2; s=2: 427x320 -> 2x3 (column stride 117.5);
      s=3: 597x448 -> 3x4 (column stride 135): 20 blocks.  Tiles: 3x4 = 12.
    * 800x640: s=1: 240x192 -> 1x2 (stride raised to 104, last block cut); s=2: 400x320 -> 2x3 (stride 104);
      s=3: 560x448 -> 3x4 (stride 122.7): 20 blocks.  Tiles: 4x5 = 20.

Coordinates follow the package convention (pixel centres at integers).  A resize to ``(W_s, H_s)`` maps
``x_s = (x + 0.5) W_s / W - 0.5`` (same for y), which is what the Lanczos3 resampler
:func:`slime_match.features.image_ops.resize_lanczos` implements.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slime_match.errors import ConfigError
from slime_match.features.image_ops import scaled_size
from slime_match.geometry.frames import Frame
from slime_match.views import View

__all__ = [
    "Block",
    "BlockConfig",
    "make_blocks",
    "make_tiles",
    "make_view_blocks",
    "points_in_blocks",
]


BORDER_MARGIN = 2.0  # px: keypoints a block crop's detector finds this close to the image border are dropped
VIEW_BLOCK_INSIDE = 0.5  # a simulated view's block is kept when this much of its core shows the image


@dataclass
class BlockConfig:
    """Block/tile geometry (paper defaults, all in px of the scaled image).

    Attributes:
        block_size: side of a full block, padding included.
        padding: context border on each side where keypoints do not count.
        stride: nominal distance between consecutive block cores.
        stride_tolerance: the stride may be adjusted within ``stride +- stride_tolerance``.
        scales: number of blocks along the shorter image side, one entry per scale.
    """

    block_size: int = 256
    padding: int = 32
    stride: int = 128
    stride_tolerance: int = 24
    scales: tuple[int, ...] = (1, 2, 3)

    def __post_init__(self) -> None:
        self.scales = tuple(int(s) for s in self.scales)
        if self.padding < 0 or self.block_size - 2 * self.padding <= 0:
            raise ConfigError("BlockConfig: need 0 <= padding < block_size / 2")
        if not 0 <= self.stride_tolerance < self.stride:
            raise ConfigError("BlockConfig: need 0 <= stride_tolerance < stride")
        if not self.scales or min(self.scales) < 1:
            raise ConfigError("BlockConfig: scales must be positive block counts")
        if len(set(self.scales)) < len(self.scales):
            raise ConfigError(f"BlockConfig: scales must be distinct, got {self.scales}")

    @property
    def core_size(self) -> int:
        """Side of the core region (block minus padding), 192 px by default."""
        return self.block_size - 2 * self.padding


@dataclass
class Block:
    """One block (or tile) of a rescaled image.

    Attributes:
        scale_index: index into ``BlockConfig.scales`` (0 for tiles).
        row: grid row index i.
        col: grid column index j.
        factor: nominal scale factor (scaled / original); the exact per-axis ratios are ``fx``, ``fy``.
        scaled_size: (W_s, H_s) size of the whole scaled image in px.
        box: (x0, y0, x1, y1) half-open pixel-index window of the block in the scaled image, padding
            included (may reach ``-padding`` and ``W_s + padding``: that part is zero padding).
        core: (x0, y0, x1, y1) half-open pixel-index window where keypoints belong to the block.
        original_size: (W, H) size of the original image in px (of a view: the view image's size).
        view: None, or the simulated view (``views.View``) whose image the block's level resizes: the block's
            frames then start with the view's affine map, and its keypoints must lie inside the original
            image (the rest of a view is the warp's reflected border).
    """

    scale_index: int
    row: int
    col: int
    factor: float
    scaled_size: tuple[int, int]
    box: tuple[int, int, int, int]
    core: tuple[int, int, int, int]
    original_size: tuple[int, int]
    view: View | None = None

    @property
    def fx(self) -> float:
        """Exact horizontal scale W_s / W."""
        return self.scaled_size[0] / self.original_size[0]

    @property
    def fy(self) -> float:
        """Exact vertical scale H_s / H."""
        return self.scaled_size[1] / self.original_size[1]

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the block image in px."""
        return self.box[3] - self.box[1], self.box[2] - self.box[0]

    @property
    def level_frame(self) -> Frame:
        """The frame of the whole scaled image (the block's level)."""
        return Frame((self.fx, self.fy), view=self.view.affine if self.view else None)

    @property
    def frame(self) -> Frame:
        """The frame of the block image (:meth:`crop`): the level cut at the box corner."""
        return Frame((self.fx, self.fy), (float(self.box[0]), float(self.box[1])),
                     self.view.affine if self.view else None)

    def in_core_local(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: block-image points (N, 2) that fall in the core (see :func:`points_in_blocks`)."""
        lo, hi = _core_bounds(self)
        xy = np.asarray(xy, dtype=np.float64) + np.array(self.box[:2], dtype=np.float64)
        return np.all((xy >= lo) & (xy < hi), axis=1)

    def off_border_local(self, xy: np.ndarray, margin: float = BORDER_MARGIN) -> np.ndarray:
        """(N,) bool: block-image points (N, 2) at least ``margin`` px inside the scaled image's border, where a
        detector sees the crop's zero-filled padding (:meth:`crop`) as an edge; in a view, also ``margin``
        original px inside the original image."""
        local = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        xy = local + np.array(self.box[:2], dtype=np.float64)
        size = np.array(self.scaled_size, dtype=np.float64)
        inside = np.all((xy >= margin - 0.5) & (xy <= size - 0.5 - margin), axis=1)
        if self.view is not None:
            inside &= self.view.inside(self.frame.to_original(local), margin)
        return inside

    def crop(self, scaled_image: np.ndarray) -> np.ndarray:
        """Cut the block from the scaled image, zero-filling the part of the box outside the image.

        Args:
            scaled_image: (H_s, W_s) or (H_s, W_s, C) array, the image resized to ``scaled_size``.

        Returns:
            (h, w[, C]) block image with ``(h, w) = self.shape``.
        """
        h_s, w_s = scaled_image.shape[:2]
        if (w_s, h_s) != self.scaled_size:
            raise ValueError(
                f"image is {w_s}x{h_s}, block expects {self.scaled_size[0]}x{self.scaled_size[1]}"
            )
        x0, y0, x1, y1 = self.box
        out = np.zeros((y1 - y0, x1 - x0) + scaled_image.shape[2:], dtype=scaled_image.dtype)
        sx0, sy0, sx1, sy1 = max(x0, 0), max(y0, 0), min(x1, w_s), min(y1, h_s)
        out[sy0 - y0 : sy1 - y0, sx0 - x0 : sx1 - x0] = scaled_image[sy0:sy1, sx0:sx1]
        return out


def _axis_cores(length: int, config: BlockConfig) -> list[tuple[int, int]]:
    """Half-open core intervals along one axis of ``length`` px (rule in the module docstring)."""
    core = config.core_size
    rest = length - core
    if rest <= 0:
        return [(0, length)]
    steps = math.ceil(rest / (config.stride + config.stride_tolerance))
    step = max(rest / steps, config.stride - config.stride_tolerance)
    starts = [round(j * step) for j in range(steps + 1)]
    return [(a, min(a + core, length)) for a in starts]


def _grid(height: int, width: int, factor: float, scale_index: int, config: BlockConfig,
          view: View | None = None) -> list[Block]:
    w_s, h_s = scaled_size(height, width, factor)
    rows, cols = _axis_cores(h_s, config), _axis_cores(w_s, config)
    pad = config.padding
    blocks = []
    for i, (ry0, ry1) in enumerate(rows):
        for j, (cx0, cx1) in enumerate(cols):
            box = (cx0 - pad, ry0 - pad, min(cx1 + pad, w_s + pad), min(ry1 + pad, h_s + pad))
            blocks.append(
                Block(scale_index, i, j, factor, (w_s, h_s), box, (cx0, ry0, cx1, ry1), (width, height), view)
            )
    return blocks


def make_blocks(height: int, width: int, config: BlockConfig | None = None) -> list[Block]:
    """Multiscale blocks of an image (paper Sec. 3.1), scale by scale, row-major within a scale.

    Args:
        height: original image height in px.
        width: original image width in px.
        config: block geometry; paper defaults when None.

    Returns:
        The blocks; the linear index w of the paper is the list index.
    """
    config = config or BlockConfig()
    short = min(height, width)
    blocks: list[Block] = []
    for k, s in enumerate(config.scales):
        target = config.core_size + config.stride * (s - 1)
        blocks += _grid(height, width, target / short, k, config)
    return blocks


def make_view_blocks(height: int, width: int, view: View, config: BlockConfig | None = None,
                     min_inside: float = VIEW_BLOCK_INSIDE) -> list[Block]:
    """The blocks of a simulated view of an (``height``, ``width``) image: each block scale resizes the view
    image by the factor that scale gives the original image (:func:`make_blocks`), so that a view's levels
    keep the original's resolution along the direction the view does not compress. A rotated view's bounding
    box has corners outside the image: blocks with less than ``min_inside`` of their core inside it are left
    out."""
    config = config or BlockConfig()
    short = min(height, width)
    blocks: list[Block] = []
    for k, s in enumerate(config.scales):
        target = config.core_size + config.stride * (s - 1)
        blocks += [b for b in _grid(view.size[1], view.size[0], target / short, k, config, view)
                   if _core_inside(b) >= min_inside]
    return blocks


def _core_inside(block: Block, samples: int = 8) -> float:
    """The fraction of a view block's core that lies inside the original image (on a grid of samples^2)."""
    x0, y0, x1, y1 = block.core
    u = (np.arange(samples) + 0.5) / samples
    grid = np.stack(np.meshgrid(x0 - 0.5 + u * (x1 - x0), y0 - 0.5 + u * (y1 - y0)), -1).reshape(-1, 2)
    return float(block.view.inside(block.level_frame.to_original(grid), margin=0.0).mean())


def make_tiles(height: int, width: int, config: BlockConfig | None = None) -> list[Block]:
    """Tiles of the original image (paper Sec. 3.5): the block geometry at factor 1, row-major."""
    return _grid(height, width, 1.0, 0, config or BlockConfig())


def _core_bounds(block: Block) -> tuple[np.ndarray, np.ndarray]:
    """Core of a block as continuous scaled-image bounds ``lo <= xy < hi`` (each (2,)).

    Pixel index p covers ``[p - 0.5, p + 0.5)``; a core side on the image border is unbounded so that
    keypoints detected in the border pixels (or slightly outside) still belong to a block.
    """
    x0, y0, x1, y1 = block.core
    w_s, h_s = block.scaled_size
    lo = np.array([x0 - 0.5 if x0 > 0 else -np.inf, y0 - 0.5 if y0 > 0 else -np.inf])
    hi = np.array([x1 - 0.5 if x1 < w_s else np.inf, y1 - 0.5 if y1 < h_s else np.inf])
    return lo, hi


def points_in_blocks(xy: np.ndarray, blocks: list[Block]) -> sp.csr_matrix:
    """Membership of points in block cores.

    Args:
        xy: (N, 2) points in original-image px.
        blocks: blocks (or tiles) of that image, of the image itself or of simulated views of it (a point
            belongs to a view's block only where it lies inside the original image, ``View.inside``).

    Returns:
        (n_blocks, N) boolean CSR matrix, True where the point lies in the block's core.
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    rows, cols = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for view in dict.fromkeys(b.view for b in blocks):  # each view's blocks in its own frame
        group = np.array([k for k, b in enumerate(blocks) if b.view == view], np.int64)
        points, candidates = xy, np.arange(len(xy))
        if view is not None:
            candidates = np.flatnonzero(view.inside(xy))
            points = view.frame.from_original(xy[candidates])
        r, c = _inside_cores(points, [blocks[k] for k in group])
        rows.append(group[r])
        cols.append(candidates[c])
    r, c = np.concatenate(rows), np.concatenate(cols)
    return sp.csr_matrix((np.ones(len(r), dtype=bool), (r, c)), shape=(len(blocks), len(xy)))


def _inside_cores(xy: np.ndarray, blocks: list[Block]) -> tuple[np.ndarray, np.ndarray]:
    """(block, point) index pairs of the (N, 2) points (px of the blocks' unscaled image) in the blocks' cores."""
    bounds = [_core_bounds(b) for b in blocks]
    scale = np.array([[b.fx, b.fy] for b in blocks])
    lo = (np.stack([lo for lo, _ in bounds]) + 0.5) / scale - 0.5
    hi = (np.stack([hi for _, hi in bounds]) + 0.5) / scale - 0.5
    rows, cols = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    chunk = max(1, 4_000_000 // max(len(blocks), 1))
    for start in range(0, len(xy), chunk):
        p = xy[start : start + chunk]
        inside = np.all((p[None] >= lo[:, None]) & (p[None] < hi[:, None]), axis=2)
        r, c = np.nonzero(inside)
        rows.append(r)
        cols.append(c + start)
    return np.concatenate(rows), np.concatenate(cols)
