"""Small typed containers passed between stages.

Conventions (everywhere in the package):
    * pixel coordinates are ``(x, y)`` = (column, row); the centre of the top-left pixel is ``(0, 0)``;
    * features live in torch tensors on the pipeline's device, matches in numpy arrays on the CPU
      (DTM, RANSAC and the Slime set logic are CPU work);
    * match scores are dissimilarities: lower is better.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch


@dataclass
class Keypoints:
    """Detector output (HarrisZ+), born upright.

    Attributes:
        xy: (N, 2) float32 keypoint centres in pixels.
        ellipse: (N, 2, 2) float32 symmetric positive-definite matrices E; the region is
            ``{x : (x - c)^T E (x - c) <= 1}`` in pixels.
        response: (N,) float32 detector response (higher is stronger).
        level: (N,) int64 scale level index of the detection.
    """

    xy: torch.Tensor
    ellipse: torch.Tensor
    response: torch.Tensor
    level: torch.Tensor

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    def subset(self, index: torch.Tensor) -> Keypoints:
        """Keypoints selected by a boolean mask or an index tensor."""
        return Keypoints(self.xy[index], self.ellipse[index], self.response[index], self.level[index])

    def to(self, device: torch.device | str) -> Keypoints:
        """The keypoints on ``device``."""
        return Keypoints(*(t.to(device) for t in (self.xy, self.ellipse, self.response, self.level)))


@dataclass
class Features:
    """Oriented, described local features of one image.

    Attributes:
        laf: (N, 2, 3) float32 local affine frames in pixels (kornia convention: ``laf[:, :, 2]`` is the
            centre, ``laf[:, :, :2]`` maps the unit patch frame to the image, including orientation).
        descriptors: (N, D) float32 descriptors (L2-normalised for the learned ones and RootSIFT).
        response: (N,) float32 detector response.
        shape_laf: optional (N, 2, 3) upright affine-normalised frames before orientation assignment;
            kept so that the descriptor can be recomputed under a fixed orientation (Slime).
    """

    laf: torch.Tensor
    descriptors: torch.Tensor
    response: torch.Tensor
    shape_laf: torch.Tensor | None = None

    def __len__(self) -> int:
        return int(self.laf.shape[0])

    @property
    def xy(self) -> torch.Tensor:
        """(N, 2) keypoint centres in pixels."""
        return self.laf[:, :, 2]

    @property
    def angle(self) -> torch.Tensor:
        """(N,) patch orientation in radians (direction of the patch x axis in the image)."""
        return torch.atan2(self.laf[:, 1, 0], self.laf[:, 0, 0])

    @property
    def scale(self) -> torch.Tensor:
        """(N,) patch scale in pixels: sqrt(|det A|) of the LAF's linear part."""
        a = self.laf[:, :, :2]
        return (a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]).abs().sqrt()

    def subset(self, index: torch.Tensor) -> Features:
        """Features selected by a boolean mask or an index tensor."""
        shape_laf = None if self.shape_laf is None else self.shape_laf[index]
        return Features(self.laf[index], self.descriptors[index], self.response[index], shape_laf)

    def strongest(self, count: int) -> torch.Tensor:
        """(min(N, count),) indices of the features of highest detector response, highest first (ties in index
        order)."""
        return torch.argsort(self.response, descending=True, stable=True)[:count]

    def to(self, device: torch.device | str) -> Features:
        """The features on ``device``."""
        shape_laf = None if self.shape_laf is None else self.shape_laf.to(device)
        return Features(self.laf.to(device), self.descriptors.to(device), self.response.to(device), shape_laf)

    def moved(self, offset: tuple[float, float]) -> Features:
        """The same features moved by ``offset`` (x, y) px, LAF and shape-frame centres alike: from one pixel
        frame to another (:class:`~slime_match.geometry.frames.Frame`) cut at a different corner."""
        shift = torch.tensor(offset, dtype=self.laf.dtype, device=self.laf.device)
        laf = self.laf.clone()
        laf[:, :, 2] += shift
        shape_laf = None
        if self.shape_laf is not None:
            shape_laf = self.shape_laf.clone()
            shape_laf[:, :, 2] += shift
        return Features(laf, self.descriptors, self.response, shape_laf)


@dataclass
class Matches:
    """Correspondences between two feature sets (possibly many-to-many).

    Attributes:
        idx0: (K,) int64 indices into the first feature set.
        idx1: (K,) int64 indices into the second feature set.
        scores: (K,) float64 dissimilarities, lower is better.
    """

    idx0: np.ndarray
    idx1: np.ndarray
    scores: np.ndarray

    def __post_init__(self) -> None:
        self.idx0 = np.asarray(self.idx0, dtype=np.int64).reshape(-1)
        self.idx1 = np.asarray(self.idx1, dtype=np.int64).reshape(-1)
        self.scores = np.asarray(self.scores, dtype=np.float64).reshape(-1)
        if not (len(self.idx0) == len(self.idx1) == len(self.scores)):
            raise ValueError("idx0, idx1 and scores must have the same length")

    def __len__(self) -> int:
        return int(self.idx0.shape[0])

    @classmethod
    def empty(cls) -> Matches:
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float64))

    def subset(self, index: np.ndarray) -> Matches:
        """Matches selected by a boolean mask or an index array."""
        return Matches(self.idx0[index], self.idx1[index], self.scores[index])


@dataclass
class GeometryResult:
    """A robust two-view model and its inliers.

    Attributes:
        kind: "homography" or "fundamental" (a fundamental RANSAC may return a homography when the
            data are planar).
        model: (3, 3) float64 matrix mapping image 0 to image 1 (H) or with x1^T F x0 = 0 (F);
            None when no model could be estimated.
        inliers: (K,) bool mask over the input correspondences.
        info: free-form diagnostics (iterations, backend, threshold...).
    """

    kind: str
    model: np.ndarray | None
    inliers: np.ndarray
    info: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        """One line (the arrays are attributes): kind, inlier count, threshold and backend."""
        text = f"GeometryResult({self.kind!r}, {int(np.sum(self.inliers))} of {len(self.inliers)} inliers"
        if self.model is None:
            text += ", no model"
        for key, unit in (("threshold", " px"), ("backend", "")):
            if key in self.info:
                text += f", {key}={self.info[key]!r}{unit}"
        return text + ")"
