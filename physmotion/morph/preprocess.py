"""Morph's pre-processing of generated motions before the physics projection (App. A, Alg. 1): a lean of
the first frame over 10 degrees undone, then the first frame's lowest body point onto the floor. Morph
applies it to the synthetic data and at inference (``generate --physics morph``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physmotion.conventions import FPS, UP_AXIS
from physmotion.skeleton import FOOT_JOINTS, swing_rotation


@dataclass
class PreprocessConfig:
    """Morph's pre-processing of generated motions before P (App. A, Alg. 1)."""

    tilt: bool = True  # undo a lean of the first frame over max_tilt_deg
    max_tilt_deg: float = 10.0
    floor: bool = True  # the first frame's lowest body point onto the floor


def tilt_angle(joints: np.ndarray) -> float:
    """Lean (degrees) of the first frame: the angle between the vertical and the line from the centre
    of the feet to the pelvis (Alg. 1, step 1). joints: (T, 22, 3), Y up."""
    v = joints[0, 0] - joints[0, list(FOOT_JOINTS)].mean(axis=0)
    up = np.eye(3)[UP_AXIS]
    cos = float(np.dot(v, up) / max(np.linalg.norm(v), 1e-9))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def correct_tilt(joints: np.ndarray, max_deg: float = 10.0) -> tuple[np.ndarray, float]:
    """Morph's tilt correction (App. A, Alg. 1 steps 1-2).

    Alg. 1 measures the angle between the vertical through the centre of mass's ground projection and the
    line from the pelvis to the centre of the feet, in the first frame only, and where it exceeds 10
    degrees "applies an additional rotation to the pelvis for the entire sequence". We take the pelvis as
    the centre of mass (no body masses are generated), the mean of ankles and toes as the centre of the
    feet, and the correction as the smallest rotation that makes that first-frame line vertical, applied to
    every frame's pose about that frame's pelvis: the root orientation turns, the root's path is kept
    (rotating the whole sequence about a fixed point would tilt a walk's path into the floor).

    joints: (T, 22, 3) metres, Y up. Returns (joints (T, 22, 3) same dtype, the angle measured in degrees).
    """
    x = np.asarray(joints, dtype=np.float64)
    angle = tilt_angle(x)
    if not angle > max_deg:
        return np.asarray(joints), angle
    v = x[0, 0] - x[0, list(FOOT_JOINTS)].mean(axis=0)
    rot = swing_rotation(v / np.linalg.norm(v), np.eye(3)[UP_AXIS])
    pelvis = x[:, :1]
    out = pelvis + (x - pelvis) @ rot.T
    return out.astype(np.asarray(joints).dtype), angle


def floor_first_frame(joints: np.ndarray, fps: float = FPS, physical: bool = False) -> np.ndarray:
    """Alg. 1 step 3: the whole motion moved up or down so that the lowest point of the body in the first
    frame touches the floor.

    The body is the humanoid P simulates (:class:`~physmotion.physics.surface.HumanoidSurface` on
    :func:`~physmotion.physics.humanoid.body_from_joints`), and the result is in the convention P expects
    (data convention: soles ``foot_lift`` under the toe joints, which P raises back), so P's soles start on
    the floor; with ``physical`` the lowest point itself is put at y = 0 (an output's convention, as P's
    simulated motions). joints: (T, 22, 3); returns (T, 22, 3), same dtype.
    """
    from physmotion.physics.humanoid import body_from_joints, foot_lift
    from physmotion.physics.surface import HumanoidSurface

    x = np.asarray(joints, dtype=np.float64)
    body = body_from_joints(x, fps)
    low = float(HumanoidSurface(body).lowest_height(x[:1], floor=-np.inf)[0])  # toes as posed: just touching
    shift = np.zeros(3)
    shift[UP_AXIS] = -low - (0.0 if physical else foot_lift(body))
    return (x + shift).astype(np.asarray(joints).dtype)


def preprocess(joints: np.ndarray, config: PreprocessConfig, fps: float = FPS) -> np.ndarray:
    """Morph's pre-processing (App. A): tilt correction, then the first frame onto the floor.
    joints: (T, 22, 3) -> (T, 22, 3) float32."""
    x = np.asarray(joints, dtype=np.float64)
    if config.tilt:
        x, _ = correct_tilt(x, config.max_tilt_deg)
    if config.floor:
        x = floor_first_frame(x, fps)
    return x.astype(np.float32)
