"""`slime pairs` on this machine against the same pairs on a Ray cluster: the 45 pairs of ten Sacré-Cœur photos
(every pair), weight-free Slime, local ``--workers 2`` against two Ray actors on a local cluster of two 1-CPU
nodes (on the loopback address), the matches compared pair by pair.

    python benchmarks/bench_ray.py --data DATA [--workers 2] [--method rootsift] [--out results/bench_ray.json]

``--method`` runs another preset instead (the base RootSIFT alone: a shorter run, in which the per-pair
overhead weighs more).

``DATA`` holds ``sacre_coeur``. Each run is timed from the call of ``match_pairs`` to its return (the workers'
or actors' start, model loading and the compiled loops' cache included; the Ray nodes are started before).
A run's overhead per pair is the workers' time not spent in the matcher, over the pairs:
(wall seconds x workers - the pairs' matcher seconds) / pairs; Ray's overhead per pair is the Ray run's minus
the local run's. The JSON has both runs, the overheads and how many pairs gave identical matches.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")  # read when ray loads: nodes on 127.0.0.1
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # a throw-away cluster on the loopback address

import numpy as np
import ray
from ray.cluster_utils import Cluster

from slime_match import make_config
from slime_match.runs.batch import match_pairs, read_pairs
from slime_match.runs.pair_lists import make_pairs, write_pairs

WEIGHT_FREE = {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift"}


def _run(label: str, config, out: Path, workers: int, **options) -> dict:
    """One timed match_pairs run of ``config`` into ``out``."""
    start = time.perf_counter()
    records = match_pairs(config, options.pop("jobs"), out, workers=workers, progress=False, **options)
    wall = time.perf_counter() - start
    matcher = sum(r["seconds"] for r in records if r["status"] == "done")
    run = {"backend": label, "workers": workers, "seconds": round(wall, 2), "matcher_seconds": round(matcher, 2),
           "pairs": len(records), "done": sum(r["status"] == "done" for r in records),
           "overhead_per_pair_s": round((wall * workers - matcher) / len(records), 3)}
    print(json.dumps(run), flush=True)
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="folder with sacre_coeur")
    parser.add_argument("--workers", type=int, default=2, help="local workers, and Ray nodes of 1 CPU (default 2)")
    parser.add_argument("--method", default="slime", help="slime (weight-free, the default) or another preset")
    parser.add_argument("--out", type=Path, default=Path("results/bench_ray.json"))
    args = parser.parse_args()
    config = make_config("slime", **WEIGHT_FREE) if args.method == "slime" else make_config(args.method)
    images = args.data / "sacre_coeur"
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        write_pairs(folder / "pairs.txt", make_pairs(images, "exhaustive"))
        jobs = read_pairs(folder / "pairs.txt", images)
        local = _run("local", config, folder / "local", args.workers, jobs=jobs)
        start = time.perf_counter()
        cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
        try:
            for _ in range(args.workers - 1):
                cluster.add_node(num_cpus=1)
            ray.init(address=cluster.address, logging_level="WARNING")
            cluster.wait_for_nodes()
            cluster_seconds = time.perf_counter() - start
            remote = _run("ray", config, folder / "ray", args.workers, jobs=jobs, backend="ray")
        finally:
            ray.shutdown()
            cluster.shutdown()
        identical = 0
        for job in jobs:
            a, b = (np.load(folder / run / job.folder / "matches.npz") for run in ("local", "ray"))
            identical += all(np.array_equal(a[key], b[key]) for key in a.files)
    summary = {"method": args.method, "pairs": len(jobs), "local": local, "ray": remote, "ray_cluster_start_s": round(cluster_seconds, 2),
               "ray_overhead_per_pair_s": round(remote["overhead_per_pair_s"] - local["overhead_per_pair_s"], 3),
               "identical_matches": identical, "cpus": os.cpu_count(), "load_average": os.getloadavg()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
