"""The :class:`Pair` with its ground truth, GT geometry (F from a pose or from correspondences, intrinsics of
a resized frame) and exact GT updates when a view is rotated or warped."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import scipy.linalg

from slime_match.errors import ConfigError
from slime_match.eval.datasets.files import read_image
from slime_match.geometry.frames import Frame

KINDS = ("homography", "fundamental", "pose", "disparity")


@dataclass
class Pair:
    """One image pair with its ground truth (fields not given by the dataset are None).

    Attributes:
        name: unique name, e.g. "graf/1-3".
        image0, image1: image file paths, or (H, W[, C]) arrays for generated pairs.
        kind: "homography" | "fundamental" | "pose" | "disparity": which ground truth drives the metrics.
        H: (3, 3) float64 homography image 0 -> image 1.
        F: (3, 3) float64 fundamental matrix, ``x1^T F x0 = 0``.
        K0, K1: (3, 3) float64 intrinsics in the original frame of each image.
        R, t: (3, 3), (3,) float64 relative pose, ``X1 = R X0 + t``.
        disparity: (H0, W0) float32 left disparity in px, left (x, y) <-> right (x - d, y); inf/nan = unknown.
        mask0, mask1: (H, W) bool, True = excluded (e.g. out-of-plane areas).
        corrs: (M, 4) float64 ground-truth correspondences ``x0 y0 x1 y1``.
        max_side: protocol resize: scale so that the longest side is at most this (None: no limit).
        size: protocol resize to exactly ``(width, height)`` for landscape images, ``(height, width)`` for
            portrait ones (None: keep).
    """

    name: str
    image0: Path | np.ndarray
    image1: Path | np.ndarray
    kind: str
    H: np.ndarray | None = None
    F: np.ndarray | None = None
    K0: np.ndarray | None = None
    K1: np.ndarray | None = None
    R: np.ndarray | None = None
    t: np.ndarray | None = None
    disparity: np.ndarray | None = None
    mask0: np.ndarray | None = None
    mask1: np.ndarray | None = None
    corrs: np.ndarray | None = None
    max_side: int | None = None
    size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ConfigError(f"unknown pair kind {self.kind!r}; expected one of {KINDS}")


# ----------------------------------------------------------------------------------------------------------
# geometry helpers


def skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) cross-product matrix of a (3,) vector."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def fundamental_from_pose(K0: np.ndarray, K1: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """F = K1^-T [t]x R K0^-1 (normalised to unit Frobenius norm) for ``X1 = R X0 + t``."""
    F = np.linalg.inv(K1).T @ skew(np.asarray(t, np.float64).reshape(3)) @ R @ np.linalg.inv(K0)
    return F / np.linalg.norm(F)


def fundamental_from_corrs(corrs: np.ndarray) -> np.ndarray:
    """F from (M >= 8, 4) correspondences ``x0 y0 x1 y1`` by the normalised 8-point algorithm (least squares)."""
    corrs = np.asarray(corrs, np.float64)
    if corrs.shape[0] < 8:
        raise ConfigError(f"need at least 8 ground-truth correspondences to compute F, got {corrs.shape[0]}")
    F, _ = cv2.findFundamentalMat(corrs[:, :2], corrs[:, 2:], cv2.FM_8POINT)
    if F is None or F.shape != (3, 3):
        raise ConfigError("degenerate ground-truth correspondences: the 8-point algorithm failed")
    return F / np.linalg.norm(F)


# ----------------------------------------------------------------------------------------------------------
# intrinsics of a protocol-resized frame


def scale_intrinsics(K: np.ndarray, frame: Frame) -> np.ndarray:
    """(3, 3) intrinsics of a resized ``frame`` (``resize.resize_image``), given original-frame ``K``."""
    return frame.matrix() @ K


# ----------------------------------------------------------------------------------------------------------
# rotations


def _rotation_affine(width: int, height: int, angle_deg: float) -> tuple[np.ndarray, tuple[int, int]]:
    """(3, 3) map from original to rotated pixel coordinates (counter-clockwise on screen, expanded canvas)."""
    k = angle_deg / 90.0
    if abs(k - round(k)) < 1e-12:
        c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][round(k) % 4]
    else:
        a = math.radians(angle_deg)
        c, s = math.cos(a), math.sin(a)
    # y points down, so a counter-clockwise rotation on screen is x' = c x + s y, y' = -s x + c y.
    Rm = np.array([[c, s], [-s, c]], np.float64)
    if isinstance(c, int):
        nw, nh = (width, height) if c != 0 else (height, width)
    else:
        nw = math.ceil(abs(c) * width + abs(s) * height - 1e-9)
        nh = math.ceil(abs(s) * width + abs(c) * height - 1e-9)
    centre = np.array([(width - 1) / 2, (height - 1) / 2])
    new_centre = np.array([(nw - 1) / 2, (nh - 1) / 2])
    A = np.eye(3)
    A[:2, :2] = Rm
    A[:2, 2] = new_centre - Rm @ centre
    return A, (nw, nh)


def rotate_image(image: np.ndarray, angle_deg: float, nearest: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Rotate an image counter-clockwise (as displayed) by ``angle_deg`` on an expanded canvas.

    Multiples of 90 degrees are exact (np.rot90); other angles use cv2.warpAffine (bilinear, or nearest
    when ``nearest``) with a zero border. Returns the rotated image and the (3, 3) map A from original to
    rotated pixel coordinates.
    """
    h, w = image.shape[:2]
    A, (nw, nh) = _rotation_affine(w, h, angle_deg)
    k = angle_deg / 90.0
    if abs(k - round(k)) < 1e-12:
        return np.ascontiguousarray(np.rot90(image, round(k) % 4)), A
    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.warpAffine(image, A[:2], (nw, nh), flags=interp, borderMode=cv2.BORDER_CONSTANT), A


def _rotate_mask(mask: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rotate an exclusion mask; pixels outside the original canvas become excluded (True)."""
    out, _ = rotate_image(mask.astype(np.uint8) + 1, angle_deg, nearest=True)
    return out != 1


def _warp_camera(
    K: np.ndarray, R: np.ndarray, t: np.ndarray, A: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """New (K, R, t) of a camera whose pixels are mapped by the in-plane affine A (RQ decomposition)."""
    Kn, Q = scipy.linalg.rq(A @ K)
    D = np.diag(np.sign(np.diag(Kn)))
    Kn, Q = Kn @ D, D @ Q
    Kn = Kn / Kn[2, 2]
    return Kn, Q @ R, Q @ t


def transform_view(pair: Pair, which: int, image: np.ndarray, A: np.ndarray) -> Pair:
    """Copy of ``pair`` whose image ``which`` (0 or 1) is replaced by ``image``, the old one warped by the
    (3, 3) pixel map A; H, F, GT correspondences and the camera of that view are updated exactly (masks
    are left to the caller)."""
    Ai = np.linalg.inv(A)
    H, F, K0, K1, R, t = pair.H, pair.F, pair.K0, pair.K1, pair.R, pair.t
    corrs = None if pair.corrs is None else pair.corrs.copy()
    cols = slice(2, 4) if which == 1 else slice(0, 2)
    if corrs is not None:
        corrs[:, cols] = corrs[:, cols] @ A[:2, :2].T + A[:2, 2]
    if which == 1:
        H = None if H is None else A @ H
        F = None if F is None else Ai.T @ F
        if K1 is not None and R is not None and t is not None:
            K1, R, t = _warp_camera(K1, R, t, A)
    else:
        H = None if H is None else H @ Ai
        F = None if F is None else F @ Ai
        if K0 is not None and R is not None and t is not None:
            # camera 0 rotates by Q: X0' = Q X0, so X1 = R Q^T X0' + t
            K0, Q, _ = _warp_camera(K0, np.eye(3), np.zeros(3), A)
            R = R @ Q.T
    F = None if F is None else F / np.linalg.norm(F)
    H = None if H is None else H / H[2, 2]
    fields = {"H": H, "F": F, "K0": K0, "K1": K1, "R": R, "t": t, "corrs": corrs}
    return replace(pair, **{("image1" if which == 1 else "image0"): image}, **fields)


def rotated_pair(pair: Pair, angle_deg: float) -> Pair:
    """Copy of ``pair`` with image 1 rotated counter-clockwise by ``angle_deg`` and the GT updated exactly.

    ``H' = A H``, ``F' = A^-T F``, GT correspondences and mask 1 are moved by A, and the pose of camera 1
    gets the in-plane rotation (``K1' Q = A K1``, ``R' = Q R``, ``t' = Q t``). Image 1 becomes an array.
    Disparity pairs cannot be rotated (the rectified geometry would be lost).
    """
    if pair.kind == "disparity":
        raise ConfigError("rotated_pair: a disparity (rectified stereo) pair cannot be rotated")
    original = read_image(pair.image1)
    img, A = rotate_image(original, angle_deg)
    out = transform_view(pair, 1, img, A)
    mask1 = pair.mask1
    if mask1 is not None or abs(angle_deg / 90 - round(angle_deg / 90)) > 1e-12:
        mask1 = _rotate_mask(np.zeros(original.shape[:2], bool) if mask1 is None else mask1, angle_deg)
    suffix = f"{angle_deg:g}".replace(".", "p")
    return replace(out, name=f"{pair.name}@rot{suffix}", mask1=mask1)
