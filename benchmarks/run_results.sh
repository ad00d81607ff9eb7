#!/usr/bin/env bash
# Produces docs/results.md: every method of the registry on the planar data (graf, the two HPatches
# sequences, each pair also rotated by 90/180/270 deg = non-upright pairs) and the non-planar data
# (the 15 ScanNet sample pairs with pose AUC, the Middlebury motorcycle stereo pair), with times.
#
#   benchmarks/run_results.sh [extra slime-bench options, e.g. --device cuda]
#
# Slow on a CPU (Slime and Slimed Key.Net take up to about a minute per pair); resumable: predictions are
# cached in $OUT/predictions, so an interrupted run continues where it stopped and a rerun only recomputes
# metrics (about 10 min for the whole cache here).
# Environment: OUT (results folder, default results/full), DESCRIPTOR (Hz+/Slime/Key.Net descriptor: tfeat where
# HardNet's weights are absent, as on the project machines; auto elsewhere), METHODS (';'-separated method
# specs, default: the paper's set and OpenCV SIFT; the registry's slime-fast, loftr and the learned bases
# (aliked-lg, disk-lg, xfeat-lg and their -nn variants) are left out: add them with
# METHODS="...;loftr;aliked-lg", their weights in TORCH_HOME, see scripts/fetch_learned_weights.py),
# TORCH_HOME (kornia weights).
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ -z "${TORCH_HOME:-}" && -d ../shared/weights ]]; then
  export TORCH_HOME="$(cd ../shared/weights && pwd)"
fi
OUT="${OUT:-results/full}"
[[ -n "${METHODS:-}" ]] && METHODS_NOTE=", METHODS=$METHODS"
D="${DESCRIPTOR:-tfeat}"
ALL="rootsift;rootsift-upright;slime-rootsift;keynet:descriptor=$D;keynet-upright:descriptor=$D"
ALL="$ALL;slime-keynet:descriptor=$D;slime-keynet-upright:descriptor=$D;hz+:descriptor=$D;hz+-upright:descriptor=$D"
METHODS="${METHODS:-$ALL;slime:descriptor=$D;slime-upright:descriptor=$D;opencv-sift}"
CMD=(python -m slime_match.eval.bench graf hpatches scannet-sample motorcycle --rotations 90,180,270
     --thresholds none,5,3,2,1 --seed 0 --methods "$METHODS" -o "$OUT" "$@")
"${CMD[@]}"
python -m slime_match.eval.report "$OUT" --doc docs/results.md \
  --command "benchmarks/run_results.sh $* (DESCRIPTOR=$D${METHODS_NOTE:-})"
