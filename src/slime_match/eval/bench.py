"""``slime bench``: run methods over dataset pairs, cache predictions, evaluate the paper's metrics.

Flow (export predictions first, evaluate the cache): for every pair and method the raw matches are loaded
from ``<out>/predictions/<method>/<pair>.npz`` or computed and saved there; then every RANSAC
post-processing threshold is applied and the pair is scored (correct matches, precision, coverage,
accuracy error, pose errors); finally :mod:`slime_match.eval.report` writes the tables, charts and maps.
Rerunning with the same output folder only recomputes the metrics.

Per-pair, per-method, per-threshold quantities (stored in ``metrics.json``):
    n_matches, n_correct, precision (correct / matches with a ground-truth verdict), coverage (paper,
    ``t_perp`` disk), error (accuracy error in px: homography reprojection or epipolar area / diagonal,
    of the model fitted to the kept matches; inf without a model), pose_errors (pose pairs: max angular
    error in degrees per essential-matrix RANSAC threshold, LoFTR protocol).
"""

from __future__ import annotations

import argparse
import logging
import math
import re
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from slime_match.errors import ConfigError
from slime_match.eval import metrics as M
from slime_match.eval.code_version import UNKNOWN, code_version
from slime_match.eval.datasets import Pair, load_dataset, rotated_pair
from slime_match.eval.methods import PAPER_METHODS, make_method, method_label, parse_method_spec
from slime_match.geometry.backends import estimate_geometry
from slime_match.geometry.fundamental import fundamental_8point
from slime_match.geometry.homography import homography_dlt
from slime_match.io import load_image, load_npz, save_json, save_npz
from slime_match.resize import resize_image

logger = logging.getLogger("slime_match")

PLANAR_KINDS = ("homography",)
DISPARITY_GT_STEP = 8  # px grid of the disparity map used as GT correspondences (coverage normaliser)


@dataclass
class BenchConfig:
    """Options of a benchmark run (paper defaults).

    Attributes:
        datasets: dataset specs of :func:`slime_match.eval.datasets.load_dataset`.
        methods: method specs of :mod:`slime_match.eval.methods`.
        output: results folder.
        thresholds: post-processing RANSAC thresholds in px; "none" = raw matches.
        rotations: angles in degrees (counter-clockwise) of the rotated variants added for each pair.
        rotate_kinds: pair kinds that get rotated variants (the paper rotates planar pairs).
        max_pairs: keep the first N pairs of each dataset (before rotations); None = all.
        seed: seed of the methods and of every RANSAC.
        device: "auto" | "cpu" | "cuda", for the methods.
        ransac_backend: "slime" (the paper's RANSACs) | "magsac" | "poselib".
        essential_thresholds: px thresholds of the pose (essential matrix) RANSAC, pose pairs only.
        t_perp: correctness / coverage / mAA threshold in px.
        homography_step: grid step in px of the planar accuracy error.
        map_pairs: pairs (the first N) that get coverage and error maps.
        data_root: root of the bundled data (None: ``$SLIME_MATCH_DATA`` or ``../shared/data``).
    """

    datasets: list[str] = field(default_factory=lambda: ["graf"])
    methods: list[str] = field(default_factory=lambda: list(PAPER_METHODS))
    output: str = "results"
    thresholds: list[str] = field(default_factory=lambda: ["none", "5", "3", "2", "1"])
    rotations: list[float] = field(default_factory=list)
    rotate_kinds: list[str] = field(default_factory=lambda: ["homography"])
    max_pairs: int | None = None
    seed: int = 0
    device: str = "auto"
    ransac_backend: str = "slime"
    essential_thresholds: list[float] = field(default_factory=lambda: [0.5, 1.0, 2.0, 3.0])
    t_perp: float = M.DEFAULTS.t_perp
    homography_step: int = 2
    map_pairs: int = 2
    data_root: str | None = None

    def validate(self) -> BenchConfig:
        if not self.methods:
            raise ConfigError("no methods given")
        for spec in self.methods:
            parse_method_spec(spec)
        labels = [method_label(s) for s in self.methods]
        if len(set(labels)) != len(labels):
            raise ConfigError(f"duplicate methods in {self.methods}")
        for th in self.thresholds:
            if th != "none" and not float(th) > 0:
                raise ConfigError(f"RANSAC thresholds must be 'none' or > 0 px, got {th!r}")
        if not self.thresholds:
            raise ConfigError("no RANSAC thresholds given")
        if self.ransac_backend not in ("slime", "magsac", "poselib"):
            raise ConfigError(f"unknown RANSAC backend {self.ransac_backend!r}")
        return self


# ----------------------------------------------------------------------------------------------------------
# pairs and images


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
    matching seconds and the :func:`code_version` that computed them."""
    (im0, frame0), (im1, frame1) = (resize_image(im, pair.max_side, pair.size) for im in images)
    xy0, xy1, scores, seconds = method(im0, im1)
    return {
        "keypoints0": frame0.to_original(np.asarray(xy0, np.float64).reshape(-1, 2)),
        "keypoints1": frame1.to_original(np.asarray(xy1, np.float64).reshape(-1, 2)),
        "scores": np.asarray(scores, np.float64).reshape(-1),
        "seconds": np.float64(seconds),
        "code": np.str_(code_version()),
    }


# ----------------------------------------------------------------------------------------------------------
# per-pair evaluation


@dataclass
class PairGT:
    """Ground truth of a pair in the form the metrics need (shapes are (H, W))."""

    pair: Pair
    shape0: tuple[int, int]
    shape1: tuple[int, int]
    gt_corrs: np.ndarray | None = None

    @property
    def planar(self) -> bool:
        return self.pair.kind in PLANAR_KINDS


def pair_gt(pair: Pair, images: tuple[np.ndarray, np.ndarray]) -> PairGT:
    """Shapes and GT correspondences (given ones, or a grid of the disparity map for stereo pairs)."""
    corrs = pair.corrs
    if pair.kind == "disparity":
        d = pair.disparity
        rows, cols = np.mgrid[0 : d.shape[0] : DISPARITY_GT_STEP, 0 : d.shape[1] : DISPARITY_GT_STEP]
        dv = d[rows, cols]
        ok = np.isfinite(dv) & (cols - dv >= 0)
        corrs = np.stack([cols[ok], rows[ok], cols[ok] - dv[ok], rows[ok]], 1).astype(np.float64)
    return PairGT(pair, images[0].shape[:2], images[1].shape[:2], corrs)


def correct_mask(gt: PairGT, x0: np.ndarray, x1: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """(K,) correct matches and (K,) matches with a GT verdict (False only for unknown disparity)."""
    p = gt.pair
    if p.kind == "homography":
        return M.correct_matches_homography(x0, x1, p.H, t, p.mask0, p.mask1), np.ones(len(x0), bool)
    if p.kind == "disparity":
        err = M.disparity_error(x0, x1, p.disparity)
        with np.errstate(invalid="ignore"):
            return err < t, np.isfinite(err)
    return M.correct_matches_fundamental(x0, x1, p.F, t, gt.gt_corrs), np.ones(len(x0), bool)


def filter_matches(
    x0: np.ndarray, x1: np.ndarray, threshold: str, kind: str, backend: str, seed: int
) -> tuple[np.ndarray, np.ndarray | None, str]:
    """Post-processing: (K,) kept mask, the (3, 3) model fitted to the kept matches (None if impossible)
    and its kind. "none" keeps all and fits least squares (normalised DLT / 8-point) to all of them."""
    keep = np.ones(len(x0), bool)
    model, model_kind = None, kind
    if threshold != "none":
        geo = estimate_geometry(x0, x1, kind, backend=backend, threshold=float(threshold), seed=seed)
        keep, model, model_kind = np.asarray(geo.inliers, bool), geo.model, geo.kind
    if kind == "fundamental" and model_kind != "fundamental":
        model = None  # planar degeneracy of a fundamental RANSAC: refit F below
    if model is None:
        n_min = 4 if kind == "homography" else 8
        if keep.sum() >= n_min:
            fit = homography_dlt if kind == "homography" else fundamental_8point
            model = fit(x0[keep], x1[keep])[0]
    return keep, model, kind


def _accuracy_error(gt: PairGT, model: np.ndarray | None, valid, step: int) -> float:
    if model is None:
        return math.inf
    if gt.planar:
        return M.homography_accuracy_error(model, gt.pair.H, valid[0], valid[1], step)
    return M.fundamental_accuracy_error(model, gt.pair.F, valid[0], valid[1])


def valid_areas(gt: PairGT, raw: dict[str, tuple[np.ndarray, np.ndarray]], t: float):
    """Coverage normalisers: planar = GT-mappable pixels; non-planar = dilated union of every method's
    correct raw matches plus the GT correspondences (whole images when that union is empty)."""
    p = gt.pair
    if gt.planar:
        return M.valid_area_homography(p.H, gt.shape0, gt.shape1, p.mask0, p.mask1)
    c0, c1 = [], []
    for x0, x1 in raw.values():
        ok = correct_mask(gt, x0, x1, t)[0]
        c0.append(x0[ok])
        c1.append(x1[ok])
    v0, v1 = M.valid_area_nonplanar(c0, c1, gt.shape0, gt.shape1, gt.gt_corrs, t)
    if not v0.any() or not v1.any():
        v0, v1 = np.ones(gt.shape0, bool), np.ones(gt.shape1, bool)
    return v0, v1


def evaluate_pair(
    gt: PairGT, raw: dict[str, tuple[np.ndarray, np.ndarray]], config: BenchConfig
) -> tuple[dict[str, dict[str, dict[str, Any]]], dict[str, Any]]:
    """Metrics of every method and threshold on one pair.

    Args:
        gt: the pair's ground truth.
        raw: method label -> (keypoints0 (K, 2), keypoints1 (K, 2)) raw matches, original frame.

    Returns:
        method -> threshold -> metrics dict, and the per-pair extras the maps need (valid areas, and per
        method and threshold the kept matches, correct mask and model).
    """
    t = config.t_perp
    valid = valid_areas(gt, raw, t)
    kind = "homography" if gt.planar else "fundamental"
    out: dict[str, dict[str, dict[str, Any]]] = {}
    extras: dict[str, Any] = {"valid": valid, "kept": {}}
    for label, (x0, x1) in raw.items():
        out[label] = {}
        for th in config.thresholds:
            keep, model, _ = filter_matches(x0, x1, th, kind, config.ransac_backend, config.seed)
            k0, k1 = x0[keep], x1[keep]
            ok, known = correct_mask(gt, k0, k1, t)
            n_known = int(known.sum())
            rec = {
                "n_matches": len(k0),
                "n_correct": int(ok.sum()),
                "precision": float(ok.sum() / n_known) if n_known else 0.0,
                "coverage": M.coverage(k0[ok], k1[ok], gt.shape0, gt.shape1, valid[0], valid[1], t),
                "error": _accuracy_error(gt, model, valid, config.homography_step),
                "model": None if model is None else np.asarray(model).tolist(),
            }
            if gt.pair.kind == "pose":
                sweep = M.pose_errors_sweep(
                    k0, k1, gt.pair.K0, gt.pair.K1, gt.pair.R, gt.pair.t, tuple(config.essential_thresholds)
                )
                rec["pose_errors"] = {f"{k:g}": v for k, v in sweep.items()}
            out[label][th] = rec
            extras["kept"][(label, th)] = (k0, k1, ok, model)
    return out, extras


# ----------------------------------------------------------------------------------------------------------
# driver


_PREDICTION_ARRAYS = ("keypoints0", "keypoints1", "scores", "seconds")


def _load_prediction(path: Path) -> dict[str, np.ndarray]:
    data = load_npz(path, "saved prediction", _PREDICTION_ARRAYS, hint="; delete it to recompute")
    return {k: data[k] for k in _PREDICTION_ARRAYS} | {"code": data.get("code", np.str_(UNKNOWN))}


def _warn_stale(records: list[dict[str, Any]], out: Path) -> None:
    """Log the methods whose predictions (per-pair ``records`` of ``run_bench``) come from code other than
    the running one."""
    for label in records[0]["methods"]:
        stale = [r["methods"][label]["code"] for r in records if r["methods"][label]["code"] != code_version()]
        if stale:
            logger.warning(
                "bench: %d predictions of %s come from code %s, not the running %s; delete %s to recompute",
                len(stale), label, ", ".join(sorted(set(stale))), code_version(), out / "predictions" / label,
            )


def run_bench(config: BenchConfig) -> dict[str, Any]:
    """Run (or resume) a benchmark and write every output under ``config.output``.

    Returns:
        {"computed": predictions computed now, "cached": predictions loaded, "pairs": number of pairs,
        "output": results folder}.
    """
    from slime_match.eval import report

    config.validate()
    out = Path(config.output)
    pairs = collect_pairs(config)
    if not pairs:
        raise ConfigError(f"no pairs in {config.datasets}")
    labels = {spec: method_label(spec) for spec in config.methods}
    methods: dict[str, Any] = {}  # built lazily, only when a prediction is missing
    records, stats = [], {"computed": 0, "cached": 0}
    map_dir = out / "maps"
    progress = tqdm(
        total=len(pairs) * len(config.methods), desc="bench", unit="pred", file=sys.stderr, disable=None
    )
    for index, (spec, pair) in enumerate(pairs):
        images = load_pair_images(pair)
        raw, seconds, code = {}, {}, {}
        for mspec in config.methods:
            label = labels[mspec]
            path = out / "predictions" / label / f"{pair_slug(pair.name)}.npz"
            progress.set_postfix_str(f"{label} {pair.name}")
            if path.is_file():
                pred = _load_prediction(path)
                stats["cached"] += 1
            else:
                if mspec not in methods:
                    methods[mspec] = make_method(mspec, device=config.device, seed=config.seed)
                pred = predict(methods[mspec], pair, images)
                save_npz(path, **pred)
                stats["computed"] += 1
            raw[label] = (pred["keypoints0"], pred["keypoints1"])
            seconds[label] = float(pred["seconds"])
            code[label] = str(pred["code"])
            progress.update()
        gt = pair_gt(pair, images)
        per_method, extras = evaluate_pair(gt, raw, config)
        records.append(
            {
                "name": pair.name,
                "dataset": spec,
                "kind": pair.kind,
                "group": "planar" if gt.planar else "non-planar",
                "upright": "@rot" not in pair.name,
                "methods": {
                    lab: {
                        "seconds": seconds[lab],
                        "code": code[lab],
                        "raw_matches": len(raw[lab][0]),
                        "thresholds": per_method[lab],
                    }
                    for lab in per_method
                },
            }
        )
        if index < config.map_pairs:
            report.write_pair_maps(map_dir / pair_slug(pair.name), images, gt, extras, config.t_perp)
    progress.close()
    _warn_stale(records, out)
    started = time.strftime("%Y-%m-%d %H:%M:%S")
    summary = {
        "config": asdict(config),
        "methods": {labels[s]: s for s in config.methods},
        "written": started,
        "pairs": records,
    }
    summary = _finite(summary)
    save_json(out / "metrics.json", summary)
    report.write_report(out, summary)
    logger.info("bench: %d predictions computed, %d loaded from %s", stats["computed"], stats["cached"], out)
    return {**stats, "pairs": len(pairs), "output": str(out)}


def _finite(obj: Any) -> Any:
    """JSON has no inf: store infinite errors as None (read back as inf by the report)."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


# ----------------------------------------------------------------------------------------------------------
# command line


def _csv(text: str) -> list[str]:
    return [s.strip() for s in text.split(",") if s.strip()]


def add_bench_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``bench`` on a ``subparsers`` object (``slime bench``); sets ``func`` to :func:`cmd_bench`."""
    p = subparsers.add_parser(
        "bench",
        help="run methods over datasets and write the paper's metric tables",
        description="Run methods over datasets, cache predictions (resumable) and write tables, charts "
        "and maps. Method specs: name[:key=value,...], e.g. 'hz+:descriptor=tfeat'.",
    )
    p.add_argument(
        "datasets",
        nargs="+",
        help="dataset specs: graf, hpatches, scannet-sample, motorcycle, "
        "planar:<dir>, hpatches:<dir>, oxford:<dir>, evd:<dir>, wxbs:<dir>, megadepth1500:<root>, "
        "scannet1500:<root>",
    )
    p.add_argument(
        "--methods",
        default=",".join(PAPER_METHODS),
        help="comma- or space-separated method specs (default: the paper's set); "
        "separate specs with options by ';'",
    )
    p.add_argument("-o", "--output", default="results", help="results folder")
    p.add_argument("--thresholds", default="none,5,3,2,1", help="post-processing RANSAC thresholds (px)")
    p.add_argument("--rotations", default="", help="rotated variants to add, degrees, e.g. 90,180,270")
    p.add_argument("--rotate-kinds", default="homography", help="pair kinds that get rotated variants")
    p.add_argument("--max-pairs", type=int, default=None, help="first N pairs of each dataset")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="auto", choices=["auto", "cpu", "cuda"])
    p.add_argument("--ransac-backend", default="slime", choices=["slime", "magsac", "poselib"])
    p.add_argument("--map-pairs", type=int, default=2, help="pairs that get coverage/error maps")
    p.add_argument("--data-root", default=None, help="root of the bundled data (default ../shared/data)")
    p.set_defaults(func=cmd_bench)
    return p


def _split_methods(text: str) -> list[str]:
    """';' separates specs when any spec has options (their options use ','); else ',' or spaces."""
    if ";" in text or ":" in text:
        return [s.strip() for s in text.split(";") if s.strip()]
    return [s for s in re.split(r"[,\s]+", text) if s]


def config_from_args(args: argparse.Namespace) -> BenchConfig:
    """BenchConfig of parsed ``bench`` arguments."""
    return BenchConfig(
        datasets=list(args.datasets),
        methods=_split_methods(args.methods),
        output=args.output,
        thresholds=_csv(args.thresholds),
        rotations=[float(a) for a in _csv(args.rotations)],
        rotate_kinds=_csv(args.rotate_kinds),
        max_pairs=args.max_pairs,
        seed=args.seed,
        device=args.device,
        ransac_backend=args.ransac_backend,
        map_pairs=args.map_pairs,
        data_root=args.data_root,
    ).validate()


def cmd_bench(args: argparse.Namespace) -> int:
    """Run ``slime bench`` from parsed arguments; prints where the tables are."""
    stats = run_bench(config_from_args(args))
    print(
        f"{stats['pairs']} pairs: {stats['computed']} predictions computed, {stats['cached']} cached "
        f"-> {stats['output']}/table.md"
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m slime_match.eval.bench ...`` (same arguments as ``slime bench``)."""
    parser = argparse.ArgumentParser(prog="slime")
    add_bench_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["bench", *(sys.argv[1:] if argv is None else argv)])
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s: %(message)s")
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
