"""``train imitator``: PPO through rsl-rl on real clips, exact resumption, the exported policy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physmotion.errors import PhysmotionError
from physmotion.imitator.clips import dataset_clips
from physmotion.imitator.train import ImitatorTrainConfig, train_imitator
from physmotion.physics.policy import load_policy

pytestmark = pytest.mark.slow


def _cfg() -> ImitatorTrainConfig:
    return ImitatorTrainConfig(num_envs=4, workers=2, num_steps_per_env=8, hidden_dims=(32, 32), chunk=1,
                               eval_every=2)  # fmt: skip


@pytest.fixture(scope="module")
def clips(small_built_dir: Path):
    train = [c for c in dataset_clips(small_built_dir, "train") if "walk" in c.name or "run" in c.name][:4]
    test = dataset_clips(small_built_dir, "test")[:1]
    return train, test


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
