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


def test_resuming_with_a_new_loss_term_logs_it(built_dir: Path, tmp_path: Path) -> None:
    """A run without the velocity loss, resumed with it: loss.csv gains its columns, empty before."""
    out = tmp_path / "run"
    train_denoiser(tiny_config(built_dir, out, steps=5), progress=False)
    train_denoiser(tiny_config(built_dir, out, steps=10, vel_weight=1.0), resume=True, progress=False)
    header, first, second = (out / "loss.csv").read_text().splitlines()
    assert header == "step,loss,diffusion,vel" and first.endswith(",,")
    step, loss, diffusion, vel = map(float, second.split(","))
    assert step == 10 and loss == pytest.approx(diffusion + vel, abs=2e-6)


def test_resume_and_overwrite_guards(built_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(PhysmotionError, match="nothing to resume"):
        train_denoiser(tiny_config(built_dir, tmp_path / "none"), resume=True, progress=False)
    train_denoiser(tiny_config(built_dir, tmp_path / "run", steps=1), progress=False)
    with pytest.raises(PhysmotionError, match="--resume"):
        train_denoiser(tiny_config(built_dir, tmp_path / "run", steps=2), progress=False)


def test_max_length_leaves_out_the_longer_motions(built_dir: Path, tmp_path: Path) -> None:
    """max_length filters as HumanML3D does (fewer than max_length + 4 frames); the crop only cuts."""
    from physmotion.data.dataset import load_items

    lengths = [len(item.features) for item in load_items(built_dir, "train")]
    train_denoiser(tiny_config(built_dir, tmp_path / "short", steps=1, max_length=80), progress=False)
    train_denoiser(tiny_config(built_dir, tmp_path / "all", steps=1), progress=False)
    short = json.loads((tmp_path / "short" / "config.json").read_text())["info"]["train_items"]
    every = json.loads((tmp_path / "all" / "config.json").read_text())["info"]["train_items"]
    assert every == len(lengths) and 0 < short == sum(n < 84 for n in lengths) < every
    with pytest.raises(PhysmotionError, match="between the crop"):
        train_denoiser(tiny_config(built_dir, tmp_path / "bad", max_length=32), progress=False)


@pytest.mark.slow
def test_fine_tuning_keeps_the_starting_models_licence_tags(built_dir: Path, tiny_model: MotionDiffusion,
                                                            tmp_path: Path) -> None:  # fmt: skip
    """A model fine-tuned from another has seen that one's data too: its tags join the build's."""
    start = copy.copy(tiny_model)
    start.info = tiny_model.info | {"licence_tags": ["NC-other-source"]}
    out = tmp_path / "ft"
    train_denoiser(tiny_config(built_dir, out, steps=1, d_model=32, layers=1), init=start, progress=False)
    build_tags = json.loads((built_dir / "build_info.json").read_text())["licence_tags"]
    assert MotionDiffusion.load(out).info["licence_tags"] == sorted({"NC-other-source", *build_tags})


@pytest.mark.slow  # a real training loop until the loss drops
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


# --- BioMoDiffuse: the 329-d loss terms, arch "biomo" on the 329-d build with its activations ---

import os

from physmotion.nets.backbone import DenoiserConfig
from physmotion.nets.denoiser import build_denoiser
from physmotion.nets.physnet import BioMoDenoiser
from physmotion.diffusion.train import LOSS_FILE, loss_terms
from tests.conftest import tiny_biomo_config


def _mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> float:
    """Mean squared error over the valid frames' entries, in numpy."""
    p, q, m = pred.detach().double().numpy(), target.double().numpy(), mask.numpy()
    return float(((p - q) ** 2)[m].mean())


def _batch(dim: int, seed: int = 0):
    gen = torch.Generator().manual_seed(seed)
    pred, x0 = torch.randn(3, 20, dim, generator=gen), torch.randn(3, 20, dim, generator=gen)
    mask = torch.arange(20)[None] < torch.tensor([20, 12, 5])[:, None]
    return pred, x0, mask


def _biomo_net(root: Path) -> BioMoDenoiser:
    net = BioMoDenoiser(DenoiserConfig(arch="biomo", feature_dim=329, d_model=32, layers=2, phys_hidden=32))
    mean, std = np.load(root / "Mean.npy"), np.load(root / "Std.npy")
    net.physics.set_feature_stats(torch.from_numpy(mean), torch.from_numpy(std))
    return net


def _rows(path: Path) -> tuple[list[str], list[list[float]]]:
    lines = path.read_text().splitlines()
    return lines[0].split(","), [[float(v) for v in line.split(",")] for line in lines[1:]]


def test_loss_terms_of_263_and_329_features() -> None:
    pred, x0, mask = _batch(263)
    parts = loss_terms(pred, x0, mask)
    assert set(parts) == {"diffusion"}
    assert float(parts["diffusion"]) == pytest.approx(_mse(pred, x0, mask), rel=1e-5)
    pred, x0, mask = _batch(329)
    pred[2, 5:] = 1e3  # padding of the last row: ignored
    parts = loss_terms(pred, x0, mask)
    assert set(parts) == {"diffusion", "accel"}
    assert float(parts["diffusion"]) == pytest.approx(_mse(pred[..., :263], x0[..., :263], mask), rel=1e-5)
    assert float(parts["accel"]) == pytest.approx(_mse(pred[..., 263:], x0[..., 263:], mask), rel=1e-5)
    pred[..., 263:] = x0[..., 263:]  # exact joint accelerations: no L_accel, L_diffusion unchanged
    again = loss_terms(pred, x0, mask)
    assert float(again["accel"]) == 0.0 and float(again["diffusion"]) == pytest.approx(float(parts["diffusion"]))


def test_velocity_term_sees_only_the_frame_to_frame_error() -> None:
    pred, x0, mask = _batch(263)
    offset = x0 + 0.5  # the same error in every frame: an x0 loss, no velocity loss
    parts = loss_terms(offset, x0, mask, velocity=True)
    assert set(parts) == {"diffusion", "vel"}
    assert float(parts["vel"]) == pytest.approx(0.0, abs=1e-10)
    assert float(parts["diffusion"]) == pytest.approx(0.25)
    flicker = x0 + 0.5 * (-1.0) ** torch.arange(x0.shape[1])[None, :, None]  # +-0.5 alternating: jerk
    parts = loss_terms(flicker, x0, mask, velocity=True)
    assert float(parts["diffusion"]) == pytest.approx(0.25) and float(parts["vel"]) == pytest.approx(1.0)
    flicker[2, 5:] = 1e3  # the last row's padding: neither its frames nor the pair across its end count
    assert float(loss_terms(flicker, x0, mask, velocity=True)["vel"]) == pytest.approx(1.0)
    pred, x0, mask = _batch(329)
    parts = loss_terms(pred, x0, mask, velocity=True)  # 329-d: over the 263 HumanML3D dims, beside L_accel
    assert set(parts) == {"diffusion", "accel", "vel"}
    d = (pred - x0)[..., :263]
    pairs = mask[:, 1:] & mask[:, :-1]
    assert float(parts["vel"]) == pytest.approx(_mse(d[:, 1:], d[:, :-1], pairs), rel=1e-5)


def test_loss_terms_of_the_physical_network(built329_dir: Path) -> None:
    """L_phys compares the network's m/s^2 with the data's joint_acc in the data's units; L_emg its
    activations with the cached ones."""
    net = _biomo_net(built329_dir)
    pred, x0, mask = _batch(329, seed=1)
    gen = torch.Generator().manual_seed(2)
    acc = torch.randn(3, 20, 22, 3, generator=gen) * 10
    u, acts = torch.rand(3, 20, 8, generator=gen), torch.rand(3, 20, 8, generator=gen)
    parts = loss_terms(pred, x0, mask, acc, u, acts, net)
    assert set(parts) == {"diffusion", "accel", "phys", "emg"}
    assert float(parts["phys"]) == pytest.approx(_mse(net.physics.to_features(acc), x0[..., 263:], mask), rel=1e-5)
    assert float(parts["emg"]) == pytest.approx(_mse(u, acts, mask), rel=1e-5)
    assert set(loss_terms(pred, x0, mask, acc, u, None, net)) == {"diffusion", "accel", "phys"}
    assert set(loss_terms(pred, x0, mask, None, None, acts, net)) == {"diffusion", "accel"}
    # the true accelerations in m/s^2 (joint_acc x fps^2) and the true activations give zero
    mean, std = np.load(built329_dir / "Mean.npy")[263:], np.load(built329_dir / "Std.npy")[263:]
    true_acc = ((x0[..., 263:].double().numpy() * std + mean) * 400.0).reshape(3, 20, 22, 3)
    exact = loss_terms(pred, x0, mask, torch.from_numpy(true_acc).float(), acts, acts, net)
    assert float(exact["phys"]) < 1e-8 and float(exact["emg"]) == 0.0
    per_frame = loss_terms(pred, x0, mask, torch.from_numpy(true_acc / 400.0).float(), u, acts, net)
    assert float(per_frame["phys"]) > 1e-3  # metres per frame^2 are not m/s^2


@pytest.mark.slow
def test_biomo_loss_goes_down_on_the_329_build(built329_dir: Path, tmp_path: Path) -> None:
    cfg = tiny_biomo_config(built329_dir, tmp_path / "run", steps=40, log_every=10)
    result = train_denoiser(cfg, progress=False)
    assert len(result.terms) == len(result.losses) == 4
    first, last = result.losses[0][1], result.losses[-1][1]
    assert last < 0.7 * first, result.losses
    for name in ("phys", "emg"):
        assert result.terms[-1][name] < 0.8 * result.terms[0][name], result.terms
    header, rows = _rows(tmp_path / "run" / LOSS_FILE)
    assert header == ["step", "loss", "diffusion", "accel", "phys", "emg"] and len(rows) == 4
    assert [r[0] for r in rows] == [10, 20, 30, 40]


def test_loss_csv_columns_and_weights(built329_dir: Path, tiny_model_dir: Path, tmp_path: Path) -> None:
    """loss.csv: one column per loss term for 329-d runs, the total their weighted sum; 263-d: step,loss."""
    cfg = tiny_biomo_config(built329_dir, tmp_path / "bio", steps=4, log_every=2, accel_weight=0.5, phys_weight=2.0,
                            emg_weight=3.0)  # fmt: skip
    result = train_denoiser(cfg, progress=False)
    header, rows = _rows(tmp_path / "bio" / LOSS_FILE)
    assert header == ["step", "loss", "diffusion", "accel", "phys", "emg"] and len(rows) == 2
    for (step, loss, diffusion, accel, phys, emg), terms in zip(rows, result.terms):
        assert loss == pytest.approx(diffusion + 0.5 * accel + 2.0 * phys + 3.0 * emg, abs=2e-5)
        assert emg == pytest.approx(terms["emg"], abs=1e-6)
    # a 329-d UNet: L_diffusion + L_accel only
    unet = replace(cfg, out=str(tmp_path / "unet"), denoiser=replace(cfg.denoiser, arch="unet"))
    train_denoiser(unet, progress=False)
    header, rows = _rows(tmp_path / "unet" / LOSS_FILE)
    assert header == ["step", "loss", "diffusion", "accel"]
    assert all(loss == pytest.approx(diffusion + 0.5 * accel, abs=2e-5) for _, loss, diffusion, accel in rows)
    assert (tiny_model_dir / LOSS_FILE).read_text().splitlines()[0] == "step,loss"
    # the resumable state holds the data's joint_acc statistics in the physical network
    state = torch.load(tmp_path / "bio" / STATE_FILE, weights_only=False)
    mean = torch.from_numpy(np.load(built329_dir / "Mean.npy"))
    assert torch.equal(state["net"]["physics.acc_mean"], mean[263:329])


def test_dropping_physics_always_leaves_the_physical_network_untrained(built329_dir: Path, tmp_path: Path) -> None:
    """P_c = 1: the physical network never runs, so its weights stay at their initial values, L_phys and
    L_emg never appear, and their weights change nothing."""
    a = tiny_biomo_config(built329_dir, tmp_path / "a", steps=3, log_every=3, phys_drop=1.0)
    b = tiny_biomo_config(built329_dir, tmp_path / "b", steps=3, log_every=3, phys_drop=1.0, phys_weight=5.0,
                          emg_weight=0.0)  # fmt: skip
    ra, rb = train_denoiser(a, progress=False), train_denoiser(b, progress=False)
    assert ra.losses == rb.losses and set(ra.terms[0]) == {"diffusion", "accel"}
    assert _rows(tmp_path / "a" / LOSS_FILE)[0] == ["step", "loss", "diffusion", "accel"]
    sa = torch.load(tmp_path / "a" / STATE_FILE, weights_only=False)["net"]
    sb = torch.load(tmp_path / "b" / STATE_FILE, weights_only=False)["net"]
    torch.manual_seed(a.seed)
    fresh = build_denoiser(replace(a.denoiser, text_dim=384)).state_dict()
    for k in sa:
        assert torch.equal(sa[k], sb[k]), k
        if k.startswith("physics.") and "acc_" not in k:
            assert torch.equal(sa[k], fresh[k]), k
    assert not torch.equal(sa["unet.in_conv.weight"], fresh["unet.in_conv.weight"])  # the UNet did train


def test_biomo_resume_continues_exactly(built329_dir: Path, tmp_path: Path) -> None:
    """4 steps in one go == 2 steps, stop, resume to 4 (the P_c draws included), loss.csv too."""
    whole, split = tmp_path / "whole", tmp_path / "split"
    train_denoiser(tiny_biomo_config(built329_dir, whole, steps=4, log_every=2, phys_drop=0.5), progress=False)
    train_denoiser(tiny_biomo_config(built329_dir, split, steps=2, log_every=2, phys_drop=0.5), progress=False)
    train_denoiser(tiny_biomo_config(built329_dir, split, steps=4, log_every=2, phys_drop=0.5), resume=True,
                   progress=False)  # fmt: skip
    a = torch.load(whole / STATE_FILE, weights_only=False)
    b = torch.load(split / STATE_FILE, weights_only=False)
    assert a["step"] == b["step"] == 4
    for k in a["net"]:
        assert torch.equal(a["net"][k], b["net"][k]), k
    assert (whole / LOSS_FILE).read_text() == (split / LOSS_FILE).read_text()


def _without_activations(src: Path, dst: Path) -> Path:
    """The build ``src`` without its activation cache (everything else linked in)."""
    dst.mkdir()
    for entry in src.iterdir():
        if entry.name != "activations":
            os.symlink(entry, dst / entry.name)
    return dst


def test_biomo_needs_the_329_build_with_activations(built_dir: Path, built329_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(PhysmotionError, match="329") as err:
        train_denoiser(tiny_biomo_config(built_dir, tmp_path / "a"), progress=False)
    assert "\n" not in str(err.value) and not (tmp_path / "a" / STATE_FILE).exists()
    bare = _without_activations(built329_dir, tmp_path / "bare")
    with pytest.raises(PhysmotionError, match="activations") as err:
        train_denoiser(tiny_biomo_config(bare, tmp_path / "b"), progress=False)
    assert "\n" not in str(err.value) and not (tmp_path / "b" / STATE_FILE).exists()


@pytest.mark.parametrize("seed", [1, 3])
def test_loss_csv_of_a_biomo_run_whose_log_windows_drop_the_physics(
    built329_dir: Path, tmp_path: Path, seed: int
) -> None:
    """With small batches some log windows have every row's physical network dropped (P_c), so they
    have no L_phys / L_emg. The run must still finish and write one loss.csv column set for the whole
    run. (With batch 1, P_c 0.5 and a row per step: seed 1 has physics in the first window and not in a
    later one, seed 3 none in the first.)"""
    cfg = tiny_biomo_config(built329_dir, tmp_path / "run", steps=6, log_every=1, batch_size=1, phys_drop=0.5,
                            seed=seed)  # fmt: skip
    result = train_denoiser(cfg, progress=False)
    present = [{"phys", "emg"} <= set(t) for t in result.terms]
    assert any(present) and not all(present)  # the case this test is about
    lines = (tmp_path / "run" / LOSS_FILE).read_text().splitlines()
    assert lines[0] == "step,loss,diffusion,accel,phys,emg"
    assert [int(line.split(",")[0]) for line in lines[1:]] == [1, 2, 3, 4, 5, 6]
    assert all(line.count(",") == 5 for line in lines[1:])


def test_a_biomo_model_says_where_its_activations_come_from(tiny_biomo, tiny_model) -> None:
    """The model's info carries the muscle term's origin (no EMG), for its model card."""
    from physmotion.diffusion.train import ACTIVATIONS_ORIGIN

    assert tiny_biomo.info["muscle_activations"] == ACTIVATIONS_ORIGIN and "no EMG" in ACTIVATIONS_ORIGIN
    assert "muscle_activations" not in tiny_model.info


def test_caption_rewrites_train_and_stay_off_the_disk_cache(
    small_built_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With every caption rewritten (p = 1) the run trains and resumes exactly, and the disk cache gains
    only captions as the data write them, none of the one-off rewrites."""
    from physmotion.data.dataset import read_captions
    from physmotion.text.encoder import load_text_encoder

    encoder = load_text_encoder("minilm")
    disk = tmp_path / "cache"  # this test's own cache folder: other xdist workers write to the shared one
    monkeypatch.setattr(encoder, "disk", disk)
    monkeypatch.setattr(encoder, "_cache", {})
    whole, split = tmp_path / "whole", tmp_path / "split"
    train_denoiser(tiny_config(small_built_dir, whole, steps=4, caption_aug=1.0), progress=False)
    train_denoiser(tiny_config(small_built_dir, split, steps=2, caption_aug=1.0), progress=False)
    train_denoiser(tiny_config(small_built_dir, split, steps=4, caption_aug=1.0), resume=True, progress=False)
    a, b = (torch.load(p / STATE_FILE, weights_only=False)["net"] for p in (whole, split))
    assert all(torch.equal(a[k], b[k]) for k in a)
    written = {str(np.load(f)["text"]) for f in disk.glob("*.npz")}
    data = {c for f in (small_built_dir / "texts").glob("*.txt") for c, _, _ in read_captions(f)}
    assert written <= data, sorted(written - data)[:5]
    with pytest.raises(PhysmotionError, match="between 0 and 1"):
        train_denoiser(tiny_config(small_built_dir, tmp_path / "bad", caption_aug=1.5), progress=False)
