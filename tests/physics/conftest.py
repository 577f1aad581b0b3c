"""Motions and models shared by the physics tests.

Synthetic motions are built with the skeleton's forward kinematics from walking-like local rotations
(a gait cycle: hip and knee flexion, ankle roll-over, arm swing, trunk counter-rotation) on a body that
is not the default one, so the tests do not depend on the importer. One fixture imports a real walking
clip from the shared mocap set with :mod:`physmotion.io.importer`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physmotion.physics.humanoid import build_model
from physmotion.skeleton import JOINT_INDEX, NUM_JOINTS, REST_OFFSETS, forward_kinematics

REAL_WALK = "bandai2_dataset-2_walk_normal_001"

# Another body: longer legs and spine, shorter arms (per-bone scales keep REST_OFFSETS' directions,
# as offsets_from_joints does for single-child bones).
_BODY_SCALE = {"hip": 1.05, "knee": 1.10, "ankle": 1.10, "foot": 1.0, "spine": 1.08, "neck": 1.0,
               "head": 1.1, "collar": 0.95, "shoulder": 0.95, "elbow": 0.92, "wrist": 0.95}  # fmt: skip


def other_body() -> np.ndarray:
    """Rest offsets (22, 3) of a body that differs from the default one by 0-10 % per bone."""
    from physmotion.physics.humanoid import JOINT_GROUP
    from physmotion.skeleton import JOINT_NAMES

    off = REST_OFFSETS.copy()
    for j in range(1, NUM_JOINTS):
        off[j] *= _BODY_SCALE[JOINT_GROUP[JOINT_NAMES[j]]]
    return off


def gait_rotations(frames: int = 60, fps: float = 20.0, period: float = 1.1) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations (T, 22, 3, 3) and root positions (T, 3) of a walk-like cycle, ours (Y-up).

    Angles in degrees about our axes (x = left, y = up, z = forward). From the T-pose the arms first
    hang down (shoulders +-75 deg about z), then swing.
    """
    t = np.arange(frames) / fps
    ph = 2 * np.pi * t / period
    rot = np.tile(np.eye(3), (frames, NUM_JOINTS, 1, 1))

    def set_euler(name: str, seq: str, angles_deg: np.ndarray) -> None:
        rot[:, JOINT_INDEX[name]] = Rotation.from_euler(seq, np.radians(angles_deg)).as_matrix()

    z = np.zeros(frames)
    for side, sign, shift in (("left", 1.0, 0.0), ("right", -1.0, np.pi)):
        p = ph + shift
        # hip flexion (leg forward) is a negative rotation about +x; a little abduction and toe-out
        hip = [-25 * np.sin(p), sign * (3 + 2 * np.cos(p)), sign * 8 + z]
        set_euler(f"{side}_hip", "xzy", np.stack(hip, -1))
        set_euler(f"{side}_knee", "xzy", np.stack([25 + 25 * np.sin(p - 1.2), z, z], -1))
        set_euler(f"{side}_ankle", "xzy", np.stack([-10 * np.sin(p - 0.5), sign * 3 * np.cos(p), z], -1))
        # arm: hang down (about our z), swing opposite to the leg (about x), elbow bent forward
        set_euler(f"{side}_shoulder", "zxy", np.stack([-sign * 75 + z, 20 * np.sin(p), sign * 10 + z], -1))
        set_euler(f"{side}_elbow", "yxz", np.stack([-sign * (25 + 15 * np.sin(p + 0.3)), z, z], -1))
        set_euler(f"{side}_collar", "zxy", np.stack([-sign * 5 + z, z, z], -1))
    set_euler("spine1", "yxz", np.stack([6 * np.sin(ph), 4 + z, 2 * np.cos(2 * ph)], -1))
    set_euler("spine2", "yxz", np.stack([-4 * np.sin(ph), 2 + z, z], -1))
    set_euler("spine3", "yxz", np.stack([-4 * np.sin(ph), 2 + z, z], -1))
    set_euler("neck", "yxz", np.stack([3 * np.sin(ph), 5 + z, z], -1))
    set_euler("pelvis", "yxz", np.stack([15 + 5 * np.sin(ph), 3 + z, 2 * np.sin(2 * ph)], -1))
    heading = np.radians(15.0)
    root = np.stack([1.3 * t * np.sin(heading), 0.93 + 0.02 * np.cos(2 * ph), 1.3 * t * np.cos(heading)], -1)
    return rot, root


def gait_joints(offsets: np.ndarray, frames: int = 60) -> np.ndarray:
    """Joint positions (T, 22, 3) of the gait cycle on the body ``offsets``."""
    rot, root = gait_rotations(frames)
    return forward_kinematics(rot, root, offsets)


@pytest.fixture(scope="session")
def default_model():
    return build_model()


@pytest.fixture(scope="session")
def body() -> np.ndarray:
    return other_body()


@pytest.fixture(scope="session")
def walk(body: np.ndarray) -> np.ndarray:
    """A synthetic walk (60, 22, 3) on :func:`other_body`."""
    return gait_joints(body)


@pytest.fixture(scope="session")
def real_walk(mocap_dir: Path) -> np.ndarray:
    """Bandai's normal walk through the project's importer: joints (T, 22, 3) float64, 20 fps.

    ``mocap_dir`` is the shared fixture of tests/conftest.py (../shared/data/mocap).
    """
    from physmotion.io.importer import import_clip, load_manifest

    clips = {c.clip: c for c in load_manifest(mocap_dir)}
    # P's input convention, which these tests were written for (the importer's default grounds the soles)
    return import_clip(clips[REAL_WALK], floor="frame0").joints.astype(np.float64)


def shrunk_upper_arms(joints: np.ndarray, start: int = 20, frames: int = 4,
                      depth: float = 0.08) -> np.ndarray:  # fmt: skip
    """joints (T, 22, 3) with both elbows slid up their upper arms by a sine bump of ``depth`` metres over
    ``frames`` frames from ``start``, the wrists where they were: arm bones that change length, as in a
    generated motion (a reach's upper arm measured 26.6 -> 19.1 cm -> 26.6 cm over six frames)."""
    out = joints.copy()
    bump = np.zeros(len(joints))
    bump[start : start + frames] = depth * np.sin(np.pi * (np.arange(frames) + 0.5) / frames)
    for shoulder, elbow in (("left_shoulder", "left_elbow"), ("right_shoulder", "right_elbow")):
        s, e = JOINT_INDEX[shoulder], JOINT_INDEX[elbow]
        bone = out[:, e] - out[:, s]
        out[:, e] -= bone / np.linalg.norm(bone, axis=-1, keepdims=True) * bump[:, None]
    return out


def wrist_error(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance (m) between the wrists of a and b (T, 22, 3), each taken from its own pelvis."""
    w = [JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]]
    return float(np.linalg.norm((a[:, w] - a[:, :1]) - (b[:, w] - b[:, :1]), axis=-1).max())
