"""HarrisZ+ corner detector: colour-aware, multi-scale Harris with z-score response and uniform ranking.

Implements ALGORITHMS.md section 1 (Bellavia & Mishkin, PRL 2022); the module is over 400 lines because it
is that one paper algorithm, its strip-wise filtering and exact greedy selections included. The image work
(2x Lanczos upsampling, gradients, Gaussian filtering, response, peaks) runs on the input's device with the
filters of :mod:`slime_match.features.image_ops` (OpenCV's on the CPU, torch elsewhere). The few thousand
peaks then go to NumPy/SciPy for the greedy spatial selections: exact greedy results computed by a
vectorised dependency resolution over k-d tree neighbour pairs.

Choices the spec leaves open: a working pixel u of the 2x image maps to the original pixel u / 2 - 0.25 (the
exact inverse of the resize under the pixel-centre convention, rather than u / 2); Gaussian kernels have
radius ceil(3 sigma) and reflected borders; peaks whose 7x7 window leaves the image are not considered.

Memory: a working image larger than ``WHOLE_PIXELS`` is filtered in strips of rows, each with enough margin
that its rows are computed exactly as on the whole image (the filters are separable and row-independent);
only the structure tensor (3 floats a pixel) and two masks are kept whole, because the mask threshold and the
z-scores are statistics of the whole image, summed row by row. The keypoints do not depend on the strips.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial import cKDTree

from slime_match._runtime.options import config_from_dict
from slime_match.errors import ConfigError, ImageError
from slime_match.features.image_ops import (
    blurred_rows,
    central_gradient,
    gaussian_radius,
    lanczos_upsample2,
    max_filter,
    row_strips,
)
from slime_match.types import Keypoints

logger = logging.getLogger("slime_match")

_SQRT2 = math.sqrt(2.0)
_GREY_WEIGHTS = (0.299, 0.587, 0.114)
WHOLE_PIXELS = 8_000_000  # a working image up to this many pixels (a 2 MP photo's 2x levels) is filtered whole,
STRIP_PIXELS = 3_000_000  # a larger one in strips of at most this many
_PEAK_STEPS = ((0, 0), (0, -1), (0, 1), (-1, 0), (1, 0))  # (dy, dx): a peak and its 4 neighbours (parabola fits)


@dataclass
class HarrisZConfig:
    """HarrisZ+ parameters (defaults from ALGORITHMS.md section 1).

    Attributes:
        max_keypoints: N, the cap on the output and the density of the uniform spatial ranking.
        num_levels: scale levels k = 0..num_levels-1, integration sigma sqrt(2)^k, derivative sigma / sqrt(2).
        upsampled_levels: levels k below this run on the 2x Lanczos-upsampled image with doubled sigmas.
        peak_window: side (working pixels) of the window in which a peak must be the unique maximum.
        mask_threshold: minimum soft gradient-mask value at a peak.
        min_axis_ratio: keypoints with axis ratio sqrt(l_min / l_max) <= this are dropped.
        ellipse_factor: ellipse semi-axes are ellipse_factor * s_i and ellipse_factor * s_i * q.
        min_ellipse_sigma: lower clamp of the original-image sigma s_i used for the ellipse size.
        dedup_radius: keypoints of the upsampled levels closer than this (pixels) to a stronger one are dropped.
        color: use the colour "best" gradient field for the mask when the input is RGB.
    """

    max_keypoints: int = 8000
    num_levels: int = 5
    upsampled_levels: int = 2
    peak_window: int = 7
    mask_threshold: float = 0.31
    min_axis_ratio: float = 0.25
    ellipse_factor: float = 3.0
    min_ellipse_sigma: float = _SQRT2
    dedup_radius: float = 1.0
    color: bool = True

    def __post_init__(self) -> None:
        if self.max_keypoints < 1:
            raise ConfigError(f"max_keypoints must be >= 1, got {self.max_keypoints}")
        if self.num_levels < 1 or not 0 <= self.upsampled_levels <= self.num_levels:
            raise ConfigError("need num_levels >= 1 and 0 <= upsampled_levels <= num_levels")
        if self.peak_window < 3 or self.peak_window % 2 == 0:
            raise ConfigError(f"peak_window must be odd and >= 3, got {self.peak_window}")

    @classmethod
    def from_dict(cls, options: dict) -> HarrisZConfig:
        """Build a config from a dict of option names, raising ConfigError for unknown names."""
        return config_from_dict(cls, options)


def detect_harrisz(image: torch.Tensor, config: HarrisZConfig | None = None) -> Keypoints:
    """Detect HarrisZ+ keypoints with affine ellipses.

    Args:
        image: (3, H, W) RGB or (1, H, W) grey float image in [0, 1], on any device.
        config: detector parameters; defaults when None.

    Returns:
        Keypoints on the image's device, in uniform-spatial-ranking order: xy (N, 2) in original-image
        pixels (centre of the top-left pixel = (0, 0)), ellipse (N, 2, 2), response (N,) = z-score Harris
        response R, level (N,) in 0..num_levels-1. Empty (N = 0) for a blank image or an image smaller
        than the largest Gaussian kernel needs.
    """
    cfg = config or HarrisZConfig()
    if image.ndim != 3 or image.shape[0] not in (1, 3):
        raise ImageError(f"HarrisZ+ expects a (3, H, W) or (1, H, W) image tensor, got {tuple(image.shape)}")
    if not image.is_floating_point():
        raise ImageError(f"HarrisZ+ expects a float image in [0, 1], got dtype {image.dtype}")
    device = image.device
    img = image.detach().float()
    height, width = img.shape[-2:]
    largest_radius = gaussian_radius(_SQRT2 ** (cfg.num_levels - 1))
    if min(height, width) <= 2 * largest_radius:
        logger.debug("HarrisZ+: image %dx%d too small for the filters, no keypoints", width, height)
        return _empty_keypoints(device)

    fields = _WorkingFields(img, cfg.color)
    parts = [_detect_level(fields, k, 2 if k < cfg.upsampled_levels else 1, cfg) for k in range(cfg.num_levels)]
    xy, ellipse, response, level = (np.concatenate(a) for a in zip(*parts))

    upsampled = np.flatnonzero(level < cfg.upsampled_levels)
    if cfg.upsampled_levels > 1 and len(upsampled):
        order = upsampled[_priority_order(response[upsampled], level[upsampled])]
        kept = _greedy_keep(xy[order], cfg.dedup_radius)
        drop = np.ones(len(xy), bool)
        drop[order[kept]] = False
        drop[level >= cfg.upsampled_levels] = False
        xy, ellipse, response, level = xy[~drop], ellipse[~drop], response[~drop], level[~drop]

    order = _priority_order(response, level)
    radius = 2.0 * math.sqrt(2.0 * height * width / (math.pi * cfg.max_keypoints))
    ranked = order[_uniform_ranking(xy[order], radius, cfg.max_keypoints)]
    logger.debug("HarrisZ+: %d keypoints (pool %d) on %dx%d", len(ranked), len(order), width, height)
    return Keypoints(
        xy=torch.from_numpy(xy[ranked].astype(np.float32)).to(device),
        ellipse=torch.from_numpy(ellipse[ranked].astype(np.float32)).to(device),
        response=torch.from_numpy(response[ranked].astype(np.float32)).to(device),
        level=torch.from_numpy(level[ranked].astype(np.int64)).to(device),
    )


def _empty_keypoints(device: torch.device) -> Keypoints:
    return Keypoints(
        xy=torch.zeros(0, 2, device=device),
        ellipse=torch.zeros(0, 2, 2, device=device),
        response=torch.zeros(0, device=device),
        level=torch.zeros(0, dtype=torch.int64, device=device),
    )


def _gradient_fields(image: torch.Tensor, color: bool, mask: bool = True) -> tuple[torch.Tensor, ...]:
    """Grey gradient (for the Harris tensor) and mask gradient ("best" colour field, or grey) of an image.

    Args:
        image: (C, H, W) with C in {1, 3}.
        color: build the colour best field when C == 3.
        mask: also return the mask gradient.

    Returns:
        gx, gy, bx, by: (H, W) each; bx, by are gx, gy themselves when there is no colour field; only gx, gy
        when ``mask`` is False.
    """
    if image.shape[0] == 3:
        r, g, b = _GREY_WEIGHTS
        grey = image[0] * r + image[1] * g + image[2] * b
    else:
        grey = image[0]
    gx, gy = central_gradient(grey)
    del grey
    if not mask:
        return gx, gy
    if not (color and image.shape[0] == 3):
        return gx, gy, gx, gy
    mx, my = central_gradient(image.amax(0))
    bx = torch.where(mx.abs() > gx.abs(), mx, gx)
    del mx
    by = torch.where(my.abs() > gy.abs(), my, gy)
    return gx, gy, bx, by


class _WorkingFields:
    """Gradient fields of the working images (the image, or its 2x Lanczos upsampling) over ranges of rows.

    The fields of the last range asked for are kept, so that the levels and passes that ask for the same
    range (all of them when the image is one strip) compute it once.
    """

    def __init__(self, image: torch.Tensor, color: bool):
        self.image, self.color = image, color
        # ((factor, start, stop, with the mask gradient), the fields) of the last range
        self._kept: tuple[tuple[int, int, int, bool], tuple[torch.Tensor, ...]] | None = None

    def shape(self, factor: int) -> tuple[int, int]:
        """(h, w) of the working image at ``factor``."""
        return factor * self.image.shape[1], factor * self.image.shape[2]

    def rows(self, factor: int, start: int, stop: int, mask: bool = True) -> tuple[torch.Tensor, ...]:
        """gx, gy, bx, by (see :func:`_gradient_fields`; when ``mask`` is False, gx, gy and maybe bx, by) of
        working rows start..stop-1, (stop - start, w) each, equal to those rows of the whole image's fields."""
        key = (factor, start, stop, mask)
        if self._kept is None or self._kept[0] not in (key, (factor, start, stop, True)):
            self._kept = None  # freed before the next range is computed
            height = self.shape(factor)[0]
            lo, hi = max(0, start - 1), min(height, stop + 1)  # central differences need a row either side
            if factor == 1:
                source = self.image[:, lo:hi]
            else:  # 2x row u samples original row u / 2 - 0.25 with taps floor(.) - 3 .. floor(.) + 4
                first, last = max(0, lo // 2 - 5), min(self.image.shape[1], (hi + 1) // 2 + 5)
                source = lanczos_upsample2(self.image[:, first:last])[:, lo - 2 * first : hi - 2 * first]
            fields = _gradient_fields(source, self.color, mask)
            self._kept = key, tuple(f[start - lo : stop - lo] for f in fields)
        return self._kept[1]


def _total(x: torch.Tensor) -> float:
    """Sum of an (h, w) float image: each row's in float32, the rows' in float64, so that strips of whole
    rows add up to the whole image's sum."""
    return float(x.sum(1).double().sum())


def _detect_level(
    fields: _WorkingFields, k: int, factor: int, cfg: HarrisZConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Keypoints of one scale level, filtered strip by strip (see the module's docstring).

    Args:
        fields: gradients of the working images.
        k: level index; integration sigma sqrt(2)^k and derivative sigma sqrt(2)^(k-1) in original pixels.
        factor: working-image scale (2 on upsampled levels, else 1).
        cfg: detector parameters.

    Returns:
        xy (n, 2) original-image pixels, ellipse (n, 2, 2), response (n,), level (n,), as NumPy arrays.
    """
    s_i = _SQRT2**k
    s_d = s_i / _SQRT2
    height, width = fields.shape(factor)
    strips = row_strips(height, width, WHOLE_PIXELS, STRIP_PIXELS)
    a, b, c, strong = _structure_tensor(fields, factor, strips, s_d * factor, s_i * factor, cfg.mask_threshold)
    means, stds = _harris_statistics(a, b, c, strips)
    h = cfg.peak_window // 2
    peaks = []
    for start, stop in strips:  # the peaks of rows start..stop-1: their windows lie within lo..hi-1
        lo, hi = max(0, start - h), min(height, stop + h)
        det, trace2 = _harris_terms(a, b, c, lo, hi)
        response = _zscored(det, means[0], stds[0]).sub_(_zscored(trace2, means[1], stds[1]))
        ys, xs = _unique_peaks(response, strong[lo:hi], cfg.peak_window)
        samples = [response[ys + dy, xs + dx] for dy, dx in _PEAK_STEPS] + [t[ys + lo, xs] for t in (a, b, c)]
        peaks.append((torch.stack(samples, dim=1).double().cpu().numpy(),
                      torch.stack((xs, ys + lo), dim=1).cpu().numpy().astype(np.float64)))
    values, peaks_xy = (np.concatenate(p) for p in zip(*peaks))
    if len(values) == 0:
        return _empty_level()

    order = np.argsort(-values[:, 0], kind="stable")
    keep = order[_greedy_keep(peaks_xy[order], math.ceil(3.0 * s_d * factor))]
    values, peaks_xy = values[keep], peaks_xy[keep]

    r0, rl, rr, ru, rd = values[:, :5].T
    u = peaks_xy[:, 0] + 0.5 * (rl - rr) / (rl - 2.0 * r0 + rr)
    v = peaks_xy[:, 1] + 0.5 * (ru - rd) / (ru - 2.0 * r0 + rd)
    if factor == 2:
        u, v = (u + 0.5) / 2.0 - 0.5, (v + 0.5) / 2.0 - 0.5

    ellipse, q = _ellipse_from_tensor(
        values[:, 5], values[:, 6], values[:, 7], cfg.ellipse_factor * max(s_i, cfg.min_ellipse_sigma)
    )
    good = q > cfg.min_axis_ratio
    xy = np.stack((u, v), axis=1)[good]
    return xy, ellipse[good], r0[good], np.full(int(good.sum()), k, np.int64)


def _structure_tensor(
    fields: _WorkingFields, factor: int, strips: list[tuple[int, int]], sigma_d: float, sigma_i: float,
    mask_threshold: float
) -> tuple[torch.Tensor, ...]:
    """The gradient mask and the structure tensor of a working image, strip by strip.

    The mask is the sigma_d-blurred indicator of a smoothed mask-gradient magnitude above its mean; the
    structure tensor [[a, c], [c, b]] blurs (sigma_i) the products of the mask-weighted smoothed grey gradients.

    Returns:
        a, b, c: (h, w) float each; strong: (h, w) bool, mask > mask_threshold.
    """
    height, width = fields.shape(factor)
    device = fields.image.device
    r_d, r_i = gaussian_radius(sigma_d), gaussian_radius(sigma_i)

    def margin(start: int, stop: int, extra: int) -> tuple[int, int]:
        return max(0, start - extra), min(height, stop + extra)

    magnitude = torch.empty(height, width, device=device)
    total = 0.0
    for start, stop in strips:
        lo, hi = margin(start, stop, r_d)
        _, _, bx, by = fields.rows(factor, lo, hi)
        total += _total(torch.hypot(*blurred_rows([bx, by], sigma_d, start, stop, lo), out=magnitude[start:stop]))
    above = magnitude > _float32(total / (height * width), device)
    del magnitude
    a, b, c = (torch.empty(height, width, device=device) for _ in range(3))
    strong = torch.empty(height, width, dtype=torch.bool, device=device)
    for start, stop in strips:
        lo, hi = margin(start, stop, r_i)  # the rows whose gradients the integration blur reads
        first, last = margin(lo, hi, r_d)
        mask = blurred_rows([above[first:last].to(a.dtype)], sigma_d, lo, hi, first)[0]
        strong[start:stop] = mask[start - lo : stop - lo] > mask_threshold
        gx, gy, *_ = fields.rows(factor, first, last, mask=False)
        dx, dy = blurred_rows([gx, gy], sigma_d, lo, hi, first)
        dx.mul_(mask)
        dy.mul_(mask)
        del mask
        for out, (p, q) in zip((a, b, c), ((dx, dx), (dy, dy), (dx, dy))):
            out[start:stop] = blurred_rows([p * q], sigma_i, start, stop, lo)[0]
    return a, b, c, strong


def _harris_statistics(a: torch.Tensor, b: torch.Tensor, c: torch.Tensor, strips: list[tuple[int, int]]
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of det and trace^2 of the structure tensor over the whole image, (2,) each,
    from their sums and sums of squares (|mean| < std on images: no cancellation to fear)."""
    count = a.numel()
    sums, squares = np.zeros(2), np.zeros(2)
    for start, stop in strips:
        for i, term in enumerate(_harris_terms(a, b, c, start, stop)):
            sums[i] += _total(term)
            squares[i] += _total(term.square_())
    means = sums / count
    variances = np.maximum(squares - count * means**2, 0.0) / max(count - 1, 1)
    return means, np.sqrt(variances)


def _float32(value: float, device: torch.device) -> torch.Tensor:
    return torch.tensor(value, dtype=torch.float32, device=device)


def _harris_terms(a: torch.Tensor, b: torch.Tensor, c: torch.Tensor, start: int, stop: int
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """det = ab - c^2 and trace^2 = (a + b)^2 of the structure tensor's rows start..stop-1."""
    a, b, c = a[start:stop], b[start:stop], c[start:stop]
    return torch.addcmul(a * b, c, c, value=-1.0), (a + b).square_()


def _zscored(x: torch.Tensor, mean: float, std: float) -> torch.Tensor:
    """(x - mean) / std in x's memory (zeros when std = 0: a constant image)."""
    centred = x.sub_(_float32(mean, x.device))
    return centred.div_(_float32(std, x.device)) if std > 0 else centred.zero_()


def _empty_level() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    return np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0), np.zeros(0, np.int64)


def _unique_peaks(response: torch.Tensor, strong: torch.Tensor, window: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Pixels that are the unique maximum of their window, with response > 0 and ``strong`` (mask > threshold).

    Peaks whose window leaves the image are ignored. Returns row and column indices (int64, same device).
    """
    h = window // 2
    height, width = response.shape
    inner = (slice(h, height - h), slice(h, width - h))
    core = response[inner]
    candidate = core == max_filter(response, window)[inner]
    candidate &= core > 0
    candidate &= strong[inner]
    ys, xs = torch.nonzero(candidate, as_tuple=True)
    ys, xs = ys + h, xs + h
    offsets = torch.arange(-h, h + 1, device=response.device)
    patch = response[(ys[:, None] + offsets)[:, :, None], (xs[:, None] + offsets)[:, None, :]]
    unique = (patch == response[ys, xs][:, None, None]).flatten(1).sum(1) == 1
    return ys[unique], xs[unique]


def _ellipse_from_tensor(
    a: np.ndarray, b: np.ndarray, c: np.ndarray, semi_axis: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Ellipse matrices from second-moment matrices U = [[a, c], [c, b]].

    The semi-axis along the weak-gradient eigenvector is ``semi_axis``, along the strong one ``semi_axis * q``
    with q = sqrt(l_min / l_max).

    Returns:
        E (n, 2, 2) with region (x - c)^T E (x - c) <= 1, and q (n,) (0 where U vanishes).
    """
    half_trace = 0.5 * (a + b)
    root = np.sqrt((0.5 * (a - b)) ** 2 + c**2)
    l_max = half_trace + root
    l_min = np.maximum(half_trace - root, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(l_max > 0, np.sqrt(l_min / l_max), 0.0)
    theta = 0.5 * np.arctan2(2.0 * c, a - b)  # direction of the strong-gradient eigenvector
    strong = np.stack((np.cos(theta), np.sin(theta)), axis=1)
    weak = np.stack((-strong[:, 1], strong[:, 0]), axis=1)
    long_axis = np.broadcast_to(np.asarray(semi_axis, dtype=np.float64), a.shape)
    short_axis = np.maximum(long_axis * q, 1e-12)
    ellipse = (
        weak[:, :, None] * weak[:, None, :] / long_axis[:, None, None] ** 2
        + strong[:, :, None] * strong[:, None, :] / short_axis[:, None, None] ** 2
    )
    return ellipse, q


def _priority_order(response: np.ndarray, level: np.ndarray) -> np.ndarray:
    """Indices sorted by response descending, then level ascending."""
    return np.lexsort((level, -response))


def _neighbour_pairs(xy: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j), i < j, of points closer than ``radius`` (strictly)."""
    if len(xy) < 2 or radius <= 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pairs = cKDTree(xy).query_pairs(radius, output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i, j = pairs.min(1), pairs.max(1)
    close = np.sum((xy[i] - xy[j]) ** 2, axis=1) < radius**2
    return i[close].astype(np.int64), j[close].astype(np.int64)


def _greedy_mis(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Exact greedy maximal independent set in index order, resolved in parallel.

    Node j is kept iff no kept node i < j is its neighbour. Each pass removes the nodes with a kept stronger
    neighbour and keeps the nodes whose stronger neighbours are all removed (the first undecided node is
    always kept, so the loop terminates); edges to decided nodes are discarded as it goes.

    Args:
        n: number of nodes, in priority order (0 = strongest).
        i, j: (E,) edges with i < j.

    Returns:
        (n,) bool keep mask.
    """
    state = np.zeros(n, np.int8)  # 0 undecided, 1 kept, -1 removed
    while True:
        live = (state[j] == 0) & (state[i] >= 0)
        i, j = i[live], j[live]
        undecided = state == 0
        if not undecided.any():
            return state == 1
        beaten = np.zeros(n, bool)
        beaten[j[state[i] == 1]] = True
        state[undecided & beaten] = -1
        waiting = np.zeros(n, bool)
        waiting[j[state[i] == 0]] = True
        state[(state == 0) & ~waiting] = 1


def _greedy_keep(xy: np.ndarray, radius: float) -> np.ndarray:
    """Indices of the greedy subset of priority-sorted points pairwise >= radius apart (increasing)."""
    i, j = _neighbour_pairs(xy, radius)
    return np.flatnonzero(_greedy_mis(len(xy), i, j))


def _uniform_ranking(xy: np.ndarray, radius: float, limit: int) -> np.ndarray:
    """Uniform spatial ranking of priority-sorted points.

    Repeatedly takes the greedy subset (points >= radius apart) of the remaining pool and appends it, in
    priority order, until ``limit`` points are collected or the pool is empty.

    Returns:
        Indices into ``xy`` in ranking order, at most ``limit`` of them.
    """
    n = len(xy)
    i, j = _neighbour_pairs(xy, radius)
    remaining = np.arange(n)
    rounds = []
    collected = 0
    while len(remaining) and collected < limit:
        position = np.full(n, -1, np.int64)
        position[remaining] = np.arange(len(remaining))
        live = (position[i] >= 0) & (position[j] >= 0)
        i, j = i[live], j[live]
        kept = _greedy_mis(len(remaining), position[i], position[j])
        rounds.append(remaining[kept])
        collected += int(kept.sum())
        remaining = remaining[~kept]
    if not rounds:
        return np.zeros(0, np.int64)
    return np.concatenate(rounds)[:limit]
