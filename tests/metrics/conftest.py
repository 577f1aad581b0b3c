"""Synthetic motions with known float, penetration and sliding, built on the default body."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from physmotion.metrics.geometry import DEFAULT_BODY
from physmotion.skeleton import rest_joints

MakeMotion = Callable[..., np.ndarray]


@pytest.fixture(scope="session")
def planted_pose() -> np.ndarray:
    """The default rest body (22, 3) standing with its lowest surface point (the soles) exactly on y = 0."""
    pose = rest_joints()
    pose[:, 1] -= DEFAULT_BODY.lowest_height(pose[None])[0]
    return pose


@pytest.fixture(scope="session")
def make_motion(planted_pose: np.ndarray) -> MakeMotion:
    """Factory: the planted body held ``frames``, raised by ``lift`` metres, moving at ``velocity`` m/s."""

    def make(frames: int = 41, lift: float = 0.0, velocity: tuple[float, float, float] = (0, 0, 0),
             fps: float = 20.0) -> np.ndarray:  # fmt: skip
        t = np.arange(frames) / fps
        motion = np.repeat(planted_pose[None], frames, axis=0)
        motion[..., 1] += lift
        return motion + t[:, None, None] * np.asarray(velocity, dtype=np.float64)

    return make


@pytest.fixture(scope="session")
def random_batch(planted_pose: np.ndarray) -> np.ndarray:
    """(4, 60, 22, 3) smooth random motions near the floor: every joint wanders by low-frequency sines."""
    rng = np.random.default_rng(0)
    frames, t = 60, np.arange(60) / 20.0
    out = np.repeat(planted_pose[None, None], 4, axis=0).repeat(frames, axis=1)
    for k in range(1, 4):
        amp = rng.normal(0, 0.02 / k, size=(4, 1, 22, 3))
        phase = rng.uniform(0, 2 * np.pi, size=(4, 1, 22, 3))
        out += amp * np.sin(2 * np.pi * 0.7 * k * t[None, :, None, None] + phase)
    out[..., [0, 2]] += rng.uniform(0.1, 1.2, size=(4, 1, 1, 2)) * t[None, :, None, None]  # root travel
    return out


@pytest.fixture(scope="session")
def mocap_root() -> Path:
    """The shared mocap collection; tests that need it skip where it is not present."""
    path = Path(os.environ.get("PHYSMOTION_MOCAP", Path(__file__).resolve().parents[3] / "shared/data/mocap"))
    if not (path / "manifest.csv").is_file():
        pytest.skip(f"no mocap collection at {path}")
    return path
