"""Options of a ``slime bench`` run (paper defaults) and their validation."""

from __future__ import annotations

from dataclasses import dataclass, field

from slime_match.choices import PAPER_METHODS
from slime_match.errors import ConfigError
from slime_match.eval import metrics as M
from slime_match.eval.methods import method_label, parse_method_spec


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
        data_root: root of the bundled data (None: ``$SLIME_MATCH_DATA``, see ``datasets.load.default_data_root``).
        protocol_datasets: dataset names (spec before ':') whose pairs are also scored by the standard
            protocol of their ground truth (:mod:`slime_match.eval.metrics.protocols`): EVD for homography
            pairs, WxBS for pairs with GT correspondences.
        protocol_h_threshold: MAGSAC++ threshold in px of the EVD protocol's homography.
        protocol_f_threshold: MAGSAC++ threshold in px of the WxBS protocol's fundamental matrix.
        protocol_max_iters: MAGSAC++ iterations of both protocols.
        protocol_orders: orders of the matches each protocol is run on (the given one and random
            permutations): the pair's ``maa_mean`` is the mean over them (its RANSAC draws samples by index).
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
    protocol_datasets: list[str] = field(default_factory=lambda: ["evd", "wxbs"])
    protocol_h_threshold: float = 3.0
    protocol_f_threshold: float = 3.0
    protocol_max_iters: int = 10000
    protocol_orders: int = 10

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
        if not (self.protocol_h_threshold > 0 and self.protocol_f_threshold > 0):
            raise ConfigError("protocol MAGSAC++ thresholds must be > 0 px")
        if self.protocol_max_iters < 1:
            raise ConfigError(f"protocol_max_iters must be >= 1, got {self.protocol_max_iters}")
        if self.protocol_orders < 1:
            raise ConfigError(f"protocol_orders must be >= 1, got {self.protocol_orders}")
        return self
