"""An end-to-end learned peer for ``slime bench``: kornia's LoFTR (the learned sparse bases, ALIKED, DISK and
XFeat with LightGlue, are base pipelines: ``slime_match.pipelines.learned``).

It follows the call contract of :mod:`slime_match.eval.methods`: ``method(image0, image1) -> (xy0, xy1,
scores, seconds)`` with (H, W, 3) float32 RGB images in [0, 1], (K, 2) float64 keypoints in pixels of the given
images (centre of the top-left pixel = (0, 0)), (K,) float64 dissimilarities (lower is better) and the
wall-clock seconds of the matching alone (models are built lazily on the first call and not timed).

Weights: LoFTR loads kornia's pretrained checkpoint through kornia itself (``LoFTR(pretrained=...)``), i.e. from
the torch-hub cache ``torch.hub.get_dir()/checkpoints`` (follows ``TORCH_HOME``), downloading it there when the
network allows it. When it is neither cached nor downloadable, :class:`~slime_match.errors.WeightsNotFoundError`
names the model, the cache folder and the alternatives; there is no fallback to another model.

Conventions:
    - LoFTR gets the grey image resized so that its longest side is at most ``max_side`` and both sides are
      multiples of 8; kornia documents its keypoints in a frame where pixel (x, y) has its centre at
      (x + 0.5, y + 0.5), so 0.5 is subtracted before mapping them back to the original pixels. Scores are
      ``1 - confidence`` (LoFTR's coarse dual-softmax confidence; kornia keeps only confidence > threshold).
    - Resizing uses OpenCV (area when shrinking), whose pixel grid maps pixel centre ``x`` of the resized image to
      ``(x + 0.5) * W / w - 0.5`` of the original; :func:`frame_of` maps that per axis.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import torch

from slime_match.errors import ConfigError
from slime_match.eval.method_base import MethodOutput, dataclass_from, synchronize, to_grey
from slime_match.features.learned_weights import pretrained
from slime_match.geometry.frames import Frame
from slime_match.matcher import resolve_device

ALTERNATIVES = "keynet, hz+, rootsift, opencv-sift (or slime)"
HOW_TO_GET = ("download them into that folder on a machine with network access (kornia does it on first use; "
              "set TORCH_HOME to move the cache)")
LOFTR_WEIGHTS = ("outdoor", "indoor", "indoor_new")

# --------------------------------------------------------------------------------------------- geometry


def fit_size(height: int, width: int, max_side: int, multiple: int = 1) -> tuple[int, int]:
    """Size (h, w) of the resized image: longest side <= max_side, both sides multiples of ``multiple``.

    The image is only shrunk to meet ``max_side`` (0 = no limit); rounding each side to the nearest multiple
    may then change its aspect ratio slightly, which :func:`frame_of`'s ``to_original`` undoes per axis.

    Args:
        height, width: original size in pixels.
        max_side: bound on the longest side (0 = none); must be >= ``multiple`` when set.
        multiple: each returned side is a positive multiple of it.
    """
    longest = max(height, width)
    scale = max_side / longest if max_side and longest > max_side else 1.0
    limit = (max_side // multiple) * multiple if max_side else None

    def side(n: int) -> int:
        s = max(multiple, int(n * scale / multiple + 0.5) * multiple)
        return min(s, limit) if limit is not None else s

    return side(height), side(width)


def resize_to(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``image`` (H, W[, C]) resized to ``size`` = (h, w) with OpenCV (area when shrinking, else bilinear)."""
    h, w = size
    height, width = image.shape[:2]
    if (h, w) == (height, width):
        return np.ascontiguousarray(image, dtype=np.float32)
    interpolation = cv2.INTER_AREA if h <= height and w <= width else cv2.INTER_LINEAR
    return cv2.resize(np.ascontiguousarray(image, dtype=np.float32), (w, h), interpolation=interpolation)


def frame_of(size: tuple[int, int], original: tuple[int, int]) -> Frame:
    """The frame of an image of ``original`` = (H, W) px resized to ``size`` = (h, w) (pixel centres are
    integers in both and the image edges coincide)."""
    return Frame.of_sizes(size[::-1], original[::-1])


# --------------------------------------------------------------------------------------------- options


def _check_device(name: str, what: str) -> None:
    if name == "auto":
        return
    try:
        torch.device(name)
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(f"{what} device must be auto, cpu or cuda[:N], got {name!r}") from exc


def _check_max_side(value: Any, multiple: int, what: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or (value != 0 and value < max(multiple, 16)):
        raise ConfigError(
            f"{what} max_side must be 0 (no limit) or an integer >= {max(multiple, 16)}, got {value!r}"
        )


def _check_threshold(value: Any, what: str) -> None:
    if value is not None and (
        isinstance(value, bool) or not isinstance(value, int | float) or not 0 <= value < 1
    ):
        raise ConfigError(f"{what} threshold must be None (kornia's default) or in [0, 1), got {value!r}")


def _numpy(t: torch.Tensor) -> np.ndarray:
    return t.detach().float().cpu().numpy().astype(np.float64)


# --------------------------------------------------------------------------------------------- LoFTR


@dataclass
class LoFTRConfig:
    """kornia LoFTR (detector-free, dense transformer matching).

    Attributes:
        weights: pretrained model, "outdoor" (MegaDepth) | "indoor" | "indoor_new" (ScanNet).
        max_side: longest side (pixels) of the image LoFTR sees, 0 = no downscaling; sides are rounded to
            multiples of 8. 840 is the usual outdoor setting.
        threshold: coarse confidence above which a match is kept; None = kornia's default (0.2).
        device: "auto" | "cpu" | "cuda".
    """

    weights: str = "outdoor"
    max_side: int = 840
    threshold: float | None = None
    device: str = "auto"


class KorniaLoFTR:
    """kornia's LoFTR on the grey images; scores are ``1 - confidence``.

    Raises (on the first call):
        WeightsNotFoundError: the LoFTR checkpoint is neither cached nor downloadable.
    """

    def __init__(self, **options: Any) -> None:
        self.config = dataclass_from(LoFTRConfig, options, "loftr")
        cfg = self.config
        if cfg.weights not in LOFTR_WEIGHTS:
            raise ConfigError(f"loftr weights must be one of {', '.join(LOFTR_WEIGHTS)}, got {cfg.weights!r}")
        _check_max_side(cfg.max_side, 8, "loftr")
        _check_threshold(cfg.threshold, "loftr")
        _check_device(cfg.device, "loftr")
        self._model: torch.nn.Module | None = None

    def _build(self) -> None:
        import kornia.feature as KF
        from kornia.feature.loftr.loftr import default_cfg

        cfg = self.config
        self.device = resolve_device(cfg.device)
        config = copy.deepcopy(default_cfg)
        if cfg.threshold is not None:
            config["match_coarse"]["thr"] = float(cfg.threshold)
        with pretrained(f"LoFTR '{cfg.weights}'", HOW_TO_GET, ALTERNATIVES):
            model = KF.LoFTR(pretrained=cfg.weights, config=config)
        self._model = model.eval().to(self.device)

    def _prepare(self, image: np.ndarray) -> tuple[torch.Tensor, tuple[int, int]]:
        """(H, W, 3) RGB -> (1, 1, h, w) grey tensor on the device, and (h, w)."""
        grey = to_grey(image)
        size = fit_size(*grey.shape, self.config.max_side, 8)
        return torch.from_numpy(resize_to(grey, size))[None, None].to(self.device), size

    @torch.inference_mode()
    def __call__(self, image0: np.ndarray, image1: np.ndarray) -> MethodOutput:
        if self._model is None:
            self._build()
        synchronize()
        start = time.perf_counter()
        (t0, size0), (t1, size1) = self._prepare(image0), self._prepare(image1)
        out = self._model({"image0": t0, "image1": t1})
        # kornia's LoFTR frame puts pixel centres at +0.5: shift to integer centres, then undo the resize
        xy0 = frame_of(size0, image0.shape[:2]).to_original(_numpy(out["keypoints0"]).reshape(-1, 2) - 0.5)
        xy1 = frame_of(size1, image1.shape[:2]).to_original(_numpy(out["keypoints1"]).reshape(-1, 2) - 0.5)
        scores = 1.0 - _numpy(out["confidence"]).reshape(-1)
        synchronize()
        return xy0, xy1, scores, time.perf_counter() - start
