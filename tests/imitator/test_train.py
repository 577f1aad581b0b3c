"""``train imitator``: PPO through rsl-rl on real clips, exact resumption, the exported policy, a warm start
from a policy folder on teacher records with no outside hand."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from safetensors.numpy import save_file

from physmotion.errors import PhysmotionError
from physmotion.imitator.clips import dataset_clips, teacher_clips
from physmotion.imitator.train import (ImitatorTrainConfig, export_weights, make_algorithm, no_hand_config,
                                       read_warm_start, train_imitator)  # fmt: skip
from physmotion.imitator.vec_env import VecImitationEnv
from physmotion.physics.policy import (NUM_ACTIONS, OBS_DIM, PolicyNetwork, PolicySettings, load_policy,
                                       settings_dict)  # fmt: skip
from physmotion.physics.search import no_hand
from physmotion.physics.tracking import TrackingConfig



def _cfg() -> ImitatorTrainConfig:
    return ImitatorTrainConfig(num_envs=4, workers=2, num_steps_per_env=8, hidden_dims=(32, 32), chunk=1,
                               eval_every=2)  # fmt: skip


@pytest.fixture(scope="module")
def clips(small_built_dir: Path):
    train = [c for c in dataset_clips(small_built_dir, "train") if "walk" in c.name or "run" in c.name][:4]
    test = dataset_clips(small_built_dir, "test")[:1]
    return train, test


@pytest.mark.slow
def test_resume_is_exact_and_the_policy_loads(clips, tmp_path: Path) -> None:
    train, test = clips
    whole = train_imitator(tmp_path / "whole", train, test, iterations=4, config=_cfg(), log=lambda *_: None)
    train_imitator(tmp_path / "split", train, test, iterations=2, config=_cfg(), log=lambda *_: None)
    split = train_imitator(tmp_path / "split", train, test, iterations=2, config=_cfg(), resume=True,
                           log=lambda *_: None)  # fmt: skip
    a, b = load_policy(whole), load_policy(split)
    for (wa, ba), (wb, bb) in zip(a.network.layers, b.network.layers):
        np.testing.assert_array_equal(wa, wb)
        np.testing.assert_array_equal(ba, bb)
    np.testing.assert_array_equal(a.network.mean, b.network.mean)
    assert a.card["iterations"] == 4 and a.card["samples"] == 4 * 4 * 8
    assert (tmp_path / "whole" / "log.csv").read_text().count("\n") == 5  # header + 4 iterations
    assert "cap" in (tmp_path / "whole" / "eval.csv").read_text()
    # Training moved the network off the tracker (the last layer starts at zero).
    assert np.abs(a.network.layers[-1][0]).max() > 0


@pytest.mark.slow
def test_refuses_a_used_folder_and_a_missing_resume(clips, tmp_path: Path) -> None:
    train, test = clips
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "x").write_text("x")
    with pytest.raises(PhysmotionError, match="--resume"):
        train_imitator(tmp_path / "run", train, test, iterations=1, config=_cfg())
    with pytest.raises(PhysmotionError, match="nothing to resume"):
        train_imitator(tmp_path / "new", train, test, iterations=1, config=_cfg(), resume=True)
    with pytest.raises(PhysmotionError, match="--iterations or --minutes"):
        train_imitator(tmp_path / "new2", train, test, config=_cfg())


# --- warm start from a policy folder, on teacher records with no outside hand ---


def _policy_folder(folder: Path, hidden: tuple[int, ...] = (32, 16), seed: int = 0) -> dict[str, np.ndarray]:
    """A policy folder with random weights (not a trained policy: any network must come through exactly)."""
    rng = np.random.default_rng(seed)
    sizes = (OBS_DIM, *hidden, NUM_ACTIONS)
    w = {"obs_mean": rng.normal(0.0, 1.0, OBS_DIM), "obs_std": rng.uniform(0.5, 2.0, OBS_DIM)}
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        w[f"layers.{i}.weight"] = rng.normal(0.0, 1.0 / np.sqrt(a), (b, a))
        w[f"layers.{i}.bias"] = rng.normal(0.0, 0.1, b)
    w = {k: v.astype(np.float32) for k, v in w.items()}
    folder.mkdir()
    save_file(w, str(folder / "policy.safetensors"))
    settings = PolicySettings(action_scale=0.4, cap=0.0, tracking=no_hand(TrackingConfig()))
    (folder / "settings.json").write_text(json.dumps(settings_dict(settings)))
    return w


def test_warm_start_reproduces_the_policy_at_iteration_0(teacher_dir: Path, tmp_path: Path) -> None:
    import torch

    w = _policy_folder(tmp_path / "student")
    weights, settings = read_warm_start(tmp_path / "student")
    cfg = replace(no_hand_config(ImitatorTrainConfig(num_envs=3, workers=1), action_scale=0.15),
                  hidden_dims=(32, 16), init_std=0.1)  # fmt: skip
    env = VecImitationEnv(teacher_clips(teacher_dir), [], cfg.env, cfg.num_envs, cfg.workers)
    try:
        alg = make_algorithm(env, cfg, "cpu", weights)
        obs = env.get_observations()
        with torch.no_grad():
            mean = alg.actor(obs).numpy()
        np.testing.assert_allclose(mean, PolicyNetwork(w)(obs["policy"].numpy()), rtol=1e-5, atol=1e-6)
        assert np.abs(mean).max() > 0.1  # a network that acts, not the tracker's zero
        for k, v in export_weights(alg).items():  # exported at iteration 0: the folder's, bit for bit
            np.testing.assert_array_equal(v, w[k])
        assert torch.equal(alg.actor.distribution.std_param.detach(), torch.full((NUM_ACTIONS,), 0.1))
    finally:
        env.close()


def test_warm_started_run_keeps_the_normaliser_and_takes_the_settings(teacher_dir: Path,
                                                                       tmp_path: Path) -> None:  # fmt: skip
    w = _policy_folder(tmp_path / "student")
    cfg = no_hand_config(ImitatorTrainConfig(num_envs=3, workers=1, num_steps_per_env=8, chunk=1, eval_every=1,
                                             init_std=0.1))  # fmt: skip
    clips = teacher_clips(teacher_dir)
    out = train_imitator(tmp_path / "run", clips, clips, iterations=2, config=cfg,
                         warm_start=tmp_path / "student", log=lambda *_: None)  # fmt: skip
    policy = load_policy(out)
    assert policy.settings.action_scale == 0.4 and policy.settings.cap == 0.0  # the student's scale, no hand
    assert policy.settings.tracking == no_hand(TrackingConfig()) and policy.card["warm_start"]
    np.testing.assert_array_equal(policy.network.mean, w["obs_mean"])  # frozen through two updates
    np.testing.assert_array_equal(policy.network.std, w["obs_std"])
    assert [b.shape for _, b in policy.network.layers] == [(32,), (16,), (NUM_ACTIONS,)]
    assert not np.array_equal(policy.network.layers[0][0], w["layers.0.weight"].T)  # PPO moved the network
    caps = {line.split(",")[2] for line in (tmp_path / "run" / "eval.csv").read_text().splitlines()[1:]}
    assert caps == {"0.0"}  # evaluated with no hand only
