"""Morph's fine-tuning (Sec. 3.3) on synthetic folders written in the SYNTH/ layout from real built items."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from physmotion.diffusion.model import DEFAULT_MODEL_DIR, MotionDiffusion
from physmotion.diffusion.train import STATE_FILE
from physmotion.errors import PhysmotionError
from physmotion.morph.finetune import (
    FinetuneConfig,
    FinetuneError,
    ItemDataset,
    MixedDataset,
    denoising_loss,
    finetune,
    selected_items,
)
from physmotion.morph.selection import select
from tests.morph.fake_synth import make_synth


@pytest.fixture(scope="module")
def synth_dir(built_dir: Path, tiny_model_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_synth(built_dir, tiny_model_dir, tmp_path_factory.mktemp("synth") / "synth")


def _cfg(tiny_model_dir: Path, synth: Path, built_dir: Path, out: Path, **kw) -> FinetuneConfig:
    return FinetuneConfig(model=str(tiny_model_dir), synth=str(synth), data=str(built_dir), out=str(out),
                          **{"steps": 4, "checkpoint_minutes": 60.0, **kw})  # fmt: skip


def test_finetuning_lowers_the_loss_on_the_synthetic_set(tiny_model_dir, synth_dir, built_dir, tmp_path) -> None:
    items = selected_items(select(synth_dir), 263)
    before = denoising_loss(MotionDiffusion.load(tiny_model_dir), items)
    result = finetune(_cfg(tiny_model_dir, synth_dir, built_dir, tmp_path / "ft", steps=20, lr=1e-3), progress=False)
    tuned = MotionDiffusion.load(tmp_path / "ft")
    after = denoising_loss(tuned, items)
    assert after < 0.9 * before, (before, after)
    morph = tuned.info["morph"]
    assert morph["rounds"] == 1 and morph["selected"] == {"refined": 6, "input": 2} and morph["ifr"] == 0.25
    assert morph["mix"] == 0.1 and morph["lr"] == 1e-3 and tuned.info["steps"] == 20 == result.train.step
    assert morph["base_model"] == str(tiny_model_dir) and morph["synth"] == str(synth_dir)
    assert result.real_items > 0 and result.synthetic_items == 8
    # The model's normaliser is kept, never recomputed from the mix.
    base = MotionDiffusion.load(tiny_model_dir)
    assert (tuned.normalizer.mean == base.normalizer.mean).all() and (tuned.normalizer.std == base.normalizer.std).all()


def test_each_batch_holds_the_synthetic_share(tiny_model, synth_dir, built_dir) -> None:
    from physmotion.data.dataset import MotionDataset

    synth = ItemDataset(selected_items(select(synth_dir), 263), tiny_model.normalizer, crop=64, random_crop=True, seed=0)
    real = MotionDataset(built_dir, "train", crop=64, normalize=False)
    mixed = MixedDataset(synth, real, 0.25)
    for step in range(5):
        _, idx = mixed.batch_indices(8, 0, step)
        assert len(idx) == 8 and sum(i < len(synth) for i in idx) == 2
        assert mixed.batch_indices(8, 0, step)[1] == idx  # a function of (seed, step): resumable
    control = MixedDataset(synth, real, 0.0)  # mix 0: the real-only control
    for step in range(5):
        _, idx = control.batch_indices(8, 0, step)
        assert len(idx) == 8 and all(i >= len(synth) for i in idx)


def test_nc_licence_carries_through(tiny_model_dir, built_dir, tmp_path) -> None:
    """A model marked open, fine-tuned on synthetic items tagged NC, is NC."""
    model = tmp_path / "open_model"
    shutil.copytree(tiny_model_dir, model)
    config = json.loads((model / "config.json").read_text())
    config["info"]["licence_tags"] = ["open"]
    (model / "config.json").write_text(json.dumps(config))
    assert MotionDiffusion.load(model).licence_tag == "open"
    synth = make_synth(built_dir, model, tmp_path / "synth", n=4, licence_tags=("NC",))
    finetune(_cfg(model, synth, built_dir, tmp_path / "ft", steps=2, mix=1.0), progress=False)
    tuned = MotionDiffusion.load(tmp_path / "ft")
    assert "NC" in tuned.info["licence_tags"] and tuned.licence_tag == "NC"


def test_joined_licence_tags_are_kept_as_their_parts(tiny_model_dir, built_dir, tmp_path) -> None:
    """Synthetic items of a model trained with NC and SA data carry "NC,SA"; the tuned model lists NC and SA."""
    synth = make_synth(built_dir, tiny_model_dir, tmp_path / "synth", n=4, licence_tags=("NC,SA",))
    finetune(_cfg(tiny_model_dir, synth, built_dir, tmp_path / "ft", steps=2, mix=1.0), progress=False)
    tuned = MotionDiffusion.load(tmp_path / "ft")
    assert {"NC", "SA"} <= set(tuned.info["licence_tags"]) and "NC,SA" not in tuned.info["licence_tags"]
    assert tuned.licence_tag == "NC,SA"


def test_the_base_runs_loss_and_length_filter_carry_over(built_dir, tmp_path) -> None:
    """A base trained with the velocity loss and caption rewrites on motions under 84 frames is fine-tuned
    with all three: its real and synthetic items are those a run with its ``max_length`` keeps."""
    import numpy as np

    from physmotion.data.dataset import MotionDataset
    from physmotion.diffusion.train import train_denoiser
    from tests.conftest import tiny_config

    base = tmp_path / "base"
    train_denoiser(tiny_config(built_dir, base, steps=2, d_model=32, layers=1, max_length=80, vel_weight=1.0,
                               caption_aug=0.5), progress=False)  # fmt: skip
    synth = make_synth(built_dir, base, tmp_path / "synth", n=16)
    result = finetune(_cfg(base, synth, built_dir, tmp_path / "ft", steps=2), progress=False)
    train = MotionDiffusion.load(tmp_path / "ft").info["train"]
    assert train["vel_weight"] == 1.0 and train["max_length"] == 80 and train["caption_aug"] == 0.5
    assert result.real_items == len(MotionDataset(built_dir, "train", crop=64, max_frames=80)) < len(
        MotionDataset(built_dir, "train", crop=64))
    lengths = [len(np.load(path)) for _, path, _ in select(synth).training_items()]
    assert 0 < result.synthetic_items == sum(n < 84 for n in lengths) < len(lengths)


def test_resume_continues_exactly(tiny_model_dir, synth_dir, built_dir, tmp_path) -> None:
    finetune(_cfg(tiny_model_dir, synth_dir, built_dir, tmp_path / "whole", steps=6), progress=False)
    finetune(_cfg(tiny_model_dir, synth_dir, built_dir, tmp_path / "split", steps=3), progress=False)
    finetune(_cfg(tiny_model_dir, synth_dir, built_dir, tmp_path / "split", steps=6), resume=True, progress=False)
    a = torch.load(tmp_path / "whole" / STATE_FILE, weights_only=False)
    b = torch.load(tmp_path / "split" / STATE_FILE, weights_only=False)
    assert a["step"] == b["step"] == 6
    for k in a["net"]:
        assert torch.equal(a["net"][k], b["net"][k]), k
    for x, y in zip(a["ema"]["shadow_params"], b["ema"]["shadow_params"]):
        assert torch.equal(x, y)


def test_bad_inputs_are_one_line_errors_and_write_nothing(tiny_model_dir, synth_dir, built_dir, tmp_path) -> None:
    out = tmp_path / "ft"
    other = make_synth(built_dir, DEFAULT_MODEL_DIR, tmp_path / "other", n=2)
    with pytest.raises(FinetuneError, match="made by another model"):
        finetune(_cfg(tiny_model_dir, other, built_dir, out), progress=False)
    wide = make_synth(built_dir, tiny_model_dir, tmp_path / "wide", n=2, feature_dim=329)
    with pytest.raises(FinetuneError, match="329-d"):
        finetune(_cfg(tiny_model_dir, wide, built_dir, out), progress=False)
    empty = make_synth(built_dir, tiny_model_dir, tmp_path / "empty", n=2)
    (empty / "index.csv").write_text((empty / "index.csv").read_text().splitlines()[0] + "\n")
    with pytest.raises(PhysmotionError, match="no finished synthetic item"):
        finetune(_cfg(tiny_model_dir, empty, built_dir, out), progress=False)
    no_config = tmp_path / "no_config"
    no_config.mkdir()
    shutil.copy(tiny_model_dir / "model.safetensors", no_config)
    with pytest.raises(FinetuneError, match="config.json"):
        finetune(_cfg(no_config, synth_dir, built_dir, out), progress=False)
    with pytest.raises(FinetuneError, match=r"--mix must be in \[0, 1\]"):
        finetune(_cfg(tiny_model_dir, synth_dir, built_dir, out, mix=1.5), progress=False)
    assert not out.exists()


def test_cli_finetune(tiny_model_dir, synth_dir, built_dir, tmp_path) -> None:
    from tests.test_cli import run

    out = tmp_path / "ft"
    common = ["morph", "finetune", "--model", tiny_model_dir, "--synth", synth_dir, "--data", built_dir, "-o", out]
    res = run(*common, "--steps", "2")
    assert res.returncode == 0, res.stderr
    assert "fine-tuned to step 2" in res.stdout and (out / "model.safetensors").is_file()
    assert "synthetic" in res.stdout
    res = run(*common[:-1], tmp_path / "control", "--steps", "1", "--mix", "0")
    assert res.returncode == 0 and "real motions alone (--mix 0: the control)" in res.stdout, res.stderr
    weights = (out / "model.safetensors").read_bytes()
    res = run(*common, "--steps", "3")
    assert res.returncode == 1 and "--resume" in res.stderr and "Traceback" not in res.stderr
    res = run(*common, "--steps", "3", "--resume")
    assert res.returncode == 0 and "fine-tuned to step 3" in res.stdout
    other = make_synth(built_dir, DEFAULT_MODEL_DIR, tmp_path / "other", n=2)
    res = run("morph", "finetune", "--model", tiny_model_dir, "--synth", other, "--data", built_dir, "-o", tmp_path / "x")
    assert res.returncode == 1 and "another model" in res.stderr and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and not (tmp_path / "x").exists()
    assert weights != (out / "model.safetensors").read_bytes()


def test_a_finetuned_model_generates_in_every_mode(tiny_model_dir, synth_dir, built_dir, tmp_path) -> None:
    from physmotion.diffusion.samplers import SamplerConfig
    from physmotion.generate import GenerateConfig, generate
    from physmotion.physics.projection import ProjectionConfig

    finetune(_cfg(tiny_model_dir, synth_dir, built_dir, tmp_path / "ft", steps=2), progress=False)
    tuned = MotionDiffusion.load(tmp_path / "ft")
    # P resets at once where the tiny model's motions fall (nearly every step) rather than searching there
    base = GenerateConfig(seconds=2.0, sampler=SamplerConfig(steps=4),
                          projection=ProjectionConfig.sampling(recover=False))  # fmt: skip
    for mode in ("none", "none+floor", "post:1", "physdiff:end:1,space:1", "morph"):
        out = generate(["a person walks"], replace(base, physics=mode), tuned)
        assert out.motions[0].joints.shape == (40, 22, 3) and out.motions[0].licence_tag == "NC", mode


def test_help_defaults_are_the_dataclasses() -> None:
    from physmotion.morph.synth import SynthConfig
    from tests.test_cli import _help_defaults

    ft, syn = FinetuneConfig(model="", synth="", data="", out=""), SynthConfig()
    stated = _help_defaults("morph", "finetune")
    expected = {"mix": ft.mix, "lr": ft.lr, "steps": ft.steps, "tau": ft.tau, "seed": ft.seed, "floor": ft.floor}
    assert {k: v for k, v in stated.items() if k != "batch-size"} == {k: str(v) for k, v in expected.items()}
    stated = _help_defaults("morph", "run")
    expected = {"per-caption": syn.per_caption, "steps": ft.steps, "mix": ft.mix, "lr": ft.lr, "seed": ft.seed,
                "floor": ft.floor, "ilc": syn.ilc_passes}
    assert syn.captions is None and stated.pop("captions") == "all"
    assert stated == {k: str(v) for k, v in expected.items()}
    assert _help_defaults("morph", "synth")["ilc"] == str(syn.ilc_passes)
