"""Our Y-up world <-> MuJoCo's Z-up world: one axis mapping, used everywhere in ``physics``.

Ours (:mod:`physmotion.conventions`): x = the body's left, y = up, z = forward.
MuJoCo (the humanoid of :mod:`physmotion.physics.humanoid`): x = forward, y = left, z = up.

    mj = (z, x, y) of ours            ours = (y, z, x) of mj

This is a cyclic permutation of the axes, i.e. a proper rotation ``P`` (det +1): handedness, cross
products and quaternion conventions carry over unchanged. A rotation matrix ``R`` of ours is
``P R P^T`` in MuJoCo, and a quaternion (w, v) becomes (w, P v).

Everything here is indexing only, so it works on numpy arrays and torch tensors alike, batched over
leading dimensions.
"""

from __future__ import annotations

from typing import Any

import numpy as np

_TO_MJ = [2, 0, 1]  # mj[i] = ours[_TO_MJ[i]]
_FROM_MJ = [1, 2, 0]  # ours[i] = mj[_FROM_MJ[i]]

MJ_FROM_OURS = np.eye(3)[_TO_MJ]
"""P (3, 3): ``p_mj = MJ_FROM_OURS @ p_ours``."""


def to_mujoco(p: Any) -> Any:
    """Positions or vectors (..., 3) from our Y-up frame to MuJoCo's Z-up frame."""
    return p[..., _TO_MJ]


def from_mujoco(p: Any) -> Any:
    """Positions or vectors (..., 3) from MuJoCo's Z-up frame to our Y-up frame."""
    return p[..., _FROM_MJ]


def rot_to_mujoco(rot: Any) -> Any:
    """Rotation matrices (..., 3, 3) of ours to MuJoCo: P R P^T."""
    return rot[..., _TO_MJ, :][..., :, _TO_MJ]


def rot_from_mujoco(rot: Any) -> Any:
    """Rotation matrices (..., 3, 3) of MuJoCo to ours: P^T R P."""
    return rot[..., _FROM_MJ, :][..., :, _FROM_MJ]


def quat_to_mujoco(q: Any) -> Any:
    """Quaternions (..., 4), scalar first (w, x, y, z) as MuJoCo stores them, ours -> MuJoCo."""
    return q[..., [0, 1 + _TO_MJ[0], 1 + _TO_MJ[1], 1 + _TO_MJ[2]]]


def quat_from_mujoco(q: Any) -> Any:
    """Quaternions (..., 4), scalar first, MuJoCo -> ours."""
    return q[..., [0, 1 + _FROM_MJ[0], 1 + _FROM_MJ[1], 1 + _FROM_MJ[2]]]
