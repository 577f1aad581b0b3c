"""Test motions built on the default body by forward kinematics (no importer needed).

Joint angles follow a walking gait: 1 stride/s, hips +-26 deg in antiphase, knees flexing up to 60 deg in
swing, arms hanging and swinging against the legs, a little pelvis bob and spine twist, the root moving
forward at 1.2 m/s along its heading. Local rotations follow :mod:`physmotion.skeleton`'s convention.
"""

from __future__ import annotations

import numpy as np
import pytest

from physmotion.conventions import FPS
from physmotion.skeleton import JOINT_INDEX, NUM_JOINTS, REST_OFFSETS, forward_kinematics, rest_joints

J = JOINT_INDEX


def rot_x(a: np.ndarray) -> np.ndarray:
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([o, z, z, z, c, -s, z, s, c], -1).reshape(np.shape(a) + (3, 3))


def rot_y(a: np.ndarray) -> np.ndarray:
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([c, z, s, z, o, z, -s, z, c], -1).reshape(np.shape(a) + (3, 3))


def rot_z(a: np.ndarray) -> np.ndarray:
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([c, -s, z, s, c, z, z, z, o], -1).reshape(np.shape(a) + (3, 3))


def standing_rotations(n: int) -> np.ndarray:
    """(n, 22, 3, 3) local rotations of a relaxed stand: arms down along the body, elbows a bit bent."""
    local = np.broadcast_to(np.eye(3), (n, NUM_JOINTS, 3, 3)).copy()
    zeros = np.zeros(n)
    local[:, J["left_shoulder"]] = rot_z(zeros - 1.25)  # the arm points along +x at rest: bring it down
    local[:, J["right_shoulder"]] = rot_z(zeros + 1.25)
    local[:, J["left_elbow"]] = rot_y(zeros + 0.3)
    local[:, J["right_elbow"]] = rot_y(zeros - 0.3)
    return local


def pelvis_height(offsets: np.ndarray = REST_OFFSETS) -> float:
    return float(rest_joints(offsets)[0, 1])


def make_walk(
    n_frames: int = 120, *, turn_deg: float = 90.0, speed: float = 1.2, offsets: np.ndarray = REST_OFFSETS
) -> np.ndarray:
    """A walking clip (n_frames, 22, 3) at 20 fps, turning left by turn_deg over the clip."""
    t = np.arange(n_frames) / FPS
    phase = 2 * np.pi * 1.0 * t
    local = standing_rotations(n_frames)
    yaw = np.deg2rad(turn_deg) * t / t[-1]
    local[:, 0] = rot_y(yaw) @ rot_x(0.05 + 0.03 * np.sin(2 * phase))
    swing = 0.45 * np.sin(phase)
    local[:, J["left_hip"]] = rot_x(-swing)
    local[:, J["right_hip"]] = rot_x(swing)
    local[:, J["left_knee"]] = rot_x(0.5 * (1 + np.sin(phase - 0.6)) ** 1.5 / 2 ** 0.5)
    local[:, J["right_knee"]] = rot_x(0.5 * (1 + np.sin(phase + np.pi - 0.6)) ** 1.5 / 2 ** 0.5)
    local[:, J["left_ankle"]] = rot_x(0.15 * np.sin(phase + 0.8))
    local[:, J["right_ankle"]] = rot_x(-0.15 * np.sin(phase + 0.8))
    local[:, J["spine2"]] = rot_y(0.12 * np.sin(phase))
    local[:, J["head"]] = rot_x(0.1 * np.sin(0.5 * phase))
    local[:, J["left_shoulder"]] = local[:, J["left_shoulder"]] @ rot_y(0.35 * np.sin(phase))
    local[:, J["right_shoulder"]] = local[:, J["right_shoulder"]] @ rot_y(0.35 * np.sin(phase))

    heading = np.stack([np.sin(yaw), np.zeros_like(yaw), np.cos(yaw)], -1)
    root = np.cumsum(heading * speed / FPS, axis=0) + np.array([0.3, 0.0, -1.0])
    root[:, 1] = pelvis_height(offsets) - 0.03 + 0.02 * np.cos(2 * phase)
    return forward_kinematics(local, root, offsets)


def make_kick(n_frames: int = 60) -> np.ndarray:
    """Stand still for 20 frames, kick the right leg forward fast (frames 20-25), hold, put it back.

    The left foot never moves. (n_frames, 22, 3).
    """
    local = standing_rotations(n_frames)
    t = np.arange(n_frames)
    lift = np.clip((t - 20) / 5, 0, 1) - np.clip((t - 40) / 5, 0, 1)  # 0 -> 1 in 5 frames, back at 40
    local[:, J["right_hip"]] = rot_x(-1.2 * lift)
    root = np.zeros((n_frames, 3))
    root[:, 1] = pelvis_height()
    return forward_kinematics(local, root, REST_OFFSETS)


def make_spin(n_frames: int = 200, deg_per_frame: float = 4.0) -> np.ndarray:
    """A rigid standing body spinning in place about +Y (left turn) at a constant rate (n_frames, 22, 3)."""
    local = standing_rotations(n_frames)
    local[:, 0] = rot_y(np.deg2rad(deg_per_frame) * np.arange(n_frames))
    root = np.zeros((n_frames, 3))
    root[:, 1] = pelvis_height()
    return forward_kinematics(local, root, REST_OFFSETS)


@pytest.fixture(scope="session")
def walk() -> np.ndarray:
    return make_walk()


@pytest.fixture(scope="session")
def kick() -> np.ndarray:
    return make_kick()


@pytest.fixture(scope="session")
def spin() -> np.ndarray:
    return make_spin()
