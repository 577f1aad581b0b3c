"""Physics: the MuJoCo humanoid and retargeting between joint positions and its qpos.

- :mod:`~physmotion.physics.frames`: our Y-up world <-> MuJoCo's Z-up world (one mapping).
- :mod:`~physmotion.physics.humanoid`: ``HumanoidConfig``, ``build_mjcf`` / ``build_model``, ``layout``.
- :mod:`~physmotion.physics.retarget`: ``joints_to_qpos``, ``qpos_to_joints``, ``qvel_from_qpos``.

MuJoCo is imported lazily (only ``build_model`` and ``layout`` need it), so the rest of the package
imports without it.
"""

from physmotion.physics.frames import from_mujoco, to_mujoco
from physmotion.physics.humanoid import (
    HumanoidConfig,
    PDGain,
    build_mjcf,
    build_model,
    foot_lift,
    layout,
    standing_height,
)
from physmotion.physics.retarget import NQ, NV, joints_to_qpos, qpos_to_joints, qpos_to_local, qvel_from_qpos

__all__ = [
    "NQ",
    "NV",
    "HumanoidConfig",
    "PDGain",
    "build_mjcf",
    "build_model",
    "foot_lift",
    "from_mujoco",
    "joints_to_qpos",
    "layout",
    "qpos_to_joints",
    "qpos_to_local",
    "qvel_from_qpos",
    "standing_height",
    "to_mujoco",
]
