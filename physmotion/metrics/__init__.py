"""Physical plausibility metrics (PhysDiff, EDGE/Morph, BioMoDiffuse) and the body surface they use."""

from physmotion.metrics.geometry import DEFAULT_BODY, BodyGeometry, BodySurface, lowest_surface_height
from physmotion.metrics.physical import (
    METRICS,
    MIN_FRAMES,
    PARAMS,
    MetricInfo,
    MetricParams,
    acceleration_consistency,
    clip_ratio,
    float_,
    float_ratio,
    format_table,
    imitation_failure_rate,
    mpjpe,
    penetrate,
    penetration_ratio,
    per_motion_metrics,
    pfc,
    phys_err,
    physical_metrics,
    skate,
    skating_ratio,
    smoothness,
    speed,
    velocity_consistency,
)

__all__ = [
    "DEFAULT_BODY", "METRICS", "MIN_FRAMES", "PARAMS", "BodyGeometry", "BodySurface", "MetricInfo",
    "MetricParams", "acceleration_consistency", "clip_ratio", "float_", "float_ratio", "format_table",
    "imitation_failure_rate", "lowest_surface_height", "mpjpe", "penetrate", "penetration_ratio",
    "per_motion_metrics", "pfc", "phys_err", "physical_metrics", "skate", "skating_ratio", "smoothness",
    "speed", "velocity_consistency",
]  # fmt: skip
