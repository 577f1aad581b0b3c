"""Training on the bundled data: the loss falls, resumption is exact, a single clip is reproduced."""

from __future__ import annotations

import copy
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.samplers import SamplerConfig, sample
from physmotion.diffusion.train import STATE_FILE, train_denoiser
from physmotion.errors import PhysmotionError
from tests.conftest import tiny_config


@pytest.mark.slow
def test_loss_goes_down_on_bundled_data(built_dir: Path, tmp_path: Path) -> None:
    result = train_denoiser(tiny_config(built_dir, tmp_path / "run", steps=80, log_every=10), progress=False)
    first, last = result.losses[0][1], min(v for _, v in result.losses[-3:])
    assert last < 0.7 * first, result.losses
    model = MotionDiffusion.load(tmp_path / "run")
    assert model.info["steps"] == 80 and model.licence_tag == "NC"  # Bandai clips are CC-BY-NC
    assert (tmp_path / "run" / "loss.csv").read_text().count("\n") == 9


def test_resume_continues_exactly(built_dir: Path, tmp_path: Path) -> None:
    """6 steps in one go == 3 steps, stop, resume to 6: same step, same weights, same EMA."""
    whole = tmp_path / "whole"
    train_denoiser(tiny_config(built_dir, whole, steps=6), progress=False)
    split = tmp_path / "split"
    train_denoiser(tiny_config(built_dir, split, steps=3), progress=False)
    train_denoiser(tiny_config(built_dir, split, steps=6), resume=True, progress=False)
    a = torch.load(whole / STATE_FILE, weights_only=False)
    b = torch.load(split / STATE_FILE, weights_only=False)
    assert a["step"] == b["step"] == 6
    for k in a["net"]:
        assert torch.equal(a["net"][k], b["net"][k]), k
    for x, y in zip(a["ema"]["shadow_params"], b["ema"]["shadow_params"]):
        assert torch.equal(x, y)
    assert a["ema"]["optimization_step"] == b["ema"]["optimization_step"]


def test_training_leaves_the_callers_config_alone(built_dir: Path, tmp_path: Path) -> None:
    """The run takes the text and feature widths from its encoder and data, and decides bf16, in a copy:
    the config passed in is the same after the run, while the saved one holds what was used."""
    cfg = tiny_config(built_dir, tmp_path / "run", steps=1, bf16=None)
    cfg = replace(cfg, denoiser=replace(cfg.denoiser, text_dim=1, feature_dim=1))
    before = copy.deepcopy(cfg)
    train_denoiser(cfg, progress=False)
    assert cfg == before
    model = MotionDiffusion.load(tmp_path / "run")
    assert (model.denoiser.text_dim, model.denoiser.feature_dim) == (384, 263)


def test_resume_and_overwrite_guards(built_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(PhysmotionError, match="nothing to resume"):
        train_denoiser(tiny_config(built_dir, tmp_path / "none"), resume=True, progress=False)
    train_denoiser(tiny_config(built_dir, tmp_path / "run", steps=1), progress=False)
    with pytest.raises(PhysmotionError, match="--resume"):
        train_denoiser(tiny_config(built_dir, tmp_path / "run", steps=2), progress=False)


@pytest.mark.slow
def test_overfits_a_single_clip(one_clip_dir: Path, tmp_path: Path) -> None:
    """The denoiser learns one real walk well enough that sampling gives it back."""
    cfg = tiny_config(one_clip_dir, tmp_path / "run", d_model=128, steps=400, random_crop=False,
                      text_drop=0.0, ema_decay=0.9)
    cfg.denoiser.dropout = 0.0
    train_denoiser(cfg, progress=False)
    model = MotionDiffusion.load(tmp_path / "run")
    target = model.normalizer.normalize(np.load(one_clip_dir / "new_joint_vecs" / "copy0.npy"))
    x = sample(model, ["a person walks forward"] * 2, [64, 64], SamplerConfig(steps=20, cfg_scale=1.0), seed=3)
    err = ((x.numpy() - target[None]) ** 2).mean()
    noise_err = ((np.random.default_rng(0).standard_normal(target.shape) - target) ** 2).mean()
    assert err < 0.05 * noise_err, (err, noise_err)
    info = json.loads((tmp_path / "run" / "config.json").read_text())
    assert info["info"]["train_items"] == 8


def test_cli_train_and_resume(built_dir: Path, tmp_path: Path) -> None:
    from tests.test_cli import run

    out = tmp_path / "cli_run"
    common = ["train", "denoiser", "--data", built_dir, "--out", out, "--d-model", "32", "--layers", "1",
              "--batch-size", "4", "--crop", "40"]  # fmt: skip
    res = run(*common, "--steps", "2")
    assert res.returncode == 0, res.stderr
    assert "trained to step 2" in res.stdout and (out / "model.safetensors").is_file()
    res = run(*common, "--steps", "2")
    assert res.returncode == 1 and "--resume" in res.stderr and "Traceback" not in res.stderr
    res = run(*common, "--steps", "3", "--resume")
    assert res.returncode == 0 and "trained to step 3" in res.stdout
    res = run("train", "denoiser", "--data", tmp_path / "missing", "--out", tmp_path / "x")
    assert res.returncode == 1 and "no such dataset folder" in res.stderr


def test_bf16_is_used_only_where_the_hardware_has_it(built_dir: Path, tmp_path: Path) -> None:
    """Unset, bf16 autocast follows bf16_helps (emulated bf16 made a CPU step 20x slower); the run
    saves the precision it used, and an explicit choice is kept."""
    from physmotion.training import bf16_helps

    train_denoiser(tiny_config(built_dir, tmp_path / "auto", steps=1, bf16=None), progress=False)
    saved = json.loads((tmp_path / "auto" / "config.json").read_text())["info"]["train"]["bf16"]
    assert saved is bf16_helps("cpu")
    assert bf16_helps("cpu") == bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    train_denoiser(tiny_config(built_dir, tmp_path / "off", steps=1, bf16=False), progress=False)
    assert json.loads((tmp_path / "off" / "config.json").read_text())["info"]["train"]["bf16"] is False
