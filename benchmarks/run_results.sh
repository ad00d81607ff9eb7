#!/usr/bin/env bash
# Produces docs/results.md: the hard sets (EVD and WxBS) scored by their own protocols (OpenCV MAGSAC++ on
# the raw matches), then the methods on the planar data (graf, the two HPatches sequences, each pair also
# rotated by 90 deg = non-upright pairs) and the non-planar data (the 15 ScanNet sample pairs with pose AUC,
# the Middlebury motorcycle stereo pair), with times.
#
#   benchmarks/run_results.sh [extra slime-bench options, e.g. --device cuda]
#
# About two hours on 2 CPU cores (the 15 hard pairs about 70 minutes, the 46 planar and non-planar pairs about
# 50; the Slime presets take 10-40 s a pair and up to 150 s where simulated views are tried and dropped, DISK
# alone about 40 s); run it on a quiet machine, as the report
# gives seconds per pair. Resumable: predictions are cached in $OUT/predictions and $OUT_HARD/predictions
# with the code version that computed them, so an interrupted run continues where it stopped and a rerun
# only recomputes metrics. Every method runs at its default settings; the main table gives each method at
# its best post-processing RANSAC threshold, stated in its column.
# Environment: OUT (results folder, default results/full), OUT_HARD (default results/hard), METHODS and
# HARD_METHODS (';'-separated method specs; the learned bases, ALIKED, DISK and XFeat alone and under Slime
# by default, need their weights in TORCH_HOME: scripts/fetch_learned_weights.py; add e.g. slime-keynet;keynet;slime-upright
# to METHODS for the other bases), ROTATIONS (default 90), DATA (data folder, default $SLIME_MATCH_DATA or
# ../shared/data), TORCH_HOME (network weights).
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ -z "${TORCH_HOME:-}" && -d ../shared/weights ]]; then
  export TORCH_HOME="$(cd ../shared/weights && pwd)"
fi
DATA="${DATA:-${SLIME_MATCH_DATA:-../shared/data}}"
OUT="${OUT:-results/full}"
OUT_HARD="${OUT_HARD:-results/hard}"
METHODS="${METHODS:-slime;hz+;slime-rootsift;rootsift;opencv-sift;aliked-lg;slime-aliked}"
ROTATIONS="${ROTATIONS:-90}"
HARD_METHODS="${HARD_METHODS:-slime;slime:views=off;hz+;asift;opencv-sift:rootsift=true,mutual=true;aliked-lg;slime-aliked;disk-lg;slime:base=disk-lg,max_keypoints=3072,views=off;xfeat-lg;slime:base=xfeat-lg,max_keypoints=3072,views=off}"
python -m slime_match.eval.bench "evd:$DATA/hard/evd" "wxbs:$DATA/hard/wxbs" --thresholds none --map-pairs 0 \
    --seed 0 --methods "$HARD_METHODS" -o "$OUT_HARD" "$@"
python -m slime_match.eval.bench graf hpatches scannet-sample motorcycle --data-root "$DATA" \
    --rotations "$ROTATIONS" --thresholds none,5,3,2,1 --seed 0 --methods "$METHODS" -o "$OUT" "$@"
python -m slime_match.eval.report "$OUT" --extra "$OUT_HARD" --doc docs/results.md --data-root "$DATA" \
  --command "benchmarks/run_results.sh $*"
