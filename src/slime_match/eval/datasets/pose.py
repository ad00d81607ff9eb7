"""Readers of relative-pose datasets: a SuperGlue-style ScanNet pair list, MegaDepth-1500, ScanNet-1500."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slime_match.errors import ConfigError
from slime_match.eval.datasets.files import read_image, require_dir
from slime_match.eval.datasets.pair import Pair, fundamental_from_pose, rotate_image, transform_view

MEGADEPTH_MAX_SIDE = 1200
SCANNET_SIZE = (640, 480)


def _pose_pair(name: str, image0: Path, image1: Path, K0: np.ndarray, K1: np.ndarray, R: np.ndarray,
               t: np.ndarray, **size: object) -> Pair:
    """A pose pair: intrinsics K0, K1 (3, 3), the pose of camera 1 from camera 0 (``X1 = R X0 + t``) and the F they
    give; ``size`` is ``Pair``'s ``size`` or ``max_side``."""
    return Pair(name, image0, image1, "pose", F=fundamental_from_pose(K0, K1, R, t), K0=K0, K1=K1, R=R, t=t,
                **size)


def read_scannet_pairs(pairs_file: Path | str, images_dir: Path | str | None = None) -> list[Pair]:
    """SuperGlue-style pair list: ``name0 name1 rot0 rot1 K0(9) K1(9) T_0to1(16)`` (row-major).

    Non-zero ``rot`` counts rotate that image by ``np.rot90(image, rot)`` with the GT updated. Pairs keep
    the ScanNet protocol size 640x480 (``Pair.size``).
    """
    pairs_file = Path(pairs_file)
    if not pairs_file.is_file():
        raise FileNotFoundError(f"ScanNet pair list {pairs_file} does not exist")
    images_dir = require_dir(images_dir or pairs_file.parent / "images", "ScanNet images")
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
        pair = _pose_pair(f"{Path(f[0]).stem}-{Path(f[1]).stem}", images_dir / f[0], images_dir / f[1], K0, K1,
                          R, t, size=SCANNET_SIZE)
        for which, rot in ((0, int(f[2])), (1, int(f[3]))):
            if rot % 4:
                img, A = rotate_image(read_image(pair.image1 if which else pair.image0), 90 * rot)
                pair = transform_view(pair, which, img, A)
        pairs.append(pair)
    return pairs


def read_megadepth1500(images_root: Path | str, gt_dir: Path | str) -> list[Pair]:
    """MegaDepth-1500: LoFTR's scene npz files in ``gt_dir`` (listed by ``megadepth_test_1500.txt`` when
    present) and images under ``images_root`` (``images_root/Undistorted_SfM/...``). Longest side <= 1200."""
    images_root = require_dir(images_root, "MegaDepth images root")
    gt_dir = require_dir(gt_dir, "MegaDepth-1500 ground truth")
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
            pairs.append(_pose_pair(f"{scene}/{Path(paths[i]).stem}-{Path(paths[j]).stem}", images_root / paths[i],
                                    images_root / paths[j], K0, K1, R, t, max_side=MEGADEPTH_MAX_SIDE))
    if not pairs:
        raise FileNotFoundError(f"no MegaDepth-1500 scene files in {gt_dir}")
    return pairs


def read_scannet1500(images_root: Path | str, gt_dir: Path | str) -> list[Pair]:
    """ScanNet-1500: ``gt_dir/test.npz`` (``name`` (N, 4) scene, sub-scene, stem0, stem1; ``rel_pose``
    (N, 12) T_0to1) and ``gt_dir/intrinsics.npz`` (K per scene, for 640x480 images); images are
    ``images_root/scene%04d_%02d/color/<stem>.jpg`` (the 640x480 test images)."""
    images_root = require_dir(images_root, "ScanNet images root")
    gt_dir = require_dir(gt_dir, "ScanNet-1500 ground truth")
    d, intr = np.load(gt_dir / "test.npz"), np.load(gt_dir / "intrinsics.npz")
    pairs = []
    for (sc, sub, s0, s1), rel in zip(
        d["name"].astype(int), d["rel_pose"].reshape(-1, 3, 4).astype(np.float64)
    ):
        scene = f"scene{sc:04d}_{sub:02d}"
        K = np.asarray(intr[scene], np.float64)
        R, t = rel[:, :3], rel[:, 3]
        color = images_root / scene / "color"
        pairs.append(_pose_pair(f"{scene}/{s0}-{s1}", color / f"{s0}.jpg", color / f"{s1}.jpg", K, K.copy(), R, t,
                                size=SCANNET_SIZE))
    return pairs
