"""Imitation episodes: the environment is P's simulation step for step, and its sampling and rewards."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from physmotion.imitator.clips import (ClipSource, TrackedTrajectory, dataset_clips, motion_clips,
                                      teacher_clips, training_sets)  # fmt: skip
from physmotion.imitator.env import Clip, EnvConfig, ImitationEnv
from physmotion.imitator.train import ImitatorTrainConfig, no_hand_config
from physmotion.imitator.vec_env import CapCurriculum
from physmotion.physics.policy import OBS_DIM, PolicySettings, capped_tracking
from physmotion.physics.search import no_hand
from physmotion.physics.tracking import TrackingConfig
from tests.conftest import TINY_TEACHER
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


# --- a clip from a teacher record: observed against the kinematic reference, rewarded on the search's ---

NO_HAND = EnvConfig(settings=PolicySettings(action_scale=1.0, cap=0.0, tracking=no_hand(TrackingConfig())),
                    max_steps=10_000)  # fmt: skip


def _record(teacher_dir: Path) -> dict[str, np.ndarray]:
    with np.load(next(teacher_dir.glob("*.npz"))) as z:
        return {k: z[k] for k in z.files}


def _teacher_clip(source: ClipSource, tracked: bool = True) -> Clip:
    """``source`` as the env prepares it, following its tracked trajectory or (``tracked`` False) not."""
    prepared = prepare_motion(source.joints.astype(np.float64), source.fps, TINY_TEACHER.projection())
    return Clip(prepared, NO_HAND, source.tracked if tracked else None)


def test_a_record_is_observed_as_p_but_rewarded_on_the_searched_trajectory(teacher_dir: Path) -> None:
    (source,) = teacher_clips(teacher_dir)
    rec = _record(teacher_dir)
    assert bool(rec["completed"]) and np.array_equal(source.tracked.qpos, rec["qpos"])
    clip = _teacher_clip(source)
    plain = _teacher_clip(source, tracked=False)
    np.testing.assert_array_equal(clip.ref.qpos, plain.ref.qpos)  # the observation's reference: P's
    env = ImitationEnv(NO_HAND)
    # Reset on the searched state (not the kinematic frame), observed against the kinematic reference: exactly
    # what the search recorded for a policy.
    np.testing.assert_array_equal(env.reset(clip, 0, 0.0), rec["observations"][0])
    rewards = []
    for k in range(clip.steps - 1):  # the record's own committed offsets carry the body along it, no hand
        obs, reward, terminated, truncated, info = env.step(rec["offsets"][k])
        np.testing.assert_allclose(env.data.qpos, rec["qpos"][k + 1], atol=1e-9)
        assert info["force"] == 0.0 and not terminated
        rewards.append(reward)
    assert truncated and min(rewards) > 0.95
    env.reset(clip, 0, 0.0)
    _, wrong, *_ = env.step(rec["offsets"][0] + 0.8)  # a large wrong offset scores lower on the first step
    assert wrong < rewards[0] - 0.05
    # The kinematic reference is not the goal: the plain clip scores the same replayed step lower.
    env.reset(clip, 0, 0.0)
    env.clip = plain  # same state and action, the kinematic reference as the goal
    _, kinematic, *_ = env.step(rec["offsets"][0])
    assert kinematic < rewards[0]


def test_termination_follows_the_tracked_trajectory(teacher_dir: Path) -> None:
    """The searched trajectory moved 0.5 m sideways (a flat floor: the same motion) is followed to its end
    with the record's offsets, though the bodies are past the 0.3 m termination from the kinematic
    reference; started there against the kinematic reference, the episode ends at once."""
    (source,) = teacher_clips(teacher_dir)
    rec = _record(teacher_dir)
    moved = rec["qpos"].copy()
    moved[:, 1] += 0.5
    clip = _teacher_clip(replace(source, tracked=TrackedTrajectory(moved, rec["qvel"])))
    env = ImitationEnv(NO_HAND)
    env.reset(clip, 0, 0.0)
    for k in range(clip.steps - 1):
        _, _, terminated, truncated, info = env.step(rec["offsets"][k])
        assert not terminated and info["mpjpe"] < 0.01
    assert truncated
    env.reset(clip, 0, 0.0)
    env.clip = _teacher_clip(source, tracked=False)
    _, _, terminated, _, info = env.step(rec["offsets"][0])
    assert terminated and info["mpjpe"] > 0.3


def test_a_failed_record_is_cut_before_its_fall(teacher_dir: Path, tmp_path: Path) -> None:
    rec = _record(teacher_dir)
    rec.update(completed=np.array(False), failed_at=np.array(10))
    np.savez(tmp_path / "walk_f0_plain.npz", **rec)
    rec.update(failed_at=np.array(1))  # one carried step: nothing to learn from, left out
    np.savez(tmp_path / "walk_f0_pushabc123.npz", **rec)
    (source,) = teacher_clips(tmp_path)
    assert source.name == "walk_f0_plain" and len(source.tracked.qpos) == 10
    clip = _teacher_clip(source)
    assert clip.steps == 10 and len(clip.ref.qpos) == len(rec["qpos"])
    env = ImitationEnv(NO_HAND)
    env.reset(clip, 7, 0.0)
    _, _, _, truncated, _ = env.step(rec["offsets"][7])
    assert not truncated
    _, _, terminated, truncated, _ = env.step(rec["offsets"][8])
    assert truncated and not terminated  # the episode ends at the last carried step
    with pytest.raises(PhysmotionError, match="teacher folder not found"):
        teacher_clips(tmp_path / "x")
    (tmp_path / "x").mkdir()
    with pytest.raises(PhysmotionError, match="no teacher records"):
        teacher_clips(tmp_path / "x")


def test_no_hand_training_keeps_the_cap_at_zero() -> None:
    cfg = no_hand_config(ImitatorTrainConfig(), action_scale=0.4)
    cur = CapCurriculum(zero_share=cfg.cap_zero_share)
    rng = np.random.default_rng(0)
    for _ in range(30):
        cur.update(0.0)  # the level moves either way; the caps do not
        assert cur.sample(rng) == 0.0
        cur.update(1.0)
        assert cur.sample(rng) == 0.0
    s = cfg.env.settings
    assert cfg.eval_caps == (0.0,) and s.cap == 0.0 and s.action_scale == 0.4
    assert capped_tracking(s.tracking, 1.0) == s.tracking and not s.tracking.feet_balance
    assert s.tracking.residual_force == s.tracking.residual_torque == s.tracking.residual_lift == 0.0


def test_teacher_segments_held_out_stay_held_out_as_the_folder_grows(teacher_dir: Path, tmp_path: Path) -> None:
    rec = _record(teacher_dir)
    names = [f"walk{i}_f0_{start}" for i in range(40) for start in ("plain", "push0a1b2c")]
    for name in names[:40]:
        np.savez(tmp_path / f"{name}.npz", **rec)
    train, evals = training_sets([], [], 100, [tmp_path])
    for name in names[40:]:  # more records arrive while a run trains
        np.savez(tmp_path / f"{name}.npz", **rec)
    train2, evals2 = training_sets([], [], 100, [tmp_path])
    held = {c.name for c in evals}
    assert held and held <= {c.name for c in evals2} and all(n.endswith("_plain") for n in held)
    assert not {c.name for c in train2} & {c.name for c in evals2}  # every start of a held segment is out
    assert {c.name for c in train} <= {c.name for c in train2} and len(train) + 2 * len(held) >= 40
