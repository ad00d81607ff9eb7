"""Synthetic extreme-viewpoint pairs with exact ground truth, rendered from frontal photos of planes (EVD layout).

Each pair shows one planar image through two pinhole cameras: a "side" pair views it frontally and at the
out-of-plane angle arccos(1 / t) (ASIFT's transition tilt t), a "crossed" pair views it twice at arccos(1 / sqrt t)
about perpendicular axes (the two tilts multiply to t, with both images foreshortened). The tilt axis and the
cameras' rolls (within +-``MAX_ROLL`` degrees: hand-held photos) are drawn from a seed; each camera stands
``DISTANCE`` image sides from the plane's centre, so the perspective is strong at large angles. Images are
rendered ``SUPERSAMPLE`` times larger and area-averaged, black outside the source.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from slime_match.errors import ConfigError

SUPERSAMPLE = 4  # render at this many times the output size, then area-average
DISTANCE = 1.5  # the camera's distance to the plane's centre, in source image sides (the longer side)
MAX_ROLL = 20.0  # degrees: each camera's roll is drawn within +- this
CONFIGS = ("side", "crossed")


@dataclass(frozen=True)
class Camera:
    """A camera of a synthetic pair: out-of-plane ``angle`` about the in-plane ``axis`` (through the plane's
    centre, degrees from the x axis), then ``roll`` about the optical axis; all in degrees."""

    angle: float
    axis: float
    roll: float


def camera_homography(size: tuple[int, int], camera: Camera) -> np.ndarray:
    """(3, 3) homography from source px of a (W, H) ``size`` plane to ``camera``'s image plane (principal point
    at 0, focal length such that a frontal camera sees the source at scale 1)."""
    width, height = size
    focal = DISTANCE * max(width, height)
    axis = math.radians(camera.axis)
    tilt = cv2.Rodrigues(np.array([math.cos(axis), math.sin(axis), 0.0]) * math.radians(camera.angle))[0]
    r = math.radians(camera.roll)
    roll = np.array([[math.cos(r), -math.sin(r), 0.0], [math.sin(r), math.cos(r), 0.0], [0.0, 0.0, 1.0]])
    rotation = roll @ tilt
    centre = np.array([[1.0, 0.0, -(width - 1) / 2.0], [0.0, 1.0, -(height - 1) / 2.0], [0.0, 0.0, 1.0]])
    plane_to_camera = np.c_[rotation[:, :2], [0.0, 0.0, focal]]  # the plane's centre at depth ``focal``
    return np.diag([focal, focal, 1.0]) @ plane_to_camera @ centre


def fit_canvas(homography: np.ndarray, size: tuple[int, int], max_side: int) -> tuple[np.ndarray, tuple[int, int]]:
    """``homography`` followed by the scale and shift that put the warped (W, H) ``size`` source in a canvas
    whose longer side is ``max_side`` px. Returns the (3, 3) source px -> canvas px map and the canvas (W, H)."""
    width, height = size
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [width - 0.5, height - 0.5], [-0.5, height - 0.5]])
    warped = cv2.perspectiveTransform(corners[None], homography)[0]
    low, high = warped.min(0), warped.max(0)
    scale = max_side / float((high - low).max())
    fit = np.array([[scale, 0.0, -0.5 - scale * low[0]], [0.0, scale, -0.5 - scale * low[1]], [0.0, 0.0, 1.0]])
    canvas = np.maximum(np.ceil((high - low) * scale - 1e-9).astype(int), 1)
    return fit @ homography, (int(canvas[0]), int(canvas[1]))


def render(image: np.ndarray, homography: np.ndarray, canvas: tuple[int, int]) -> np.ndarray:
    """``image`` warped by the (3, 3) source px -> canvas px ``homography`` into a (W, H) ``canvas``: bilinear at
    ``SUPERSAMPLE`` times the size, then area-averaged (pixel centres at integer coordinates throughout)."""
    s = SUPERSAMPLE
    up = np.array([[s, 0.0, (s - 1) / 2.0], [0.0, s, (s - 1) / 2.0], [0.0, 0.0, 1.0]])  # canvas px -> fine px
    fine = cv2.warpPerspective(image, up @ homography, (canvas[0] * s, canvas[1] * s), flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT)
    return cv2.resize(fine, canvas, interpolation=cv2.INTER_AREA)


def pair_cameras(config: str, transition_tilt: float, rng: np.random.Generator) -> tuple[Camera, Camera]:
    """The two cameras of a ``config`` ("side" or "crossed") pair at ``transition_tilt`` (> 1), the tilt axis
    and the rolls drawn from ``rng``."""
    if config not in CONFIGS:
        raise ConfigError(f"pair configuration must be one of {CONFIGS}, got {config!r}")
    if not transition_tilt > 1.0:
        raise ConfigError(f"transition tilt must be > 1, got {transition_tilt}")
    axis = float(rng.uniform(0.0, 180.0))
    rolls = [float(r) for r in rng.uniform(-MAX_ROLL, MAX_ROLL, 2)]
    if config == "side":
        angle = math.degrees(math.acos(1.0 / transition_tilt))
        return Camera(0.0, axis, rolls[0]), Camera(angle, axis, rolls[1])
    angle = math.degrees(math.acos(1.0 / math.sqrt(transition_tilt)))
    return Camera(angle, axis, rolls[0]), Camera(angle, axis + 90.0, rolls[1])


def source_name(path: Path) -> str:
    """A pair-name stem: the file's folder and stem (``oxford_graf_img1``, ``v_churchill_1``)."""
    return f"{path.parent.name}_{path.stem}"


def write_viewpoint_set(sources: list[Path], out: Path, tilts: list[float], seed: int = 0,
                        max_side: int = 800) -> list[dict]:
    """Render a "side" and a "crossed" pair per source image and transition tilt into the EVD layout under
    ``out`` (``1/<name>.png``, ``2/<name>.png``, ``h/<name>.txt``: image 1 -> image 2) and ``pairs.json``
    (each pair's source, configuration, tilt, cameras and sizes). Returns those records."""
    if not all(t > 1.0 for t in tilts):
        raise ConfigError(f"transition tilts must all be > 1, got {list(tilts)}")
    if max_side < 32:
        raise ConfigError(f"max_side must be at least 32 px, got {max_side}")
    images = []
    for source in sources:
        image = cv2.imread(str(source), cv2.IMREAD_COLOR)
        if image is None:
            raise ConfigError(f"cannot read source image {source}")
        images.append(image)
    rng = np.random.default_rng(seed)
    for sub in ("1", "2", "h"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    records = []
    for source, image in zip(sources, images):
        size = (image.shape[1], image.shape[0])
        for config in CONFIGS:
            for tilt in tilts:
                name = f"{source_name(source)}_{config}{tilt:g}"
                cameras = pair_cameras(config, tilt, rng)
                maps, canvases = [], []
                for k, camera in enumerate(cameras):
                    homography, canvas = fit_canvas(camera_homography(size, camera), size, max_side)
                    path = out / str(k + 1) / f"{name}.png"
                    if not cv2.imwrite(str(path), render(image, homography, canvas)):
                        raise OSError(f"cannot write {path}")
                    maps.append(homography)
                    canvases.append(canvas)
                gt = maps[1] @ np.linalg.inv(maps[0])
                np.savetxt(out / "h" / f"{name}.txt", gt / gt[2, 2])
                records.append({"name": name, "source": str(source), "config": config, "transition_tilt": tilt,
                                "cameras": [asdict(c) for c in cameras], "sizes": canvases})
    (out / "pairs.json").write_text(json.dumps(records, indent=1))
    return records
