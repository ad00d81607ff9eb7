"""``slime bench``: run methods over dataset pairs, cache predictions, evaluate the paper's metrics.

Flow (export predictions first, evaluate the cache): for every pair and method the raw matches are loaded
from ``<out>/predictions/<method>/<pair>.npz`` or computed and saved there (:mod:`slime_match.eval.predictions`);
then every RANSAC post-processing threshold is applied and the pair is scored (:mod:`slime_match.eval.scoring`:
correct matches, precision, coverage, accuracy error, pose errors); finally :mod:`slime_match.eval.report`
writes the tables and charts, and :mod:`slime_match.eval.figures` the maps of the first pairs.
Rerunning with the same output folder only recomputes the metrics.

Per-pair, per-method, per-threshold quantities (stored in ``metrics.json``):
    n_matches, n_correct, precision (correct / matches with a ground-truth verdict), coverage (paper,
    ``t_perp`` disk), error (accuracy error in px: homography reprojection or epipolar area / diagonal,
    of the model fitted to the kept matches; inf without a model), pose_errors (pose pairs: max angular
    error in degrees per essential-matrix RANSAC threshold, LoFTR protocol).
Pairs of the ``protocol_datasets`` are also scored by the standard protocol of the hard sets on the raw
matches (pair field ``protocol``: "evd", "wxbs" or None; per method ``protocol``: pair mAA and the error or
recall curve, :mod:`slime_match.eval.metrics.protocols`).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import re
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from tqdm import tqdm

from slime_match.errors import ConfigError
from slime_match.eval import bench_args
from slime_match.eval.bench_config import BenchConfig
from slime_match.eval.code_version import code_version
from slime_match.eval.methods import make_method, method_label
from slime_match.eval.predictions import _load_prediction, collect_pairs, load_pair_images, pair_slug, predict
from slime_match.eval.scoring import evaluate_pair, evaluate_protocol, pair_gt, pair_protocol
from slime_match.io import save_json, save_npz
from slime_match.output_folder import replacing_owned_files

logger = logging.getLogger("slime_match")

METRICS_FILE = "metrics.json"
MAPS_FOLDER = "maps"
REPORT_FILES = (METRICS_FILE, "table.md", "table.csv", "bar_*.png",  # all replaced by each run
                f"{MAPS_FOLDER}/*/coverage_*.png", f"{MAPS_FOLDER}/*/error_*.png")


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
        "output": results folder, "protocols": the standard-protocol summary of
        :func:`slime_match.eval.aggregation.aggregate`}.
    """
    from slime_match.eval import report

    config.validate()
    out = Path(config.output)
    pairs = collect_pairs(config)
    if not pairs:
        raise ConfigError(f"no pairs in {config.datasets}")
    with replacing_owned_files(out, REPORT_FILES, last=METRICS_FILE) as staging:  # predictions/ is a cache
        records, stats = _score_pairs(config, pairs, out, staging / MAPS_FOLDER)
        _warn_stale(records, out)
        summary = _finite({
            "config": asdict(config),
            "methods": {method_label(s): s for s in config.methods},
            "written": time.strftime("%Y-%m-%d %H:%M:%S"),
            "pairs": records,
        })
        save_json(staging / METRICS_FILE, summary)
        agg = report.write_report(staging, summary)
    logger.info("bench: %d predictions computed, %d loaded from %s", stats["computed"], stats["cached"], out)
    return {**stats, "pairs": len(pairs), "output": str(out), "protocols": agg["protocols"]}


def _score_pairs(config: BenchConfig, pairs: list, out: Path, map_dir: Path
                 ) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """Predict (or load from ``out``'s cache) and score every pair: the per-pair records of ``metrics.json``
    and the counts of predictions computed and cached; maps of the first pairs go under ``map_dir``."""
    from slime_match.eval import figures

    labels = {spec: method_label(spec) for spec in config.methods}
    methods: dict[str, Any] = {}  # built lazily, only when a prediction is missing
    records, stats = [], {"computed": 0, "cached": 0}
    progress = tqdm(
        total=len(pairs) * len(config.methods), desc="bench", unit="pred", file=sys.stderr, disable=None
    )
    for index, (spec, pair) in enumerate(pairs):
        images = load_pair_images(pair)
        raw, seconds, code, views = {}, {}, {}, {}
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
            views[label] = json.loads(str(pred["decisions"])).get("views")
            progress.update()
        gt = pair_gt(pair, images)
        per_method, extras = evaluate_pair(gt, raw, config)
        protocol = pair_protocol(spec, gt, config)
        scores = evaluate_protocol(protocol, gt, raw, config) if protocol else {}
        records.append(
            {
                "name": pair.name,
                "dataset": spec,
                "kind": pair.kind,
                "group": "planar" if gt.planar else "non-planar",
                "upright": "@rot" not in pair.name,
                "protocol": protocol,
                "methods": {
                    lab: {
                        "seconds": seconds[lab],
                        "code": code[lab],
                        "raw_matches": len(raw[lab][0]),
                        **({"views": views[lab]} if views.get(lab) else {}),
                        "thresholds": per_method[lab],
                        **({"protocol": scores[lab]} if lab in scores else {}),
                    }
                    for lab in per_method
                },
            }
        )
        if index < config.map_pairs:
            figures.write_pair_maps(map_dir / pair_slug(pair.name), images, gt, extras, config.t_perp)
    progress.close()
    return records, stats


def _finite(obj: Any) -> Any:
    """JSON has no inf: store infinite errors as None (read back as inf by the report)."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def _csv(text: str) -> list[str]:
    return [s.strip() for s in text.split(",") if s.strip()]


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
        protocol_datasets=[s.lower() for s in _csv(args.protocol_datasets)],
        protocol_h_threshold=args.protocol_h_threshold,
        protocol_f_threshold=args.protocol_f_threshold,
        protocol_max_iters=args.protocol_max_iters,
        protocol_orders=args.protocol_orders,
    ).validate()


def cmd_bench(args: argparse.Namespace) -> int:
    """Run ``slime bench`` from parsed arguments; prints where the tables are."""
    stats = run_bench(config_from_args(args))
    print(
        f"{stats['pairs']} pairs: {stats['computed']} predictions computed, {stats['cached']} cached "
        f"-> {stats['output']}/table.md"
    )
    for (dataset, method), v in stats["protocols"].items():
        empty = f" ({', '.join(v['no_match_pairs'])})" if v["no_match_pairs"] else ""
        print(
            f"{dataset} {method}: {v['protocol'].upper()} mAA {v['maa']:.2f} ({v['maa_mean']:.2f} over "
            f"{args.protocol_orders} orders of the matches), {v['solved']}/{v['pairs']} pairs solved, "
            f"{len(v['no_match_pairs'])} without matches{empty}"
        )
    return 0


def add_bench_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``bench`` on a ``subparsers`` object, running :func:`cmd_bench`."""
    return bench_args.add_bench_parser(subparsers, cmd_bench)


def main(argv: list[str] | None = None) -> int:
    """``python -m slime_match.eval.bench ...`` (same arguments as ``slime bench``)."""
    parser = argparse.ArgumentParser(prog="slime")
    add_bench_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["bench", *(sys.argv[1:] if argv is None else argv)])
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s: %(message)s")
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
