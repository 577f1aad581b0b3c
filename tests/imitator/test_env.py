"""Imitation episodes: the environment is P's simulation step for step, and its sampling and rewards."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physmotion.imitator.clips import dataset_clips, motion_clips
from physmotion.imitator.env import Clip, EnvConfig, ImitationEnv
from physmotion.imitator.vec_env import CapCurriculum
from physmotion.physics.policy import OBS_DIM
from physmotion.physics.projection import ProjectionConfig, prepare_motion
from physmotion.physics.sim import simulate
from physmotion.physics.tracking import ModelBasedTracker
from physmotion.errors import PhysmotionError


@pytest.fixture(scope="module")
def walk(small_built_dir: Path) -> Clip:
    src = next(c for c in dataset_clips(small_built_dir, "train") if "_walk_" in c.name and c.name[0] != "M")
    return Clip(prepare_motion(src.joints.astype(np.float64), src.fps, ProjectionConfig()), EnvConfig())


def test_zero_action_is_the_tracker(walk: Clip) -> None:
    """With zero actions at cap 1 an episode from frame 0 is P's plain simulation, step for step."""
    env = ImitationEnv(EnvConfig(max_steps=10_000))
    obs = env.reset(walk, 0, 1.0)
    assert obs.shape == (OBS_DIM,)
    roll = simulate(walk.model, walk.ref, ModelBasedTracker(walk.model), fail_mpjpe=0.5)
    for k in range(1, 30):
        obs, reward, terminated, truncated, info = env.step(np.zeros(63))
        assert info["mpjpe"] == pytest.approx(roll.mpjpe[k], abs=1e-12)
        assert info["force"] == pytest.approx(roll.residual_force[k], abs=1e-12)
        assert not terminated and 0.0 < reward < 1.0


def test_terminates_off_the_reference_and_truncates_at_the_end(walk: Clip) -> None:
    env = ImitationEnv(EnvConfig())
    env.reset(walk, 0, 0.0)
    for _ in range(walk.steps):  # full-scale random flailing with no residual: the body leaves the motion
        _, _, terminated, truncated, _ = env.step(np.random.default_rng(0).choice([-1.0, 1.0], 63))
        if terminated or truncated:
            break
    assert terminated
    env.reset(walk, walk.steps - 3, 1.0)
    _, _, terminated, truncated, _ = env.step(np.zeros(63))
    _, _, terminated, truncated, _ = env.step(np.zeros(63))
    assert truncated and not terminated


def test_curriculum_moves_with_survival() -> None:
    cur = CapCurriculum()
    rng = np.random.default_rng(0)
    caps = [cur.sample(rng) for _ in range(400)]
    assert 0.15 < np.mean(np.array(caps) == 0.0) < 0.35 and max(caps) <= 1.0
    for _ in range(30):
        cur.update(0.9)
    assert cur.level == 1.0 and max(cur.sample(rng) for _ in range(200)) <= 0.25
    cur.update(0.1)
    assert cur.level == pytest.approx(0.95)


def test_clip_sources(small_built_dir: Path, tmp_path: Path) -> None:
    train = dataset_clips(small_built_dir, "train")
    names = {c.name for c in train}
    assert any(n.startswith("M") for n in names) and all(c.joints.shape[1:] == (22, 3) for c in train)
    with pytest.raises(PhysmotionError, match="not a dataset folder"):
        dataset_clips(tmp_path, "train")
    with pytest.raises(PhysmotionError, match="no .npz motions"):
        motion_clips(tmp_path)
