"""The learned imitation controller: observation, numpy network, loading, and its place in P."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physmotion.errors import PhysmotionError
from physmotion.imitator.clips import dataset_clips
from physmotion.physics.policy import (
    DEFAULT_POLICY,
    NUM_ACTIONS,
    OBS_DIM,
    Policy,
    PolicyNetwork,
    PolicySettings,
    load_policy,
    observe,
)
from physmotion.physics.projection import ProjectionConfig, prepare_motion, project
from physmotion.physics.sim import simulate
from physmotion.physics.tracking import ModelBasedTracker, prepare_reference


def _zero_weights(hidden: int = 8) -> dict[str, np.ndarray]:
    return {"obs_mean": np.zeros(OBS_DIM, np.float32), "obs_std": np.ones(OBS_DIM, np.float32),
            "layers.0.weight": np.ones((hidden, OBS_DIM), np.float32), "layers.0.bias": np.zeros(hidden, np.float32),
            "layers.1.weight": np.zeros((NUM_ACTIONS, hidden), np.float32),
            "layers.1.bias": np.zeros(NUM_ACTIONS, np.float32)}  # fmt: skip


@pytest.fixture(scope="module")
def run_clip(small_built_dir: Path):
    """A captured run of the small build (train split), prepared as P prepares it."""
    clip = next(c for c in dataset_clips(small_built_dir, "train") if "_run_" in c.name and c.name[0] != "M")
    return clip, prepare_motion(clip.joints.astype(np.float64), clip.fps, ProjectionConfig())


def test_observation_is_finite_and_sized(run_clip) -> None:
    import mujoco

    _, prep = run_clip
    ref = prepare_reference(prep.model, prep.target, 1 / 30)
    data = mujoco.MjData(prep.model)
    data.qpos[:], data.qvel[:] = ref.qpos[3], ref.qvel[3]
    mujoco.mj_forward(prep.model, data)
    obs = observe(prep.model, data, ref, 3, 0.25)
    assert obs.shape == (OBS_DIM,) and obs.dtype == np.float32 and np.all(np.isfinite(obs))
    # On the reference itself the hinge errors to the next reference steps are the reference's own steps.
    assert obs[-1] == pytest.approx(0.25)
    assert 0.5 < obs[0] < 1.3  # pelvis height, m


def test_zero_policy_is_the_capped_tracker(run_clip) -> None:
    """A network whose output is zero drives the humanoid exactly as the tracker with the same cap."""
    from physmotion.physics.policy import capped_tracking

    _, prep = run_clip
    settings = PolicySettings(cap=0.5)
    ref = prepare_reference(prep.model, prep.target, 1 / 30, settings.tracking)
    policy = Policy(PolicyNetwork(_zero_weights()), settings, {})
    a = simulate(prep.model, ref, policy.controller(prep.model), fail_mpjpe=0.5)
    tracker = ModelBasedTracker(prep.model, capped_tracking(settings.tracking, 0.5))
    b = simulate(prep.model, ref, tracker, fail_mpjpe=0.5)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    assert a.residual_force.max() <= 0.5 * settings.tracking.residual_force + 1e-9


def test_network_matches_the_torch_actor() -> None:
    """export_weights + PolicyNetwork give rsl-rl's actor mean (normaliser included)."""
    import torch
    from rsl_rl.models import MLPModel
    from tensordict import TensorDict

    from physmotion.imitator.train import export_weights

    torch.manual_seed(0)
    obs = TensorDict({"policy": torch.randn(5, OBS_DIM)}, batch_size=[5])
    actor = MLPModel(obs, {"actor": ["policy"]}, "actor", NUM_ACTIONS, hidden_dims=[32, 16], obs_normalization=True,
                     distribution_cfg={"class_name": "GaussianDistribution", "init_std": 0.3})  # fmt: skip
    actor.update_normalization(TensorDict({"policy": 3 * torch.randn(64, OBS_DIM) + 1}, batch_size=[64]))

    class _Alg:
        def get_policy(self):
            return actor

    net = PolicyNetwork(export_weights(_Alg()))
    with torch.no_grad():
        want = actor(obs).numpy()
    np.testing.assert_allclose(net(obs["policy"].numpy()), want, rtol=1e-4, atol=1e-5)


def test_shipped_policy_loads_with_a_card() -> None:
    policy = load_policy()
    assert policy.settings.cap == pytest.approx(0.25)
    card = json.loads((DEFAULT_POLICY / "card.json").read_text())
    assert card["samples"] > 0 and card["data"]["licence_tags"] and card["hardware"]
    assert (DEFAULT_POLICY / "policy.safetensors").stat().st_size < 10_000_000


def test_load_policy_errors(tmp_path: Path) -> None:
    with pytest.raises(PhysmotionError, match="policy.safetensors is missing"):
        load_policy(tmp_path)
    from safetensors.numpy import save_file

    bad = _zero_weights()
    bad["obs_mean"] = np.zeros(10, np.float32)
    save_file(bad, str(tmp_path / "policy.safetensors"))
    (tmp_path / "settings.json").write_text(json.dumps({"action_scale": 0.15, "cap": 0.25, "tracking": {}}))
    with pytest.raises(PhysmotionError, match="do not fit this humanoid"):
        load_policy(tmp_path)
    (tmp_path / "settings.json").write_text("{not json")
    with pytest.raises(PhysmotionError, match="cannot read"):
        load_policy(tmp_path)


def test_project_with_the_shipped_policy(run_clip) -> None:
    """P driven by the shipped policy simulates a captured run with its residual within the policy's cap."""
    clip, _ = run_clip
    cfg = ProjectionConfig(workers=1).with_controller("policy")
    out = project(clip.joints, clip.fps, cfg)
    assert out.simulated.shape == clip.joints.shape
    bound = load_policy().settings.cap * cfg.tracking.residual_force
    assert float(out.residual_force.max()) <= bound + 1e-9
    # A run is chaotic to simulate: the bound leaves room for rounding, not for a fall
    # (docs/decisions/projection.md: "the policy test's bound on a chaotic run").
    assert bool(out.success) and float(out.mpjpe.mean()) < 0.2
    again = project(clip.joints, clip.fps, cfg)
    np.testing.assert_array_equal(out.simulated, again.simulated)  # deterministic


def test_controller_name_is_checked() -> None:
    with pytest.raises(PhysmotionError, match="controller must be"):
        ProjectionConfig(controller="pid")
