"""BioMoDiffuse's 329-d representation: HumanML3D's 263 features + 22 joint accelerations (22 x 3 = 66).

The paper (BioMoDiffuse, sec. 3.3 and the ablation "expanding the motion representation dimension from
263 to 329") supervises the joint accelerations Phi'' of the coordinate representation next to the 263
features, but does not print their formula. We define them to sit beside HumanML3D's ``local_vel``:

    joint_acc[t] = r_rot[t] (p[t+1] - 2 p[t] + p[t-1])      t = 1 .. T-2
    joint_acc[0] = r_rot[0] (p[2]   - 2 p[1] + p[0])        (one-sided: frame 1's second difference)

p: the canonical joints (those the 263 features encode); r_rot[t]: HumanML3D's root yaw of frame t, the
same frame that ``local_vel[t] = r_rot[t] (p[t+1] - p[t])`` is expressed in. So, for t >= 1,
``joint_acc[t]`` is the backward difference of the *global* velocities turned into the root frame of t:
central in time, and heading-invariant like the rest of the vector. Units: metres per frame^2 at the
clip's rate (20 fps), as ``local_vel`` is in metres per frame; multiply by fps^2 for m/s^2.

Layout: dims 0..262 are exactly :func:`physmotion.features.humanml3d.extract_features`'s, dims 263..328
are ``joint_acc`` (joint-major, xyz).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from physmotion.errors import ShapeError
from physmotion.features.humanml3d import FEATURE_DIM, SLICES, _extract, _rot_y
from physmotion.skeleton import NUM_JOINTS

FEATURE_DIM_BIOMECH = FEATURE_DIM + NUM_JOINTS * 3  # 329

SLICES_BIOMECH: dict[str, slice] = {**SLICES, "joint_acc": slice(FEATURE_DIM, FEATURE_DIM_BIOMECH)}
"""Named groups of the 329-d vector: HumanML3D's groups plus ``joint_acc`` (263:329)."""


def extract_features_329(
    joints: np.ndarray, *, uniform: bool = True, feet_thre: float = 0.002, floor: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """The 329-d features of a motion.

    joints: (T, 22, 3) metres, Y up, T >= 3 (an acceleration needs three frames). uniform, feet_thre,
    floor: as in :func:`~physmotion.features.humanml3d.extract_features`.
    Returns (features (T-1, 329) float32, canonical_joints (T, 22, 3) float32); ``features[:, :263]``
    equals ``extract_features(joints)[0]``. Raises ShapeError for bad input or fewer than 3 frames.
    """
    if isinstance(joints, np.ndarray) and joints.ndim == 3 and joints.shape[0] < 3:
        raise ShapeError(f"joints need at least 3 frames for accelerations, got {joints.shape[0]}")
    out = _extract(joints, uniform=uniform, feet_thre=feet_thre, floor=floor)
    acc = joint_accelerations(out.canonical, out.half_yaw)
    features = np.concatenate([out.features, acc.reshape(len(acc), -1)], axis=-1)
    return features.astype(np.float32), out.canonical.astype(np.float32)


def joint_accelerations(canonical: np.ndarray, half_yaw: np.ndarray) -> np.ndarray:
    """Joint accelerations (T-1, 22, 3) in the root frame of each frame (see the module doc).

    canonical: (T, 22, 3) canonical joints, T >= 3. half_yaw: (T,) half-angles a_t of the root rotations
    r_rot[t] = Ry(2 a_t) (what ``recover_root_rot_pos`` accumulates from ``root_rot_vel``).
    """
    second = canonical[2:] - 2.0 * canonical[1:-1] + canonical[:-2]  # centred at frames 1 .. T-2
    acc = np.concatenate([second[:1], second], axis=0)  # frame 0 borrows frame 1's
    return _rot_y(2.0 * half_yaw[:-1, None], acc)


def to_263(features329: Any) -> Any:
    """The HumanML3D part of 329-d features: (..., 329) -> (..., 263), numpy or torch (a view)."""
    dim = features329.shape[-1] if hasattr(features329, "shape") else None
    if dim != FEATURE_DIM_BIOMECH:
        raise ShapeError(f"features must have last dimension {FEATURE_DIM_BIOMECH}, got {dim}")
    return features329[..., :FEATURE_DIM]
