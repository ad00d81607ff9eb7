"""The benchmark's pairs and the methods' predictions on them: pair names, the pairs of the datasets with their
rotated variants, images, one prediction in the original frame, and a saved prediction read back."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.code_version import UNKNOWN, code_version
from slime_match.eval.datasets import Pair, load_dataset, rotated_pair
from slime_match.io import load_image, load_npz
from slime_match.resize import resize_image


def pair_slug(name: str) -> str:
    """File-system safe name of a pair."""
    return re.sub(r"[^A-Za-z0-9+@._-]", "_", name.replace("/", "__"))


def collect_pairs(config: BenchConfig) -> list[tuple[str, Pair]]:
    """(dataset spec, pair) for every dataset, with the rotated variants right after each original pair."""
    out = []
    for spec in config.datasets:
        pairs = load_dataset(spec, config.data_root)[: config.max_pairs]
        for pair in pairs:
            pair = replace(pair, name=f"{spec.split(':')[0]}/{pair.name}")
            out.append((spec, pair))
            if config.rotations and pair.kind in config.rotate_kinds and pair.kind != "disparity":
                # rotate the RGB float image so that every method sees the same colours as the original
                rgb = replace(pair, image1=load_image(pair.image1))
                out.extend((spec, rotated_pair(rgb, angle)) for angle in config.rotations)
    return out


def load_pair_images(pair: Pair) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) float32 RGB images of a pair in their original frame."""
    return load_image(pair.image0), load_image(pair.image1)


def predict(method, pair: Pair, images: tuple[np.ndarray, np.ndarray]) -> dict[str, np.ndarray]:
    """Run a method on a pair under the protocol resize; keypoints come back in the original frame, with the
    matching seconds, the :func:`code_version` that computed them and, for the package's methods, the adaptive
    choices of the run (``decisions``: the vote, the views tried; JSON text)."""
    (im0, frame0), (im1, frame1) = (resize_image(im, pair.max_side, pair.size) for im in images)
    xy0, xy1, scores, seconds = method(im0, im1)
    return {
        "decisions": np.str_(json.dumps(getattr(method, "last_decisions", {}))),
        "keypoints0": frame0.to_original(np.asarray(xy0, np.float64).reshape(-1, 2)),
        "keypoints1": frame1.to_original(np.asarray(xy1, np.float64).reshape(-1, 2)),
        "scores": np.asarray(scores, np.float64).reshape(-1),
        "seconds": np.float64(seconds),
        "code": np.str_(code_version()),
    }


_PREDICTION_ARRAYS = ("keypoints0", "keypoints1", "scores", "seconds")


def _load_prediction(path: Path) -> dict[str, np.ndarray]:
    data = load_npz(path, "saved prediction", _PREDICTION_ARRAYS, hint="; delete it to recompute")
    return {k: data[k] for k in _PREDICTION_ARRAYS} | {"code": data.get("code", np.str_(UNKNOWN)),
                                                      "decisions": data.get("decisions", np.str_("{}"))}
