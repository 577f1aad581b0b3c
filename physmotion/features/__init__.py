"""Motion features: HumanML3D's 263-d vector (joints <-> features), BioMoDiffuse's 329-d, normalisation."""

from physmotion.features.biomech import FEATURE_DIM_BIOMECH, SLICES_BIOMECH, extract_features_329, to_263
from physmotion.features.humanml3d import (
    FEATURE_DIM,
    SLICES,
    UNIFORM_OFFSETS,
    extract_features,
    mirror_features,
    recover_from_ric,
    recover_from_rot,
    recover_root_rot_pos,
)
from physmotion.features.normalize import Normalizer, compute_mean_std

__all__ = [
    "FEATURE_DIM",
    "FEATURE_DIM_BIOMECH",
    "SLICES",
    "SLICES_BIOMECH",
    "UNIFORM_OFFSETS",
    "Normalizer",
    "compute_mean_std",
    "extract_features",
    "extract_features_329",
    "mirror_features",
    "recover_from_ric",
    "recover_from_rot",
    "recover_root_rot_pos",
    "to_263",
]
