"""Readers of evaluation datasets: each yields :class:`Pair` objects with their ground truth.

Conventions: pixel coordinates are ``(x, y)`` with the centre of the top-left pixel at ``(0, 0)``; every
ground-truth quantity refers to the image files as stored (the "original frame"). ``H`` maps image 0 to
image 1, ``F`` satisfies ``x1^T F x0 = 0``, ``(R, t)`` maps camera-0 coordinates to camera-1 coordinates
(``X1 = R X0 + t``), masks are boolean with True = excluded.

Protocol resizing (MegaDepth longest side <= 1200 px, ScanNet 640x480) is described by ``Pair.max_side`` /
``Pair.size``; :func:`slime_match.resize.resize_image` resizes an image accordingly and returns the factors
that :func:`slime_match.resize.to_original` uses to bring coordinates back to the original frame.
"""

from __future__ import annotations

import logging
import math
import os
import re
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import scipy.linalg

from slime_match.errors import ConfigError
from slime_match.io import IMAGE_EXTS
from slime_match.resize import to_original_matrix

logger = logging.getLogger("slime_match")

KINDS = ("homography", "fundamental", "pose", "disparity")
MEGADEPTH_MAX_SIDE = 1200
SCANNET_SIZE = (640, 480)


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


def _read_matrix(path: Path) -> np.ndarray:
    m = np.loadtxt(path, dtype=np.float64)
    if m.shape != (3, 3):
        raise ConfigError(f"{path}: expected a 3x3 matrix, got shape {m.shape}")
    return m


def _read_image(image: Path | np.ndarray) -> np.ndarray:
    if isinstance(image, np.ndarray):
        return image
    img = cv2.imread(str(image), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FileNotFoundError(f"cannot read image {image}")
    return img


def _read_mask(path: Path) -> np.ndarray | None:
    if not path.is_file():
        return None
    m = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if m is None:
        raise FileNotFoundError(f"cannot read mask {path}")
    return m > 0


def _find_image(folder: Path, stem: str) -> Path | None:
    for ext in IMAGE_EXTS:
        for cand in (folder / f"{stem}{ext}", folder / f"{stem}{ext.upper()}"):
            if cand.is_file():
                return cand
    return None


def _require_dir(path: Path | str, what: str) -> Path:
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{what}: folder {path} does not exist")
    return path


# ----------------------------------------------------------------------------------------------------------
# intrinsics of a protocol-resized frame


def scale_intrinsics(K: np.ndarray, scale: tuple[float, float]) -> np.ndarray:
    """(3, 3) intrinsics of the resized frame, given original-frame ``K`` and (sx, sy) = original/resized."""
    return np.linalg.inv(to_original_matrix(scale)) @ K


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
    original = _read_image(pair.image1)
    img, A = rotate_image(original, angle_deg)
    out = transform_view(pair, 1, img, A)
    mask1 = pair.mask1
    if mask1 is not None or abs(angle_deg / 90 - round(angle_deg / 90)) > 1e-12:
        mask1 = _rotate_mask(np.zeros(original.shape[:2], bool) if mask1 is None else mask1, angle_deg)
    suffix = f"{angle_deg:g}".replace(".", "p")
    return replace(out, name=f"{pair.name}@rot{suffix}", mask1=mask1)


# ----------------------------------------------------------------------------------------------------------
# planar readers


def read_planar(folder: Path | str) -> list[Pair]:
    """The paper's planar folder: ``<scene>{1..6}.png``, ``<scene>_H1<k>.txt`` (1 -> k), masks
    ``mask_<scene><k>.png`` (non-zero = exclude) and rotated variants ``<scene>rot<k>.png`` +
    ``<scene>rot_H1<k>.txt`` (reference image ``<scene>rot1.png`` if present, else ``<scene>1.png``)."""
    folder = _require_dir(folder, "planar dataset")
    pairs = []
    for hfile in sorted(folder.glob("*_H1*.txt")):
        m = re.fullmatch(r"(?P<scene>.+)_H1(?P<k>\d+)\.txt", hfile.name)
        if m is None:
            continue
        scene, k = m["scene"], m["k"]
        base = scene.removesuffix("rot")
        im0 = _find_image(folder, f"{scene}1") or _find_image(folder, f"{base}1")
        im1 = _find_image(folder, f"{scene}{k}")
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{hfile}: images {scene}1 / {scene}{k} not found in {folder}")
        mask0 = _read_mask(folder / f"mask_{scene}1.png")
        if mask0 is None:
            mask0 = _read_mask(folder / f"mask_{base}1.png")
        mask1 = _read_mask(folder / f"mask_{scene}{k}.png")
        pairs.append(
            Pair(f"{scene}/1-{k}", im0, im1, "homography", H=_read_matrix(hfile), mask0=mask0, mask1=mask1)
        )
    if not pairs:
        raise FileNotFoundError(f"no '<scene>_H1<k>.txt' homography files in {folder}")
    return pairs


def _read_hpatches_sequence(folder: Path) -> list[Pair]:
    pairs = []
    im0 = _find_image(folder, "1")
    for hfile in sorted(folder.glob("H_1_*")):
        k = hfile.name[4:]
        im1 = _find_image(folder, k)
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{hfile}: images 1 / {k} not found in {folder}")
        pairs.append(Pair(f"{folder.name}/1-{k}", im0, im1, "homography", H=_read_matrix(hfile)))
    return pairs


def read_hpatches(folder: Path | str) -> list[Pair]:
    """HPatches: one sequence folder (``1..6.ppm`` + ``H_1_k``) or a root of ``v_*`` / ``i_*`` folders."""
    folder = _require_dir(folder, "HPatches")
    seqs = (
        [folder]
        if any(folder.glob("H_1_*"))
        else sorted(p for p in folder.iterdir() if p.is_dir() and p.name[:2] in ("v_", "i_"))
    )
    pairs = [p for s in seqs for p in _read_hpatches_sequence(s)]
    if not pairs:
        raise FileNotFoundError(f"no HPatches sequences (folders v_*/i_* with H_1_k files) in {folder}")
    return pairs


def read_oxford(folder: Path | str) -> list[Pair]:
    """Oxford affine sequence: ``img1..imgK.*`` and ``H1toKp`` (1 -> K)."""
    folder = _require_dir(folder, "Oxford sequence")
    im0 = _find_image(folder, "img1")
    pairs = []
    for hfile in sorted(folder.glob("H1to*p")):
        k = hfile.name[4:-1]
        im1 = _find_image(folder, f"img{k}")
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{hfile}: images img1 / img{k} not found in {folder}")
        pairs.append(Pair(f"{folder.name}/1-{k}", im0, im1, "homography", H=_read_matrix(hfile)))
    if not pairs:
        raise FileNotFoundError(f"no H1to<k>p files in {folder}")
    return pairs


def read_evd(folder: Path | str) -> list[Pair]:
    """EVD-style: ``1/<name>.png``, ``2/<name>.png``, ``h/<name>.txt`` (3x3, 1 -> 2)."""
    folder = _require_dir(folder, "EVD dataset")
    hdir = _require_dir(folder / "h", "EVD dataset")
    pairs = []
    for hfile in sorted(hdir.glob("*.txt")):
        im0, im1 = _find_image(folder / "1", hfile.stem), _find_image(folder / "2", hfile.stem)
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{hfile}: images 1/{hfile.stem}.* or 2/{hfile.stem}.* not found")
        pairs.append(Pair(hfile.stem, im0, im1, "homography", H=_read_matrix(hfile)))
    if not pairs:
        raise FileNotFoundError(f"no homography files in {hdir}")
    return pairs


# ----------------------------------------------------------------------------------------------------------
# non-planar readers


def read_wxbs(folder: Path | str) -> list[Pair]:
    """WxBS-style: every folder (searched recursively) holding ``01.*``, ``02.*`` and ``corrs.txt``
    (rows ``x0 y0 x1 y1``); F_gt is the normalised 8-point fit to all GT correspondences."""
    folder = _require_dir(folder, "WxBS dataset")
    pairs = []
    for cfile in sorted(folder.rglob("corrs.txt")):
        d = cfile.parent
        im0, im1 = _find_image(d, "01"), _find_image(d, "02")
        if im0 is None or im1 is None:
            raise FileNotFoundError(f"{d}: images 01.* / 02.* not found")
        corrs = np.loadtxt(cfile, dtype=np.float64, ndmin=2)
        if corrs.shape[1] != 4:
            raise ConfigError(f"{cfile}: expected rows 'x0 y0 x1 y1', got {corrs.shape[1]} columns")
        name = d.relative_to(folder).as_posix() if d != folder else d.name
        pairs.append(Pair(name, im0, im1, "fundamental", F=fundamental_from_corrs(corrs), corrs=corrs))
    if not pairs:
        raise FileNotFoundError(f"no WxBS pair folders (01.*, 02.*, corrs.txt) under {folder}")
    return pairs


def read_scannet_pairs(pairs_file: Path | str, images_dir: Path | str | None = None) -> list[Pair]:
    """SuperGlue-style pair list: ``name0 name1 rot0 rot1 K0(9) K1(9) T_0to1(16)`` (row-major).

    Non-zero ``rot`` counts rotate that image by ``np.rot90(image, rot)`` with the GT updated. Pairs keep
    the ScanNet protocol size 640x480 (``Pair.size``).
    """
    pairs_file = Path(pairs_file)
    if not pairs_file.is_file():
        raise FileNotFoundError(f"ScanNet pair list {pairs_file} does not exist")
    images_dir = _require_dir(images_dir or pairs_file.parent / "images", "ScanNet images")
    pairs = []
    for line in pairs_file.read_text().splitlines():
        f = line.split()
        if not f:
            continue
        if len(f) != 38:
            raise ConfigError(f"{pairs_file}: expected 38 fields per line, got {len(f)}")
        v = np.asarray(f[4:], np.float64)
        K0, K1, T = v[:9].reshape(3, 3), v[9:18].reshape(3, 3), v[18:].reshape(4, 4)
        R, t = T[:3, :3], T[:3, 3]
        pair = Pair(
            f"{Path(f[0]).stem}-{Path(f[1]).stem}",
            images_dir / f[0],
            images_dir / f[1],
            "pose",
            F=fundamental_from_pose(K0, K1, R, t),
            K0=K0,
            K1=K1,
            R=R,
            t=t,
            size=SCANNET_SIZE,
        )
        for which, rot in ((0, int(f[2])), (1, int(f[3]))):
            if rot % 4:
                img, A = rotate_image(_read_image(pair.image1 if which else pair.image0), 90 * rot)
                pair = transform_view(pair, which, img, A)
        pairs.append(pair)
    return pairs


def read_megadepth1500(images_root: Path | str, gt_dir: Path | str) -> list[Pair]:
    """MegaDepth-1500: LoFTR's scene npz files in ``gt_dir`` (listed by ``megadepth_test_1500.txt`` when
    present) and images under ``images_root`` (``images_root/Undistorted_SfM/...``). Longest side <= 1200."""
    images_root = _require_dir(images_root, "MegaDepth images root")
    gt_dir = _require_dir(gt_dir, "MegaDepth-1500 ground truth")
    listing = gt_dir / "megadepth_test_1500.txt"
    names = listing.read_text().split() if listing.is_file() else sorted(p.stem for p in gt_dir.glob("*.npz"))
    pairs = []
    for scene in names:
        d = np.load(gt_dir / f"{scene}.npz", allow_pickle=True)
        paths, Ks, poses = d["image_paths"], d["intrinsics"], d["poses"]
        for info in d["pair_infos"]:
            i, j = (int(v) for v in info[0])
            T = poses[j] @ np.linalg.inv(poses[i])
            K0, K1 = np.asarray(Ks[i], np.float64), np.asarray(Ks[j], np.float64)
            R, t = T[:3, :3], T[:3, 3]
            pairs.append(
                Pair(
                    f"{scene}/{Path(paths[i]).stem}-{Path(paths[j]).stem}",
                    images_root / paths[i],
                    images_root / paths[j],
                    "pose",
                    F=fundamental_from_pose(K0, K1, R, t),
                    K0=K0,
                    K1=K1,
                    R=R,
                    t=t,
                    max_side=MEGADEPTH_MAX_SIDE,
                )
            )
    if not pairs:
        raise FileNotFoundError(f"no MegaDepth-1500 scene files in {gt_dir}")
    return pairs


def read_scannet1500(images_root: Path | str, gt_dir: Path | str) -> list[Pair]:
    """ScanNet-1500: ``gt_dir/test.npz`` (``name`` (N, 4) scene, sub-scene, stem0, stem1; ``rel_pose``
    (N, 12) T_0to1) and ``gt_dir/intrinsics.npz`` (K per scene, for 640x480 images); images are
    ``images_root/scene%04d_%02d/color/<stem>.jpg`` (the 640x480 test images)."""
    images_root = _require_dir(images_root, "ScanNet images root")
    gt_dir = _require_dir(gt_dir, "ScanNet-1500 ground truth")
    d, intr = np.load(gt_dir / "test.npz"), np.load(gt_dir / "intrinsics.npz")
    pairs = []
    for (sc, sub, s0, s1), rel in zip(
        d["name"].astype(int), d["rel_pose"].reshape(-1, 3, 4).astype(np.float64)
    ):
        scene = f"scene{sc:04d}_{sub:02d}"
        K = np.asarray(intr[scene], np.float64)
        R, t = rel[:, :3], rel[:, 3]
        pairs.append(
            Pair(
                f"{scene}/{s0}-{s1}",
                images_root / scene / "color" / f"{s0}.jpg",
                images_root / scene / "color" / f"{s1}.jpg",
                "pose",
                F=fundamental_from_pose(K, K, R, t),
                K0=K,
                K1=K.copy(),
                R=R,
                t=t,
                size=SCANNET_SIZE,
            )
        )
    return pairs


def read_motorcycle() -> list[Pair]:
    """scikit-image's Middlebury motorcycle stereo pair (arrays) with its left disparity map."""
    from skimage.data import stereo_motorcycle

    left, right, disp = stereo_motorcycle()
    F = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]) / math.sqrt(2)
    return [Pair("motorcycle", left, right, "disparity", F=F, disparity=disp.astype(np.float32))]


# ----------------------------------------------------------------------------------------------------------
# dispatcher


def default_data_root() -> Path:
    """Folder of the bundled test data: ``$SLIME_MATCH_DATA`` or ``<repository>/../shared/data``."""
    env = os.environ.get("SLIME_MATCH_DATA")
    if env:
        return Path(env)
    repo = Path(__file__).resolve().parents[3]
    for cand in (repo.parent / "shared" / "data", Path.cwd().parent / "shared" / "data"):
        if cand.is_dir():
            return cand
    raise FileNotFoundError("data folder not found: pass root= or set SLIME_MATCH_DATA")


def load_dataset(spec: str, root: Path | str | None = None) -> list[Pair]:
    """Pairs of a dataset named by ``spec``.

    Specs: "graf", "hpatches", "scannet-sample", "motorcycle" (bundled data under ``root``, default
    :func:`default_data_root`); "planar:<dir>", "hpatches:<dir>", "oxford:<dir>", "evd:<dir>", "wxbs:<dir>";
    "megadepth1500:<images_root>", "scannet1500:<images_root>" (GT from ``root/gt_1500``).
    """
    name, _, arg = spec.partition(":")
    name = name.strip().lower()
    readers = {
        "planar": read_planar,
        "hpatches": read_hpatches,
        "oxford": read_oxford,
        "evd": read_evd,
        "wxbs": read_wxbs,
    }
    if name in readers and arg:
        return readers[name](arg)
    if name == "motorcycle":
        return read_motorcycle()
    if name in ("megadepth1500", "scannet1500"):
        if not arg:
            raise ConfigError(f"{name} needs an images root: '{name}:<images_root>'")
        base = Path(root) if root is not None else default_data_root()
        if name == "megadepth1500":
            return read_megadepth1500(arg, base / "gt_1500" / "megadepth")
        return read_scannet1500(arg, base / "gt_1500" / "scannet")
    bundled = {
        "graf": lambda r: read_oxford(r / "oxford_graf"),
        "hpatches": lambda r: read_hpatches(r / "hpatches"),
        "scannet-sample": lambda r: read_scannet_pairs(r / "scannet_sample" / "pairs_with_gt.txt"),
    }
    if name in bundled and not arg:
        return bundled[name](Path(root) if root is not None else default_data_root())
    known = sorted(set(readers) | set(bundled) | {"motorcycle", "megadepth1500", "scannet1500"})
    raise ConfigError(
        f"unknown dataset spec {spec!r}; known: {', '.join(known)} (folder formats need ':<dir>')"
    )
