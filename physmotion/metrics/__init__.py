"""Physical plausibility metrics (PhysDiff, EDGE/Morph, BioMoDiffuse), the body surface they use, and the
HumanML3D generation metrics (R-Precision, MM-Dist, FID, Diversity, MultiModality)."""

from physmotion.metrics.generation import (
    confidence_interval,
    diversity,
    embedding_stats,
    fid,
    frechet_distance,
    multimodality,
    multimodality_per_text,
    r_precision,
)
from physmotion.metrics.geometry import DEFAULT_BODY, BodyGeometry, BodySurface, lowest_surface_height
from physmotion.metrics.physical import (
    METRIC_MIN_FRAMES,
    METRICS,
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
    ragged_physical_metrics,
    skate,
    skating_ratio,
    smoothness,
    speed,
    velocity_consistency,
)

__all__ = [
    "DEFAULT_BODY", "METRICS", "METRIC_MIN_FRAMES", "PARAMS", "BodyGeometry", "BodySurface", "MetricInfo",
    "MetricParams", "acceleration_consistency", "clip_ratio", "confidence_interval", "diversity",
    "embedding_stats", "fid", "float_", "float_ratio", "format_table", "frechet_distance",
    "imitation_failure_rate", "lowest_surface_height", "mpjpe", "multimodality", "multimodality_per_text",
    "penetrate", "penetration_ratio", "per_motion_metrics", "pfc", "phys_err", "physical_metrics",
    "r_precision", "ragged_physical_metrics", "skate",
    "skating_ratio", "smoothness", "speed", "velocity_consistency",
]  # fmt: skip
