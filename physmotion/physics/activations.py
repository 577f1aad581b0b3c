"""Muscle activations of a motion without EMG: joint effort of the humanoid that follows it.

BioMoDiffuse conditions on muscle activations from a pose-to-EMG encoder (its MIA model) that we cannot
have: neither its weights nor paired EMG data are available. The joint torques our MuJoCo humanoid needs
to follow the motion stand in for them: the inverse dynamics of the reference with the foot contact
forces split out (:func:`physmotion.physics.tracking.prepare_reference`), grouped into
:data:`ACTIVATION_CHANNELS` and divided by the actuators' torque limits. Those torques are clipped at
the limits, so an activation of 1 means the joint is saturated. No simulation runs, so the result is
deterministic and does not depend on whether a tracker could follow the motion
(docs/decisions/biomodiffuse.md: "muscle activations from inverse dynamics").
"""

from __future__ import annotations

import numpy as np

from physmotion.conventions import FPS
from physmotion.errors import ShapeError
from physmotion.physics.humanoid import HumanoidConfig, body_from_joints, build_model, foot_lift, layout
from physmotion.physics.retarget import joints_to_qpos
from physmotion.physics.tracking import prepare_reference
from physmotion.skeleton import JOINT_INDEX, NUM_JOINTS

ACTIVATION_CHANNELS: tuple[str, ...] = (
    "left_hip", "right_hip", "left_knee", "right_knee",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
)  # fmt: skip
"""One channel per joint: the effort of its three hinges together."""

_MIN_FRAMES = 3  # central differences for velocity and acceleration need a frame on each side


def activations(joints: np.ndarray, fps: float = FPS, config: HumanoidConfig | None = None) -> np.ndarray:
    """Per-frame activation of each channel of :data:`ACTIVATION_CHANNELS`.

    joints: (T, 22, 3) metres, Y up, the data convention (floor at the lowest joint), T >= 3.
    fps: frames per second of ``joints``. config: the humanoid (default ``HumanoidConfig()``).
    Returns (T, 8) float32 in [0, 1]: per channel, the root mean square over the joint's three hinges
    of |torque| / torque limit, the torques being the inverse dynamics of the motion's own humanoid
    (bone lengths from the motion) with the feet carrying the root wrench.
    """
    x = _check_joints(joints)
    if not (np.isfinite(fps) and fps > 0):
        raise ShapeError(f"fps must be a positive number, got {fps}")
    offsets = body_from_joints(x, fps)
    model = build_model(offsets, config)
    qpos = joints_to_qpos(x, model, lift=foot_lift(offsets, config), config=config)
    tau = prepare_reference(model, qpos, 1.0 / fps).tau_ff  # (T, nv), hinges clipped at their limits
    dof = layout(model).hinge_dof[[JOINT_INDEX[c] for c in ACTIVATION_CHANNELS]]  # (8, 3)
    effort = np.abs(tau[:, dof]) / _torque_limits(model)[dof]  # (T, 8, 3)
    out = np.sqrt(np.mean(effort**2, axis=-1))
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def _torque_limits(model) -> np.ndarray:
    """(nv,) torque limit (N m) of the actuator on each dof; inf on the unactuated root."""
    limits = np.full(model.nv, np.inf)
    dof = model.jnt_dofadr[model.actuator_trnid[:, 0]]
    limits[dof] = np.abs(model.actuator_forcerange[:, 1])
    return limits


def _check_joints(joints: np.ndarray) -> np.ndarray:
    x = np.asarray(joints, dtype=np.float64)
    if x.ndim != 3 or x.shape[1:] != (NUM_JOINTS, 3):
        raise ShapeError(f"joints must have shape (T, {NUM_JOINTS}, 3), got {x.shape}")
    if x.shape[0] < _MIN_FRAMES:
        raise ShapeError(f"joints need at least {_MIN_FRAMES} frames for accelerations, got {x.shape[0]}")
    if not np.all(np.isfinite(x)):
        raise ShapeError("joints contain NaN or infinite values")
    return x
