"""Generic image operations: resamplers, Gaussian and max filters, central gradients, row strips.

Three resamplers, kept apart because they compute different things (merging any two would change the images
and so the matches):
    * :func:`lanczos_upsample2`: exact 2x upsampling with the Lanczos-4 kernel (a = 4) and replicated borders,
      OpenCV's ``INTER_LANCZOS4`` on CPU tensors and the same filter in torch elsewhere; for HarrisZ+'s
      upsampled levels.
    * :func:`resize_lanczos`: any factor, Lanczos-3 (a = 3, MATLAB's ``imresize(..., 'lanczos3')``),
      antialiased when shrinking, mirrored borders, in NumPy/SciPy; for Slime's multiscale block images.
    * :func:`resize_area`: OpenCV area interpolation when shrinking, bilinear otherwise; for the working-size
      images (:mod:`slime_match.resize`).

The torch filters (Lanczos 2x, separable Gaussian, max) run on the tensor's device: on the CPU they call the
equivalent OpenCV functions, ~10x faster there (see :func:`use_opencv`); both paths agree to float32
rounding (the max filter exactly).
Coordinates follow the package convention: pixel centres at integers, the top-left pixel's at (0, 0).
"""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np
import scipy.sparse as sp
import torch
import torch.nn.functional as F


def use_opencv(x: torch.Tensor) -> bool:
    """Whether the image filters of tensor ``x`` run in OpenCV (CPU tensors) rather than in torch."""
    return x.device.type == "cpu"


def _lanczos_weights(frac: float) -> torch.Tensor:
    """(8,) normalised Lanczos-4 weights of the taps at floor(x) - 3 .. floor(x) + 4, frac = x - floor(x)."""
    d = np.arange(8) - 3 - frac
    w = np.sinc(d) * np.sinc(d / 4.0)
    return torch.from_numpy(w / w.sum()).float()


def lanczos_upsample2(image: torch.Tensor) -> torch.Tensor:
    """2x Lanczos-4 upsampling: OpenCV's ``INTER_LANCZOS4`` on CPU, an equivalent torch kernel elsewhere.

    Output pixel u samples the input at u / 2 - 0.25 (pixel-centre convention), so each axis is a two-phase
    8-tap filter (phase fractions 0.75 and 0.25) with replicated borders, exactly as OpenCV does.

    Args:
        image: (C, H, W) float.

    Returns:
        (C, 2H, 2W) float.
    """
    if use_opencv(image):
        src = image.detach().contiguous().numpy()
        out = np.empty((src.shape[0], 2 * src.shape[1], 2 * src.shape[2]), src.dtype)
        for channel, target in zip(src, out):  # into place: no second copy of the 2x image
            cv2.resize(channel, target.shape[::-1], dst=target, interpolation=cv2.INTER_LANCZOS4)
        return torch.from_numpy(out)
    return lanczos_upsample2_torch(image)


def lanczos_upsample2_torch(image: torch.Tensor) -> torch.Tensor:
    """Torch version of :func:`lanczos_upsample2` (the path of non-CPU tensors), (C, H, W) -> (C, 2H, 2W)."""
    w_even, w_odd = _lanczos_weights(0.75).tolist(), _lanczos_weights(0.25).tolist()

    def along_last(x: torch.Tensor) -> torch.Tensor:
        n = x.shape[-1]
        p = F.pad(x, (4, 4), mode="replicate")
        even = sum(w * p[..., t : t + n] for t, w in enumerate(w_even))
        odd = sum(w * p[..., t + 1 : t + 1 + n] for t, w in enumerate(w_odd))
        return torch.stack((even, odd), dim=-1).flatten(-2)

    rows = along_last(image)
    return along_last(rows.transpose(-1, -2)).transpose(-1, -2).contiguous()


def central_gradient(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Central differences of an (H, W) image with replicated borders; returns d/dx and d/dy, each (H, W),
    in intensity per pixel (one-sided half differences on the border rows and columns)."""
    gx, gy = torch.empty_like(x), torch.empty_like(x)
    torch.sub(x[:, 2:], x[:, :-2], out=gx[:, 1:-1])
    torch.sub(x[:, 1], x[:, 0], out=gx[:, 0])
    torch.sub(x[:, -1], x[:, -2], out=gx[:, -1])
    torch.sub(x[2:], x[:-2], out=gy[1:-1])
    torch.sub(x[1], x[0], out=gy[0])
    torch.sub(x[-1], x[-2], out=gy[-1])
    return gx.mul_(0.5), gy.mul_(0.5)


def gaussian_radius(sigma: float) -> int:
    """Radius r = max(1, ceil(3 sigma)) px of the sampled Gaussian kernel of ``sigma`` px."""
    return max(1, math.ceil(3.0 * sigma))


def gaussian_kernel(sigma: float) -> np.ndarray:
    """(2r+1,) normalised sampled Gaussian of ``sigma`` px, r = :func:`gaussian_radius` (float64)."""
    r = gaussian_radius(sigma)
    k = np.exp(-(np.arange(-r, r + 1) ** 2) / (2.0 * sigma**2))
    return k / k.sum()


def gaussian_blur(channels: list[torch.Tensor], sigma: float) -> list[torch.Tensor]:
    """Separable Gaussian smoothing (``sigma`` px) of (H, W) images, reflected borders (BORDER_REFLECT_101).

    On CPU this calls ``cv2.sepFilter2D`` per image (about 10x faster than torch here); elsewhere it runs
    torch shifted multiply-adds (much faster than single-channel conv2d). Both give the same result.
    """
    k = gaussian_kernel(sigma)
    if use_opencv(channels[0]):
        k32 = k.astype(np.float32)
        return [
            torch.from_numpy(
                cv2.sepFilter2D(ch.contiguous().numpy(), -1, k32, k32, borderType=cv2.BORDER_REFLECT_101)
            )
            for ch in channels
        ]
    return list(gaussian_blur_torch(torch.stack(channels), k).unbind(0))


def gaussian_blur_torch(x: torch.Tensor, kernel: np.ndarray) -> torch.Tensor:
    """Torch separable filtering of (C, H, W) with a symmetric odd kernel and reflected borders, (C, H, W)."""
    r = len(kernel) // 2
    k = kernel.tolist()
    height, width = x.shape[-2:]
    p = F.pad(x[None], (r, r, r, r), mode="reflect")[0]
    rows = k[0] * p[:, :, :width]
    for i in range(1, 2 * r + 1):
        rows.add_(p[:, :, i : i + width], alpha=k[i])
    out = k[0] * rows[:, :height]
    for i in range(1, 2 * r + 1):
        out.add_(rows[:, i : i + height], alpha=k[i])
    return out


def blurred_rows(channels: list[torch.Tensor], sigma: float, start: int, stop: int, first: int
                 ) -> list[torch.Tensor]:
    """Rows start..stop-1, (stop - start, W) each, of the Gaussian-blurred images whose rows first.. are
    ``channels``; equal to those rows of the whole images' blur when ``channels`` reach
    :func:`gaussian_radius` rows beyond them (or the image border)."""
    return [blurred[start - first : stop - first] for blurred in gaussian_blur(channels, sigma)]


def max_filter(x: torch.Tensor, window: int) -> torch.Tensor:
    """Maximum over the window x window neighbourhood of each pixel of (H, W); outside pixels are ignored."""
    if use_opencv(x):
        return torch.from_numpy(cv2.dilate(x.contiguous().numpy(), np.ones((window, window), np.uint8)))
    return max_filter_torch(x, window)


def max_filter_torch(x: torch.Tensor, window: int) -> torch.Tensor:
    """Torch version of :func:`max_filter` (separable max pooling), (H, W) -> (H, W)."""
    h = window // 2
    pooled = F.max_pool2d(x[None, None], (1, window), stride=1, padding=(0, h))
    return F.max_pool2d(pooled, (window, 1), stride=1, padding=(h, 0))[0, 0]


def row_strips(height: int, width: int, whole_pixels: int, strip_pixels: int) -> list[tuple[int, int]]:
    """Row ranges [start, stop) covering ``height`` rows of width ``width``: one when the image has at most
    ``whole_pixels`` pixels, else near-equal strips of at most ``strip_pixels`` pixels (never empty)."""
    pixels = height * width
    count = 1 if pixels <= whole_pixels else min(height, math.ceil(pixels / strip_pixels))
    bounds = [round(i * height / count) for i in range(count + 1)]
    return list(itertools.pairwise(bounds))


def scaled_size(height: int, width: int, factor: float) -> tuple[int, int]:
    """(W_s, H_s) = rounded size of a ``height`` x ``width`` image scaled by ``factor``."""
    return max(1, round(width * factor)), max(1, round(height * factor))


def _lanczos3(x: np.ndarray) -> np.ndarray:
    return np.where(np.abs(x) < 3.0, np.sinc(x) * np.sinc(x / 3.0), 0.0)


def _resize_matrix(n_out: int, n_in: int, dtype: np.dtype) -> sp.csr_matrix:
    """(n_out, n_in) Lanczos3 interpolation matrix, antialiased (kernel widened) when shrinking."""
    ratio = n_out / n_in
    stretch = min(ratio, 1.0)
    half = 3.0 / stretch
    taps = math.ceil(2 * half) + 1
    u = (np.arange(n_out) + 0.5) / ratio - 0.5
    j = np.floor(u - half)[:, None].astype(np.int64) + 1 + np.arange(taps)[None]
    w = _lanczos3((u[:, None] - j) * stretch)
    j = np.abs(j)  # symmetric border: -1 -> 1 ... mirror around pixel 0 and n-1
    period = 2 * (n_in - 1) if n_in > 1 else 1
    j = j % period
    j = np.where(j >= n_in, period - j, j)
    rows = np.repeat(np.arange(n_out), taps)
    mat = sp.csr_matrix((w.ravel(), (rows, j.ravel())), shape=(n_out, n_in))
    mat.sum_duplicates()
    norm = np.asarray(mat.sum(axis=1)).ravel()
    return (sp.diags(1.0 / norm) @ mat).astype(dtype).tocsr()


def resize_lanczos(image: np.ndarray, factor: float) -> np.ndarray:
    """Resize with a separable Lanczos3 kernel (a = 3), antialiased when downscaling.

    This is our own Lanczos3 (as in MATLAB's ``imresize(..., 'lanczos3')``): the kernel is stretched by
    ``1 / factor`` when shrinking and the image border is mirrored.  OpenCV's ``INTER_LANCZOS4`` is a = 4
    without antialiasing, so it is not used.  Pixel centres are aligned as ``x_s = (x + 0.5) f - 0.5``.

    Args:
        image: (H, W) or (H, W, C) float array.
        factor: scale factor; the output size is :func:`scaled_size`.

    Returns:
        (H_s, W_s[, C]) array of the input's float dtype (float32 for integer input).
    """
    image = np.asarray(image)
    dtype = image.dtype if np.issubdtype(image.dtype, np.floating) else np.dtype(np.float32)
    h, w = image.shape[:2]
    w_s, h_s = scaled_size(h, w, factor)
    chans = image.shape[2:]
    c = int(np.prod(chans)) if chans else 1
    img = image.astype(dtype, copy=False).reshape(h, w * c)
    if h_s != h:
        img = _resize_matrix(h_s, h, dtype) @ img
    img = img.reshape(h_s, w, c).transpose(1, 0, 2).reshape(w, h_s * c)
    if w_s != w:
        img = _resize_matrix(w_s, w, dtype) @ img
    return np.ascontiguousarray(img.reshape(w_s, h_s, c).transpose(1, 0, 2).reshape((h_s, w_s) + chans))


def resize_area(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """OpenCV resize of an (H, W[, C]) image to ``size`` = (w, h) px: area interpolation when the output has
    fewer pixels (each output pixel the mean of the input pixels it covers), bilinear otherwise.

    Returns:
        (h, w[, C]) array of the input's dtype; pixel centres map as ``x = (x_s + 0.5) W / w - 0.5``.
    """
    h, w = image.shape[:2]
    nw, nh = size
    interp = cv2.INTER_AREA if nw * nh < w * h else cv2.INTER_LINEAR
    return cv2.resize(image, (nw, nh), interpolation=interp)
