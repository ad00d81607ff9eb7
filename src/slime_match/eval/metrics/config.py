"""Metric parameters shared by every metric module: :class:`MetricConfig` and its paper defaults."""

from __future__ import annotations

from dataclasses import dataclass

from slime_match._runtime.options import config_from_dict


@dataclass
class MetricConfig:
    """Metric parameters (paper defaults).

    Attributes:
        t_perp: correctness / coverage / mAA threshold in px (paper: 15).
        gt_radius: radius in px of the GT-correspondence neighbourhood checked by the non-planar test.
        gt_neighbours: number of nearest GT correspondences used for the local affine flow model.
        gt_flow_neighbours: nearest GT correspondences whose flow alone may vouch for a match.
        accuracy_step: grid step in px of the valid points sampled by the epipolar accuracy.
        accuracy_col_step: strip width in px of the line-area integration of the epipolar accuracy.
        pose_thresholds: AUC thresholds in degrees (LoFTR protocol).
    """

    t_perp: float = 15.0
    gt_radius: float = 50.0
    gt_neighbours: int = 8
    gt_flow_neighbours: int = 2
    accuracy_step: int = 8
    accuracy_col_step: int = 4
    pose_thresholds: tuple[float, ...] = (5.0, 10.0, 20.0)

    @classmethod
    def from_options(cls, **options: object) -> MetricConfig:
        """Config with some fields overridden; unknown names raise ConfigError."""
        return config_from_dict(cls, options)


DEFAULTS = MetricConfig()
