"""Training the denoiser: DDPM (1000 steps, cosine), x0 loss, AdamW, EMA, gradient clipping, bf16 autocast
(by default only where the hardware has bf16 natively: :func:`physmotion.training.bf16_helps`).

MDM's recipe (GuyTevet/motion-diffusion-model, train/training_loop.py): predict x0, masked MSE on the
valid frames, classifier-free text dropout of 10%, AdamW with lr 1e-4. ``accelerate`` handles the device
(``--device cuda``), mixed precision and multi-GPU (``accelerate launch``); on one CPU process it is a
thin wrapper. diffusers' ``EMAModel`` keeps the exponential moving average that is saved for sampling.

Exact resumption without saving RNG streams: the batch order of epoch e is a permutation drawn from
``(seed, e)``, and the noise, timesteps, text dropout and dropout masks of step s come from generators
seeded by ``(seed, s)``. A resumed run therefore replays exactly the steps an uninterrupted run takes.
The output folder holds the model for sampling (EMA weights, :class:`MotionDiffusion`), ``train_state.pt``
(raw weights, optimizer, EMA, step) and ``loss.csv``; all are written atomically every few minutes.

Fine-tuning (Morph, Sec. 3.3: "we follow the original training setup, only adjusting the learning rate")
runs this same loop: ``init`` gives the starting weights and ``dataset`` the data (see
:mod:`physmotion.morph.finetune`).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from physmotion.conventions import MAX_FRAMES
from physmotion.data.dataset import MotionDataset, collate
from physmotion.nets.denoiser import DenoiserConfig, build_denoiser
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.schedule import DiffusionConfig, training_scheduler
from physmotion.errors import PhysmotionError
from physmotion.features.biomech import FEATURE_DIM_BIOMECH, SLICES_BIOMECH
from physmotion.features.humanml3d import FEATURE_DIM
from physmotion.motion import write_atomic
from physmotion.text.augment import rewrite_batch
from physmotion.text.encoder import load_text_encoder
from physmotion.training import (
    batch_indices,
    bf16_helps,
    check_finite,
    loss_bar,
    seed_dropout,
    seeded_generator,
    warmup_lr,
)

if TYPE_CHECKING:
    from accelerate import Accelerator
    from torch.utils.data import Dataset

STATE_FILE = "train_state.pt"
ACTIVATIONS_ORIGIN = ("no EMG: 8 channels of inverse-dynamics joint effort of the physmotion humanoid "
                      "(|torque| / actuator limit, physmotion.physics.activations), cached by "
                      "`physmotion data build --activations`")  # fmt: skip
LOSS_FILE = "loss.csv"


@dataclass
class TrainConfig:
    """Everything a training run depends on; saved with its checkpoints."""

    data: str
    out: str
    denoiser: DenoiserConfig = field(default_factory=DenoiserConfig)
    diffusion: DiffusionConfig = field(default_factory=DiffusionConfig)
    text_encoder: str = "minilm"
    crop: int = MAX_FRAMES  # training windows are cropped to at most this many frames
    # Motions of max_length + 4 frames or more are left out (HumanML3D's length filter). Lowering it
    # fine-tunes a model on the motions it was trained on: the default model saw those under 124 frames.
    max_length: int = MAX_FRAMES
    random_crop: bool = True  # HumanML3D's random windows and captions; False: the start, first caption
    batch_size: int = 32
    steps: int = 10000
    lr: float = 2e-4
    weight_decay: float = 0.01
    warmup: int = 200
    ema_decay: float = 0.999
    grad_clip: float = 1.0
    text_drop: float = 0.1
    # Probability of each caption rewrite (another subject, a shorter clause: physmotion.text.augment);
    # 0 trains on the captions as written (docs/decisions/data.md, "Caption rewrites").
    caption_aug: float = 0.0
    # BioMoDiffuse (Sec. 3.3, Eq. 8-9): with 329-d features the loss is L_diffusion (the 263 HumanML3D dims)
    # + accel_weight * L_accel (the 66 joint-acceleration dims of the output); "biomo" adds
    # phys_weight * L_phys (the physical network's accelerations) + emg_weight * L_emg (its activations
    # against the cached stand-ins), and drops the physical network with probability phys_drop (P_c).
    # accel_weight 0.1, not the paper's implicit 1: docs/decisions/biomodiffuse.md "L_accel's weight".
    accel_weight: float = 0.1
    phys_weight: float = 1.0
    emg_weight: float = 1.0
    phys_drop: float = 0.1
    # MDM's velocity loss (lambda_vel), here on the features: vel_weight * MSE of the frame-to-frame
    # differences of the predicted x0 against the true ones; 0 leaves it out (docs/decisions/sampling.md,
    # "velocity loss").
    vel_weight: float = 0.0
    bf16: bool | None = None  # bf16 autocast; None: where the hardware has it natively (bf16_helps)
    device: str = "cpu"
    seed: int = 0
    checkpoint_minutes: float = 5.0
    log_every: int = 25


@dataclass
class TrainResult:
    step: int
    losses: list[tuple[int, float]]  # (step, mean loss over the last log_every steps)
    seconds: float
    terms: list[dict[str, float]] = field(default_factory=list)  # per losses entry: each loss term's mean


def masked_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean squared error over valid frames: pred/target (B, T, D), mask (B, T) bool."""
    m = mask[..., None].to(pred.dtype)
    return ((pred - target) ** 2 * m).sum() / (m.sum() * pred.shape[-1]).clamp_min(1.0)


def _accelerator(cpu: bool, bf16: bool) -> Accelerator:
    """An Accelerator for one run. Accelerate keeps one state per process and refuses a second run with
    another precision; outside ``accelerate launch`` (one process) each run may start from a fresh one."""
    from accelerate import Accelerator
    from accelerate.state import AcceleratorState, DistributedType

    if AcceleratorState._shared_state and AcceleratorState().distributed_type == DistributedType.NO:
        AcceleratorState._reset_state(reset_partial_state=True)  # private, but the only way to reset
    return Accelerator(cpu=cpu, mixed_precision="bf16" if bf16 else "no")


def train_denoiser(
    cfg: TrainConfig,
    resume: bool = False,
    progress: bool = True,
    *,
    init: MotionDiffusion | None = None,
    dataset: Dataset | None = None,
    info: dict | None = None,
) -> TrainResult:
    """Train (or resume training) a text-to-motion denoiser on a HumanML3D-layout folder.

    ``cfg`` is not changed: what the run decides (the text and feature widths, bf16) goes into the copy
    that is saved with it.

    init: start from this model's weights and denoiser config instead of a fresh network (the EMA starts
    at them too); its text encoder and diffusion config must be ``cfg``'s. dataset: train on it instead of
    ``cfg.data``'s train split: items as :class:`MotionDataset`'s, a ``normalizer`` and ``set_epoch``, and
    optionally ``batch_indices(batch_size, seed, step) -> (epoch, indices)`` to compose its own batches.
    info: entries added to (or replacing) the saved model's ``info``."""
    from diffusers.training_utils import EMAModel

    out = Path(cfg.out)
    state_path = out / STATE_FILE
    if resume and not state_path.is_file():
        raise PhysmotionError(f"{out}: nothing to resume (no {STATE_FILE})")
    if not resume and state_path.is_file():
        raise PhysmotionError(f"{out} already holds a training run: pass --resume or choose another --out")
    if cfg.denoiser.max_frames < cfg.crop:
        raise PhysmotionError(f"crop {cfg.crop} is longer than the model's {cfg.denoiser.max_frames} frames")
    if not cfg.crop <= cfg.max_length <= MAX_FRAMES:
        raise PhysmotionError(f"max length {cfg.max_length} must lie between the crop ({cfg.crop}) and "
                              f"{MAX_FRAMES}")

    if not 0.0 <= cfg.caption_aug <= 1.0:
        raise PhysmotionError(f"caption rewrite probability {cfg.caption_aug} must lie between 0 and 1")

    # The crop sets the window length only; max_length decides which motions are kept. (Up to step 7904
    # the shipped model's run passed the crop as max_frames, which dropped the longer ones.)
    biomo = (init.denoiser if init is not None else cfg.denoiser).arch == "biomo"
    if dataset is None:
        if biomo:
            _check_biomo_data(cfg.data)
        dataset = MotionDataset(cfg.data, "train", crop=cfg.crop, random_crop=cfg.random_crop, seed=cfg.seed,
                                max_frames=cfg.max_length, activations=biomo)  # fmt: skip
    encoder = load_text_encoder(cfg.text_encoder)
    if init is not None:
        if init.text_encoder != cfg.text_encoder or init.diffusion != cfg.diffusion:
            raise PhysmotionError("the starting model's text encoder or diffusion config differs from the run's")
        if (init.denoiser.text_dim, init.denoiser.feature_dim) != (encoder.dim, dataset.normalizer.dim):
            raise PhysmotionError(f"the starting model takes {init.denoiser.feature_dim}-d features and "
                                  f"{init.denoiser.text_dim}-d text, the data {dataset.normalizer.dim}-d "
                                  f"and {encoder.dim}-d")  # fmt: skip
    denoiser = init.denoiser if init is not None else cfg.denoiser
    denoiser = replace(denoiser, text_dim=encoder.dim, feature_dim=dataset.normalizer.dim)
    cfg = replace(cfg, denoiser=denoiser)
    if cfg.bf16 is None:
        cfg = replace(cfg, bf16=bf16_helps(cfg.device))  # saved as decided
    accel = _accelerator(cfg.device == "cpu", cfg.bf16)
    torch.manual_seed(cfg.seed)
    net = build_denoiser(cfg.denoiser)
    if biomo:
        stats = dataset.normalizer
        net.physics.set_feature_stats(torch.from_numpy(stats.mean), torch.from_numpy(stats.std))
    if init is not None:
        net.load_state_dict(init.net.state_dict())
        # a fine-tuned model has seen its start's data too: its licence tags carry over (NC stays NC)
        tags = sorted(set(init.info.get("licence_tags", ["unknown"])) | set(_data_licence_tags(cfg.data)))
        info = {"licence_tags": tags} | (info or {})
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    # foreach: a few fused kernels per EMA update instead of several per tensor (launch-bound on a GPU)
    ema = EMAModel(net.parameters(), decay=cfg.ema_decay, foreach=cfg.device != "cpu")
    step, losses, terms, seconds_before = 0, [], [], 0.0
    if resume:
        state = torch.load(state_path, map_location="cpu", weights_only=False)
        net.load_state_dict(state["net"])
        opt.load_state_dict(state["opt"])
        ema.load_state_dict(state["ema"])
        step, losses = state["step"], [tuple(x) for x in state["losses"]]
        terms, seconds_before = state.get("terms", []), state.get("seconds", 0.0)
    net, opt = accel.prepare(net, opt)
    ema.to(accel.device)
    noise_sched = training_scheduler(cfg.diffusion)

    def save() -> None:
        seconds = seconds_before + time.monotonic() - t0  # training time over every resumed part
        _save(cfg, out, accel.unwrap_model(net), opt, ema, step, losses, terms, dataset,
              {"train_seconds": round(seconds, 1)} | (info or {}))  # fmt: skip

    t0 = last_save = time.monotonic()
    # On a GPU, reading the loss each step would wait for the device's queue: it is read once per log window
    # (the divergence check too); on the CPU nothing waits, and each step is checked as it comes.
    per_step_check = accel.device.type == "cpu"
    window: list[torch.Tensor] = []
    window_terms: dict[str, list[torch.Tensor]] = {}
    bar = loss_bar(progress, cfg.steps, step)
    net.train()
    while step < cfg.steps:
        if hasattr(dataset, "batch_indices"):  # a dataset that composes its batches (a fixed mix)
            epoch, idx = dataset.batch_indices(cfg.batch_size, cfg.seed, step)
        else:
            epoch, idx = batch_indices(len(dataset), cfg.batch_size, cfg.seed, step)
        dataset.set_epoch(epoch)
        batch = collate([dataset[i] for i in idx])
        x0, mask = batch["motion"].to(accel.device), batch["mask"].to(accel.device)
        captions = batch["text"]
        if cfg.caption_aug > 0:  # rewritten captions are one-offs: kept off the disk cache
            captions = rewrite_batch(captions, cfg.seed, step, cfg.caption_aug)
        text = encoder.encode(captions, persist=cfg.caption_aug == 0).to(accel.device)
        g = seeded_generator(cfg.seed, 2, step)
        t = torch.randint(0, cfg.diffusion.num_train_timesteps, (len(idx),), generator=g)
        if accel.device.type == "cpu":
            noise = torch.randn(x0.shape, generator=g)
        else:  # drawn on the device: 1.2x faster steps on an H200 (decisions "...ablation on a GPU")
            noise = torch.randn(x0.shape, generator=seeded_generator(cfg.seed, 3, step, device=accel.device),
                                device=accel.device)  # fmt: skip
        drop = torch.rand(len(idx), generator=g) < cfg.text_drop
        drop_phys = (torch.rand(len(idx), generator=g) < cfg.phys_drop).to(accel.device) if biomo else None
        xt = noise_sched.add_noise(x0, noise, t.to(x0.device))
        seed_dropout(g)  # dropout masks of this step
        for group in opt.param_groups:
            group["lr"] = warmup_lr(cfg.lr, cfg.warmup, step)
        with accel.autocast():
            if biomo:
                pred, acc, u = net(xt, t.to(accel.device), text, mask, drop.to(accel.device), drop_phys,
                                   physics=True)  # fmt: skip
            else:
                pred, acc, u = net(xt, t.to(accel.device), text, mask, drop.to(accel.device)), None, None
        parts = loss_terms(pred.float(), x0, mask, acc, u, batch.get("activations"), accel.unwrap_model(net),
                           velocity=cfg.vel_weight > 0)  # fmt: skip
        loss = _weighted(parts, cfg)
        if per_step_check:
            check_finite(loss, step)
        opt.zero_grad(set_to_none=True)
        accel.backward(loss)
        accel.clip_grad_norm_(net.parameters(), cfg.grad_clip)
        opt.step()
        ema.step(accel.unwrap_model(net).parameters())
        step += 1
        window.append(loss.detach())
        for name, value in parts.items():
            window_terms.setdefault(name, []).append(value.detach())
        if len(window) == cfg.log_every or step == cfg.steps:
            values = _read(window)
            if not per_step_check and not np.all(np.isfinite(values)):
                raise PhysmotionError(f"training diverged between steps {step - len(window) + 1} and {step}")
            losses.append((step, float(np.mean(values))))
            if len(window_terms) > 1 or terms:
                # a one-term run resumed with more terms: its earlier windows get empty cells in loss.csv
                terms.extend({} for _ in range(len(losses) - 1 - len(terms)))
                terms.append({k: float(np.mean(_read(v))) for k, v in window_terms.items()})
            window, window_terms = [], {}
        if bar is not None:
            bar.update(step, loss=losses[-1][1] if losses else loss.item())
        if time.monotonic() - last_save > cfg.checkpoint_minutes * 60 and accel.is_main_process:
            save()
            last_save = time.monotonic()
    if bar is not None:
        bar.close()
    if accel.is_main_process:
        save()
    return TrainResult(step=step, losses=losses, seconds=time.monotonic() - t0, terms=terms)


def _read(values: list[torch.Tensor]) -> np.ndarray:
    """Scalar tensors (of one log window) as float64, read off the device at once."""
    return torch.stack(values).double().cpu().numpy()


def loss_terms(
    pred: torch.Tensor,
    x0: torch.Tensor,
    mask: torch.Tensor,
    acc: torch.Tensor | None = None,
    u: torch.Tensor | None = None,
    activations: torch.Tensor | None = None,
    net: torch.nn.Module | None = None,
    velocity: bool = False,
) -> dict[str, torch.Tensor]:
    """The unweighted loss terms of one batch (normalised feature units).

    pred, x0: (B, T, D) predicted and true x0; mask (B, T). D = 263: ``diffusion`` only (MDM's x0 MSE).
    D = 329: ``diffusion`` over the 263 HumanML3D dims and ``accel`` (BioMoDiffuse's L_accel, Eq. 8) over
    the 66 joint-acceleration dims. With the physical network's acc (B, T, 22, 3) m/s^2 and u (B, T, 8):
    ``phys`` (L_phys: acc against the true accelerations) and ``emg`` (u against ``activations``).
    velocity: also ``vel``, the MSE of the first time differences over the HumanML3D dims (pairs of valid
    frames only), i.e. the frame-to-frame part of the error, where the samples' jerk lives."""
    hml, jacc = slice(0, FEATURE_DIM), SLICES_BIOMECH["joint_acc"]
    biomech = pred.shape[-1] == FEATURE_DIM_BIOMECH
    out = {"diffusion": masked_mse(pred[..., hml], x0[..., hml], mask)}
    if biomech:
        out["accel"] = masked_mse(pred[..., jacc], x0[..., jacc], mask)
    if velocity:
        d_pred, d_true = (v[:, 1:, hml] - v[:, :-1, hml] for v in (pred, x0))
        out["vel"] = masked_mse(d_pred, d_true, mask[:, 1:] & mask[:, :-1])
    if biomech and acc is not None and net is not None:
        out["phys"] = masked_mse(net.physics.to_features(acc.float()), x0[..., jacc], mask)
        if u is not None and activations is not None:
            out["emg"] = masked_mse(u.float(), activations.to(u.device), mask)
    return out


def _weighted(parts: dict[str, torch.Tensor], cfg: TrainConfig) -> torch.Tensor:
    weights = {"diffusion": 1.0, "accel": cfg.accel_weight, "phys": cfg.phys_weight, "emg": cfg.emg_weight,
               "vel": cfg.vel_weight}  # fmt: skip
    return sum(weights[k] * v for k, v in parts.items())


def _check_biomo_data(root: str | Path) -> None:
    """The biomo denoiser trains on a 329-d build with cached activations; say how to make one."""
    from physmotion.data.build import ACTIVATIONS
    from physmotion.features.normalize import Normalizer

    how = "build one with `physmotion data build --features 329 --activations`"
    if Normalizer.load(root).dim != FEATURE_DIM_BIOMECH:
        raise PhysmotionError(f"{root}: --arch biomo needs {FEATURE_DIM_BIOMECH}-d features; {how}")
    if not (Path(root) / ACTIVATIONS).is_dir():
        raise PhysmotionError(f"{root}: --arch biomo needs cached muscle activations; {how}")


def _data_licence_tags(data: str | Path) -> list[str]:
    """The licence tags a built dataset's ``build_info.json`` names (["unknown"] without one)."""
    path = Path(data) / "build_info.json"
    return json.loads(path.read_text()).get("licence_tags", ["unknown"]) if path.is_file() else ["unknown"]


def _save(cfg: TrainConfig, out: Path, net: torch.nn.Module, opt, ema, step: int, losses: list,
          terms: list, dataset: Dataset, extra: dict | None = None) -> None:  # fmt: skip
    """Checkpoint: resumable state first, then the EMA model for sampling, then the loss log."""
    state = {"net": net.state_dict(), "opt": opt.state_dict(), "ema": ema.state_dict(), "step": step,
             "losses": losses, "terms": terms, "seconds": (extra or {}).get("train_seconds", 0.0),
             "config": asdict(cfg)}  # fmt: skip
    write_atomic(out / STATE_FILE, lambda f: torch.save(state, f))
    ema_net = build_denoiser(cfg.denoiser)
    ema_net.load_state_dict(net.state_dict())  # buffers (the physical network's feature statistics) too:
    ema.copy_to(ema_net.parameters())  # the EMA holds the parameters only
    info = {"data": str(cfg.data), "licence_tags": _data_licence_tags(cfg.data),
            "train_items": len(dataset), "steps": step, "train": _summary(cfg)} | (extra or {})  # fmt: skip
    if cfg.denoiser.arch == "biomo":  # what a model card must say about the muscle term
        info["muscle_activations"] = ACTIVATIONS_ORIGIN
    MotionDiffusion(ema_net.eval(), cfg.denoiser, cfg.diffusion, dataset.normalizer, cfg.text_encoder, info).save(out)
    # A window where P_c dropped the physical network on every row has no phys/emg: the cell stays empty.
    names = list(dict.fromkeys(n for t in terms for n in t)) if terms and len(terms) == len(losses) else []
    lines = ",".join(["step", "loss", *names]) + "\n"
    for k, (s, v) in enumerate(losses):
        cells = (f"{terms[k][n]:.6f}" if n in terms[k] else "" for n in names)
        lines += ",".join([str(s), f"{v:.6f}", *cells]) + "\n"
    write_atomic(out / LOSS_FILE, lambda f: f.write(lines), "w")


def _summary(cfg: TrainConfig) -> dict:
    d = asdict(cfg)
    d.pop("denoiser"), d.pop("diffusion")
    return d
