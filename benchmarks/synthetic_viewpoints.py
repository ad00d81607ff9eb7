"""Write a synthetic EVD-style set of extreme-viewpoint pairs with exact ground truth
(:mod:`slime_match.eval.datasets.viewpoints`): a "side" and a "crossed" pair per source image and transition tilt,
to check on pairs nothing was tuned on how a method copes with foreshortening.

    python benchmarks/synthetic_viewpoints.py --data DATA --out OUT [--tilts 2,4,6] [--seed 0]
    slime bench evd:OUT --methods "slime-aliked;aliked-lg;asift" --thresholds none

``DATA`` holds ``oxford_graf`` and ``hpatches``: the default sources are graf's img1 and the first image of each
HPatches viewpoint sequence (``--sources`` takes other frontal images of planes).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from slime_match.errors import ConfigError
from slime_match.eval.datasets.viewpoints import write_viewpoint_set


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=Path("../shared/data"))
    parser.add_argument("--out", type=Path, required=True, help="EVD-style folder to write (1/, 2/, h/)")
    parser.add_argument("--sources", type=Path, nargs="*", help="frontal images of planes (default: see above)")
    parser.add_argument("--tilts", default="2,4,6", help="transition tilts, comma-separated (each > 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-side", type=int, default=800, help="longer side of each rendered image, px")
    args = parser.parse_args()
    sources = args.sources or [args.data / "oxford_graf" / "img1.png", *sorted(args.data.glob("hpatches/v_*/1.ppm"))]
    try:
        records = write_viewpoint_set(sources, args.out, [float(t) for t in args.tilts.split(",")], args.seed,
                                      args.max_side)
    except (ConfigError, OSError, ValueError) as error:
        raise SystemExit(f"error: {error}") from error
    print(f"{len(records)} pairs written to {args.out}")


if __name__ == "__main__":
    main()
