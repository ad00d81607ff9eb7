"""Affine view synthesis (ASIFT): simulated views of an image seen from a tilted viewpoint.

A camera looking at a plane from latitude ``arccos(1 / t)`` sees it compressed by the *tilt* ``t`` along one
direction. ASIFT simulates such views of an image: rotate by ``angle``, blur along x (anti-aliasing, a
Gaussian of ``0.8 sqrt(t^2 - 1)`` px) and subsample x by ``t``; the rotations are sampled every ``72 / t``
degrees in [0, 180) (ASIFT's sampling). Matching a simulated view of one image against the other compensates
a strong tilt between the two that neither the detector's affine shapes nor the block scales can: views of
image 0 undo a tilt that compresses image 1, views of image 1 one that compresses image 0.

Where views are used: Slime's block stage (``slime.view_step``: each view is one more set of block levels)
and a base pipeline alone (``pipelines.view_matching``). Both add them adaptively by default (:class:`ViewConfig`):
only when the plain run finds too little consistent geometry, tilt after tilt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from ._runtime.options import check_choice, check_integer
from .choices import VIEW_IMAGES, VIEW_MODES
from .errors import ConfigError
from .geometry.frames import Frame

__all__ = ["VIEW_IMAGES", "VIEW_MODES", "View", "ViewConfig", "ViewRecord", "ViewTry", "simulate_view", "view_geometry",
           "views_of_tilt"]

ANTIALIAS = 0.8  # ASIFT's blur: sigma = ANTIALIAS * sqrt(t^2 - 1) px before subsampling x by t
VIEW_BORDER = 2.0  # original px: keypoints of a view closer than this to the image border are dropped


@dataclass
class ViewConfig:
    """Simulated views (ASIFT tilts and rotations) and when to add them.

    Attributes:
        mode: "auto" (views only when the plain run finds too little consistent geometry, tilt after tilt
            until it does), "always" (every tilt of every image asked for), "off".
        tilts: the tilts tried, in order (each with the rotations ``views_of_tilt`` gives it).
        images: whose views: "both" (default, as ASIFT simulates both images: Slime keeps each image's
            views a branch of its own and keeps the stronger, ``slime.view_step``; a base alone pools the
            matches of both), "image0" or "image1".
        min_support: Slime's "auto" adds views while F^theta (the planes the epipolar vote kept, Secs.
            3.6-3.7) holds fewer matches than this; when no view reaches it, the views' planes are dropped
            and the images' own planes decide (views that find no stronger geometry only compete with them).
            A branch under it is kept too when its views added ``min_support`` times the base pipeline's
            ``slime_view_gain`` matches to the plain F^theta (``slime.view_step``).
        min_tilt: Slime's "auto" adds no view either when the plain F^theta is under ``min_support`` but its
            matches' affine map (``slime.view_step.PlainTilt``, measured on 10 matches of 2 planes at least)
            shows a tilt under this: the base matched the scene where it is not foreshortened, and what limits
            the matches there is appearance or overlap, which views do not change (1: views whatever the tilt).
        max_tilt: Slime's "auto" adds views also when the plain F^theta holds ``min_support`` matches but their
            affine map (measured as for ``min_tilt``) shows a tilt over this: the scene is foreshortened beyond
            what a base matches alone, so the plain matches hold only the part of it seen least obliquely
            (inf: never).
        steep_tilts: the tilts Slime's "auto" tries after ``tilts`` where the plain matches read a tilt over
            ``max_tilt`` and no earlier tilt's views were kept: views up to 4 leave such a scene a residual tilt
            over 2, more than the base follows (empty: none).
        min_inliers: a base pipeline alone adds views while fewer of its matches than this are consistent
            with one fundamental matrix (OpenCV MAGSAC++, 3 px; a base alone finds far fewer matches than
            Slime).
        min_probe: Slime with level matching (``SlimeConfig.block_matching``, a matcher that reads whole
            images) pairs a view's blocks only when its probe, its finest level matched against the other
            image's level of the nearest scale, holds this many matches consistent with one fundamental matrix
            (``slime.view_planes``); 0 pairs every view's blocks.
        screen_keypoints: the probe is screened first on this many of each level's strongest keypoints, and
            a view whose screen holds fewer than ``slime.view_planes.SCREEN_FLOOR`` (10) consistent matches
            is not probed in full (0: every view probed in full).
    """

    mode: str = "auto"
    tilts: tuple[float, ...] = (2.0, 4.0)
    images: str = "both"
    min_support: int = 100
    min_tilt: float = math.sqrt(2.0)
    max_tilt: float = 8.0
    steep_tilts: tuple[float, ...] = (8.0,)
    min_inliers: int = 50
    min_probe: int = 25
    screen_keypoints: int = 1024

    def __post_init__(self) -> None:
        self.tilts = tuple(float(t) for t in self.tilts)
        self.steep_tilts = tuple(float(t) for t in self.steep_tilts)
        self.min_tilt, self.max_tilt = float(self.min_tilt), float(self.max_tilt)
        self.validate()

    def validate(self) -> ViewConfig:
        check_choice("views.mode", self.mode, VIEW_MODES)
        check_choice("views.images", self.images, VIEW_IMAGES)
        check_integer("views.min_support", self.min_support, 1)
        check_integer("views.min_inliers", self.min_inliers, 8)
        check_integer("views.min_probe", self.min_probe, 0)
        check_integer("views.screen_keypoints", self.screen_keypoints, 0)
        if not self.min_tilt >= 1.0:
            raise ConfigError(f"views.min_tilt must be >= 1 (1: views whatever the matches' tilt), got {self.min_tilt}")
        if not self.max_tilt > self.min_tilt:
            raise ConfigError(f"views.max_tilt must be > views.min_tilt ({self.min_tilt:g}; inf: never), "
                              f"got {self.max_tilt}")
        if not all(t > 1.0 for t in self.tilts):
            raise ConfigError(f"views.tilts must all be > 1 (1 is the image itself), got {self.tilts}")
        if not all(t > 1.0 for t in self.steep_tilts):
            raise ConfigError(f"views.steep_tilts must all be > 1 (1 is the image itself), got {self.steep_tilts}")
        return self

    @property
    def viewed(self) -> tuple[int, ...]:
        """The images whose views are simulated (0, 1 or both), image 0 first."""
        return {"image0": (0,), "image1": (1,), "both": (0, 1)}[self.images]

    def schedule(self) -> list[tuple[int, float]]:
        """Every (image, tilt) step in the order a base pipeline alone tries them: per tilt, image 0's views
        before image 1's."""
        return [(image, tilt) for tilt in self.tilts for image in self.viewed]


@dataclass(frozen=True)
class View:
    """A simulated view of an image: ``affine`` maps original px to view px.

    Attributes:
        tilt: compression of the x axis after the rotation (>= 1).
        angle: rotation in degrees (counter-clockwise in the image as displayed, y down).
        affine: (6,) row-major 2x3 map original px -> view px (pixel centres at integers).
        size: (W, H) of the view image, px.
        original_size: (W, H) of the original image, px.
    """

    tilt: float
    angle: float
    affine: tuple[float, ...]
    size: tuple[int, int]
    original_size: tuple[int, int]

    @property
    def frame(self) -> Frame:
        """The view as a frame of the original image (``to_original``, ``from_original``, ``matrix``)."""
        return Frame(view=self.affine)

    def inside(self, xy_original: np.ndarray, margin: float = VIEW_BORDER) -> np.ndarray:
        """(N,) bool: original-px points at least ``margin`` px inside the original image (a view's pixels
        beyond it are the reflected border of the warp, not the image)."""
        xy = np.asarray(xy_original, np.float64).reshape(-1, 2)
        size = np.array(self.original_size, np.float64)
        return np.all((xy >= margin - 0.5) & (xy <= size - 0.5 - margin), axis=1)


def view_geometry(size: tuple[int, int], tilt: float, angle: float) -> View:
    """The view of an image of (W, H) ``size`` rotated by ``angle`` degrees and compressed along x by ``tilt``:
    the rotated image's bounding box, then x subsampled (a pixel centre x maps to ``(x + 0.5) / t - 0.5``)."""
    if tilt < 1.0:
        raise ValueError(f"a tilt is >= 1, got {tilt}")
    width, height = size
    rotation = _rotation(angle)
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [-0.5, height - 0.5], [width - 0.5, height - 0.5]])
    turned = corners @ rotation.T
    low, high = turned.min(0), turned.max(0)
    rotated_size = np.ceil(high - low - 1e-9).astype(int)
    shift = -low - 0.5  # the bounding box's corner (-0.5, -0.5) in the rotated image
    compress = np.diag([1.0 / tilt, 1.0])
    linear = compress @ rotation
    offset = compress @ (shift + 0.5) - 0.5
    view_size = (max(1, math.ceil(rotated_size[0] / tilt)), int(rotated_size[1]))
    return View(float(tilt), float(angle), tuple(np.c_[linear, offset].ravel().tolist()), view_size,
                (int(width), int(height)))


def simulate_view(image: np.ndarray, tilt: float, angle: float) -> tuple[np.ndarray, View]:
    """ASIFT's simulated view of an (H, W[, C]) float image: rotated (bilinear, reflected border), blurred along
    x by ``ANTIALIAS sqrt(t^2 - 1)`` px and subsampled along x by ``tilt``.

    Returns:
        The (H_v, W_v[, C]) float32 view image and its :class:`View`.
    """
    height, width = image.shape[:2]
    view = view_geometry((width, height), tilt, angle)
    rotated_width = math.ceil(tilt * view.size[0] - 1e-9) if tilt > 1 else view.size[0]
    offset = np.reshape(view.affine, (2, 3))[:, 2]
    rotate = np.c_[_rotation(angle), np.diag([tilt, 1.0]) @ (offset + 0.5) - 0.5]  # the view's map before the x step
    source = np.ascontiguousarray(image, dtype=np.float32)
    rotated = cv2.warpAffine(source, rotate, (rotated_width, view.size[1]), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REFLECT_101)
    if tilt == 1.0:
        return rotated.reshape(rotated.shape[:2] + image.shape[2:]), view
    sigma = ANTIALIAS * math.sqrt(tilt * tilt - 1.0)
    radius = max(1, math.ceil(3.0 * sigma))
    kernel = cv2.getGaussianKernel(2 * radius + 1, sigma)
    blurred = cv2.sepFilter2D(rotated, -1, kernel, np.ones((1, 1)), borderType=cv2.BORDER_REFLECT_101)
    step = np.array([[1.0 / tilt, 0.0, 0.5 / tilt - 0.5], [0.0, 1.0, 0.0]])
    out = cv2.warpAffine(blurred, step, view.size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
    return out.reshape(out.shape[:2] + image.shape[2:]), view


def _rotation(angle: float) -> np.ndarray:
    """(2, 2) rotation by ``angle`` degrees, counter-clockwise as displayed (y down)."""
    a = math.radians(angle)
    return np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])


def views_of_tilt(tilt: float) -> list[float]:
    """ASIFT's rotations (degrees in [0, 180)) for ``tilt``: a step of ``72 / t`` degrees."""
    step = 72.0 / tilt
    return [k * step for k in range(math.ceil(180.0 / step - 1e-9))]


@dataclass
class ViewTry:
    """One (image, tilt) step of the views: its ``views`` of ``image`` (0 or 1) at ``tilt`` and, for Slime,
    the block ``planes`` they found, the matches of F^theta of the image's branch once they joined it
    (``support``: the plain planes and this image's views so far) and how many of those lie on the branch's
    view planes (``on_views``; the rest are the images' own planes' matches, which the views can move through
    the vote), the final F^theta's matches on this step's planes (``ftheta_matches``; 0 when they were not
    kept) and, per view angle in degrees whose planes hold some, how many (``ftheta_by_angle``); when the views
    were probed (``ViewConfig.min_probe``), each view's screen count by angle (``screens``, when screened), the
    probe count of each view probed in full (``probes``) and how many views had their blocks paired
    (``paired``)."""

    image: int
    tilt: float
    views: int
    planes: int | None = None
    support: int | None = None
    on_views: int | None = None
    ftheta_matches: int | None = None
    ftheta_by_angle: dict[str, int] = field(default_factory=dict)
    probes: dict[str, int] = field(default_factory=dict)
    screens: dict[str, int] = field(default_factory=dict)
    paired: int | None = None

    def as_dict(self) -> dict:
        out = {"image": self.image, "tilt": self.tilt, "views": self.views}
        if self.planes is not None:
            out.update(planes=self.planes, support=self.support, on_views=self.on_views,
                       ftheta_matches=self.ftheta_matches, ftheta_by_angle=self.ftheta_by_angle)
        if self.probes or self.screens:
            out.update(screens=self.screens, probes=self.probes, paired=self.paired)
        return out


@dataclass
class ViewRecord:
    """What the view synthesis did for one pair (for ``summary.json``).

    Attributes:
        mode, images: the ``ViewConfig``'s.
        tried: the (image, tilt) steps run, in order.
        decision: "off", "not needed" (auto: the plain run had enough geometry), "kept" (the views' planes or
            matches stay) or "dropped" (auto: no view reached the support asked for, the plain run's result is
            kept).
        reason: why the views stopped (or why none was tried), in words.
        plain_tilt: Slime's plain F^theta's matches' tilt: their affine map's ``tilt``, how many ``matches`` it
            holds, on how many ``planes``, and whether that is enough to be the scene's (``measured``;
            ``slime.view_step.PlainTilt``); None when no map fits.
    """

    mode: str
    images: str = "both"
    tried: list[ViewTry] = field(default_factory=list)
    decision: str = "off"
    reason: str = "views off"
    plain_tilt: dict[str, float] | None = None

    @property
    def views(self) -> int:
        """How many views were simulated."""
        return sum(step.views for step in self.tried)

    @property
    def tilts(self) -> list[float]:
        """The tilts tried, in order, each once."""
        return list(dict.fromkeys(step.tilt for step in self.tried))

    def as_dict(self) -> dict:
        out = {"mode": self.mode, "images": self.images, "tilts": self.tilts, "views": self.views,
               "decision": self.decision, "reason": self.reason}
        if self.plain_tilt is not None:
            out["plain_tilt"] = self.plain_tilt
        return {**out, "tried": [step.as_dict() for step in self.tried]} if self.tried else out
