"""Morph's Stage 2 (Sec. 3.3): fine-tune the motion generator on its own physics-refined motions.

The model's denoiser continues training from its EMA weights, with the training loop of
:func:`physmotion.diffusion.train.train_denoiser` ("we follow the original training setup, only adjusting
the learning rate to 1e-5"; our model trained at 2e-4), on the items that Morph's imitation selection
(:func:`physmotion.morph.selection.select`) keeps from a synthetic folder: the refined motion where P
imitated it, else the generated input. Each batch holds a fixed share ``mix`` of synthetic items, the
rest drawn from the real train split, so the model does not drift from the data it was trained on.
``mix`` 0 is the control: the same fine-tune (loss, steps, floor) on the real split alone, to tell what
the synthetic items add to what continued training on the re-floored real motions gives.

Features are normalised with the *model's* Mean/Std: the network's input space must not move under it.
By default every motion stands with the humanoid's soles on the floor (:mod:`physmotion.morph.floor`), so
the fine-tuned model learns where P puts the feet; the model records that convention (``info["floor"]``).
The output folder is a training run (model, ``train_state.pt``, ``loss.csv``) and resumes exactly.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from physmotion.checkpoint import CONFIG_FILE, WEIGHTS_FILE, weights_sha256
from physmotion.conventions import FLOOR_SURFACE, FLOORS, MAX_FRAMES, MIN_FRAMES
from physmotion.data.dataset import MotionDataset, MotionItem, collate, length_limit
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.train import TrainConfig, TrainResult, masked_mse, train_denoiser
from physmotion.errors import PhysmotionError
from physmotion.features.normalize import Normalizer
from physmotion.morph.floor import on_surface, selected_on_surface
from physmotion.morph.selection import TAU, Selection, read_synth_info, select
from physmotion.training import seeded_generator

SKELETON = "smpl22"
# Training settings taken from the base model's own run where FinetuneConfig leaves them unset (Sec. 3.3:
# the original setup); the learning rate is the one setting Morph changes.
# The base's loss terms (vel_weight) belong to that setup too, and so does its length filter
# (MotionDiffusion.trained_max_length, set in _prepare): without them a fine-tune of the default trains on
# windows and a loss it never saw (docs/decisions/morph.md: "Morph from the velocity-loss default"). Its caption
# rewrites too: without them a fine-tune loses wordings they taught ("Morph re-tuned from the shipped default").
INHERITED = ("batch_size", "crop", "random_crop", "warmup", "weight_decay", "ema_decay", "grad_clip",
             "text_drop", "vel_weight", "caption_aug", "log_every")  # fmt: skip


class FinetuneError(PhysmotionError):
    """A fine-tuning request that cannot run: a model, synthetic folder or data that do not belong together."""


@dataclass
class FinetuneConfig:
    """One fine-tuning run. Unset training settings (None) are the base model's run's."""

    model: str
    synth: str
    data: str
    out: str
    # Share of synthetic items in each batch; the rest from the real train split. 0.1 keeps FID at the
    # base's PhysDiff row where 0.25 and 0.5 did not (docs/decisions/morph.md: "a lower mix, 0.1").
    mix: float = 0.1
    lr: float = 1e-5  # Morph Sec. 4 "Training Setup": 1e-5 (the original runs used 2e-4 here)
    steps: int = 2000
    batch_size: int | None = None
    tau: float = TAU  # m: Morph's imitation selection threshold (Sec. 4)
    seed: int = 0
    checkpoint_minutes: float = 5.0
    warmup: int | None = None
    device: str = "cpu"
    bf16: bool | None = None
    # Floor convention of the training motions, and so of the fine-tuned model's samples: the soles on
    # the floor where P put them (FLOOR_SURFACE), or HumanML3D's lowest joint on y = 0 (FLOOR_JOINTS, as
    # the base model's data). docs/decisions/morph.md: "Morph fine-tuning on the physical floor".
    floor: str = FLOOR_SURFACE


@dataclass
class FinetuneResult:
    train: TrainResult
    selection: Selection
    synthetic_items: int  # selected items within the model's length range
    real_items: int
    rounds: int  # fine-tuning rounds behind the saved model (the base's plus this one)


class ItemDataset(MotionDataset):
    """:class:`MotionDataset`'s items and cropping over a given list of items and a given normaliser."""

    def __init__(self, items: list[MotionItem], normalizer: Normalizer, *, crop: int, random_crop: bool,
                 seed: int, unit_length: int = 4) -> None:  # fmt: skip
        # MotionDataset.__init__ reads a folder; everything __getitem__ needs is set here instead.
        self.root, self.items, self.normalizer = Path("."), items, normalizer
        self.crop, self.unit_length, self.random_crop, self.seed, self.epoch = crop, unit_length, random_crop, seed, 0


class MixedDataset:
    """Synthetic items then real ones, in batches that hold ``round(mix * batch)`` synthetic items.

    Indices 0..len(synth)-1 are the synthetic items, the rest the real ones. ``batch_indices`` draws
    each source's part from its own seeded epoch permutations, so a batch is a function of
    ``(seed, step)`` and a resumed run replays it. Both parts are normalised with ``synth.normalizer``.
    """

    def __init__(self, synth: MotionDataset, real: MotionDataset | None, mix: float) -> None:
        if real is None and mix < 1.0:
            raise FinetuneError("a mix below 1 needs the real train split")
        self.synth, self.real, self.mix = synth, real, mix
        self.normalizer = synth.normalizer
        if real is not None:
            real.normalizer = synth.normalizer

    def __len__(self) -> int:
        return len(self.synth) + (len(self.real) if self.real is not None else 0)

    def set_epoch(self, epoch: int) -> None:
        self.synth.set_epoch(epoch)
        if self.real is not None:
            self.real.set_epoch(epoch)

    def __getitem__(self, index: int) -> dict:
        n = len(self.synth)
        return self.synth[index] if index < n else self.real[index - n]

    def batch_indices(self, batch: int, seed: int, step: int) -> tuple[int, list[int]]:
        """(crop epoch, indices) of the batch at ``step``; the step itself keys the crops and captions."""
        n_synth = min(max(round(self.mix * batch), 1 if self.mix > 0 else 0), batch)
        idx = _part(len(self.synth), n_synth, seed, 0, step)
        if self.real is not None and batch > n_synth:
            idx += [len(self.synth) + i for i in _part(len(self.real), batch - n_synth, seed, 1, step)]
        return step, idx


def _part(n: int, take: int, seed: int, source: int, step: int) -> list[int]:
    """``take`` indices of 0..n-1 for ``step``: consecutive slices of seeded per-epoch permutations (all
    n where n < take)."""
    if take <= 0 or n <= 0:
        return []
    if n <= take:
        return torch.randperm(n, generator=seeded_generator(seed, 3, source, step)).tolist()
    per_epoch = n // take
    epoch, k = divmod(step, per_epoch)
    perm = torch.randperm(n, generator=seeded_generator(seed, 3, source, epoch)).tolist()
    return perm[k * take : (k + 1) * take]


def check_model_dir(model_dir: str | Path) -> Path:
    """A model folder with its config and weights, else FinetuneError."""
    model_dir = Path(model_dir)
    if not (model_dir / CONFIG_FILE).is_file() or not (model_dir / WEIGHTS_FILE).is_file():
        raise FinetuneError(f"{model_dir}: not a model folder (no {CONFIG_FILE} and {WEIGHTS_FILE})")
    return model_dir


def check_synth(synth_dir: str | Path, model_dir: str | Path, model: MotionDiffusion) -> dict:
    """synth.json of ``synth_dir`` when it was made by this very model (same weights' sha256), with its
    skeleton and feature width; else FinetuneError."""
    info = read_synth_info(synth_dir)
    sha = weights_sha256(model_dir)
    if info.get("model_sha256") != sha:
        raise FinetuneError(f"{synth_dir} was made by another model ({info.get('model', '?')}), not {model_dir}: "
                            "fine-tune the model that generated it")  # fmt: skip
    if info.get("skeleton", SKELETON) != SKELETON or info.get("feature_dim") != model.denoiser.feature_dim:
        raise FinetuneError(f"{synth_dir} holds {info.get('feature_dim')}-d features on skeleton "
                            f"{info.get('skeleton')!r}; the model takes {model.denoiser.feature_dim}-d on "
                            f"{SKELETON!r}")  # fmt: skip
    return info


def selected_items(selection: Selection, feature_dim: int, max_frames: int = MAX_FRAMES) -> list[MotionItem]:
    """The selected motions as dataset items (features not normalised), with the dataset's length filter.

    Raises FinetuneError where a file is missing or of another width, or where none is left."""
    items = []
    for sid, path, caption in selection.training_items():
        try:
            feats = np.load(path).astype(np.float32)
        except (OSError, ValueError) as exc:
            raise FinetuneError(f"{path}: unreadable synthetic motion ({exc})") from None
        if feats.ndim != 2 or feats.shape[1] != feature_dim or not np.all(np.isfinite(feats)):
            raise FinetuneError(f"{path}: expected finite (T, {feature_dim}) features, got {feats.shape}")
        if MIN_FRAMES <= len(feats) < length_limit(max_frames):  # load_items' HumanML3D filter
            items.append(MotionItem(sid, feats, [caption]))
    if not items:
        raise FinetuneError("the selection is empty: no synthetic motion within the model's length range")
    return items


def _licence_tags(*groups) -> list[str]:
    """The distinct tags of every group; a joined tag ("NC,SA", a synthetic motion's) counts as its parts."""
    tags = {part for g in groups for t in (g or []) for part in str(t).split(",") if part}
    return sorted(tags) or ["unknown"]


def _prepare(config: FinetuneConfig, progress: bool = False
             ) -> tuple[MotionDiffusion, TrainConfig, MixedDataset, dict, Selection, int]:  # fmt: skip
    """Every check and load of a run, before anything is written."""
    if config.floor not in FLOORS:
        raise FinetuneError(f"--floor must be one of {', '.join(FLOORS)}, got {config.floor!r}")
    if not 0.0 <= config.mix <= 1.0:
        raise FinetuneError(f"--mix must be in [0, 1] (the synthetic share of a batch; 0: the control "
                            f"on real motions alone), got {config.mix}")
    if not config.lr > 0 or config.steps < 1:
        raise FinetuneError(f"--lr must be positive and --steps at least 1, got {config.lr} and {config.steps}")
    model_dir = check_model_dir(config.model)
    model = MotionDiffusion.load(model_dir)
    check_synth(config.synth, model_dir, model)
    selection = select(config.synth, config.tau)
    max_length = model.trained_max_length
    # The control (mix 0) trains on no synthetic item: none is read or grounded.
    items = selected_items(selection, model.denoiser.feature_dim, max_length) if config.mix > 0 else []
    if config.floor == FLOOR_SURFACE and items:
        refined = {s.id: s.features_path.parent.parent / "new_joints" / s.features_path.name
                   for s in selection.items if s.source == "refined"}  # fmt: skip
        items = selected_on_surface(items, refined, progress)
    base_train = model.info.get("train", {})
    given = {"batch_size": config.batch_size, "warmup": config.warmup}
    train = {k: base_train[k] for k in INHERITED if k in base_train} | {k: v for k, v in given.items() if v is not None}
    train["crop"] = min(train.get("crop", model.denoiser.max_frames), model.denoiser.max_frames)
    train["max_length"] = max_length
    cfg = TrainConfig(data=str(config.data), out=str(config.out), denoiser=model.denoiser,
                      diffusion=model.diffusion, text_encoder=model.text_encoder, steps=config.steps,
                      lr=config.lr, seed=config.seed, checkpoint_minutes=config.checkpoint_minutes,
                      device=config.device, bf16=config.bf16, **train)  # fmt: skip
    synth = ItemDataset(items, model.normalizer, crop=cfg.crop, random_crop=cfg.random_crop, seed=cfg.seed)
    real = None
    data_tags: list[str] = []
    if config.mix < 1.0:
        real = MotionDataset(config.data, "train", crop=cfg.crop, random_crop=cfg.random_crop, seed=cfg.seed,
                             normalize=False, max_frames=max_length)  # fmt: skip
        dim = real.items[0].features.shape[-1]
        if dim != model.denoiser.feature_dim:
            raise FinetuneError(f"{config.data} holds {dim}-d features; the model takes {model.denoiser.feature_dim}-d")
        if config.floor == FLOOR_SURFACE:
            real.items = on_surface(real.items, progress, "grounding real motions")
        build_info = Path(config.data) / "build_info.json"
        data_tags = json.loads(build_info.read_text()).get("licence_tags", []) if build_info.is_file() else ["unknown"]
    dataset = MixedDataset(synth, real, config.mix)
    base_morph = model.info.get("morph", {})
    rounds = int(base_morph.get("rounds", 0)) + 1
    info = {
        # Union of the generator's, the synthetic items' and the real data's tags: an NC clip anywhere
        # behind the weights keeps the fine-tuned model NC.
        "licence_tags": _licence_tags(model.info.get("licence_tags"), selection.licence_tags, data_tags),
        "floor": config.floor,
        "morph": {"base_model": str(model_dir), "base_model_sha256": weights_sha256(model_dir),
                  "synth": str(config.synth), "rounds": rounds,
                  "selected": {"refined": selection.counts.get("refined", 0),
                               "input": selection.counts.get("input", 0)},
                  "counts": dict(selection.counts), "ifr": selection.ifr, "tau": config.tau, "mix": config.mix,
                  "lr": config.lr, "steps": config.steps, "synthetic_items": len(items),
                  "real_items": len(real) if real is not None else 0},
        "base_info": {k: v for k, v in model.info.items() if k != "base_info"},
    }  # fmt: skip
    return model, cfg, dataset, info, selection, rounds


def finetune(config: FinetuneConfig, resume: bool = False, progress: bool = True) -> FinetuneResult:
    """Fine-tune ``config.model`` on the selection of ``config.synth`` mixed with ``config.data``'s train
    split; the run (model, ``train_state.pt``, ``loss.csv``) goes to ``config.out``.

    Every check runs before anything is written: a model folder without config or weights, a synthetic
    folder made by another model or for another skeleton or feature width, or an empty selection raise
    FinetuneError (or the selection's SelectionError) and leave ``config.out`` as it was."""
    model, cfg, dataset, info, selection, rounds = _prepare(config, progress)
    result = train_denoiser(cfg, resume=resume, progress=progress, init=model, dataset=dataset, info=info)
    return FinetuneResult(train=result, selection=selection, synthetic_items=len(dataset.synth),
                          real_items=len(dataset.real) if dataset.real is not None else 0, rounds=rounds)  # fmt: skip


@torch.no_grad()
def denoising_loss(model: MotionDiffusion, items: list[MotionItem], seed: int = 0, repeats: int = 4,
                   crop: int | None = None) -> float:  # fmt: skip
    """The x0 training loss of ``model`` on ``items`` (features not normalised), averaged over ``repeats``
    draws of timestep and noise seeded by ``seed``: the same draws for any model, so two models compare.
    Windows are each item's first ``crop`` frames (default the model's length), the caption its first."""
    from physmotion.diffusion.schedule import training_scheduler
    from physmotion.text.encoder import load_text_encoder

    crop = crop or model.denoiser.max_frames
    batch = collate([{"motion": torch.from_numpy(model.normalizer.normalize(it.features[:crop]).astype(np.float32)),
                      "length": min(len(it.features), crop), "text": it.captions[0], "id": it.id}
                     for it in items])  # fmt: skip
    text = load_text_encoder(model.text_encoder).encode(batch["text"])
    sched = training_scheduler(model.diffusion)
    net = model.net.eval()
    losses = []
    for r in range(repeats):
        g = seeded_generator(seed, 4, r)
        x0, mask = batch["motion"], batch["mask"]
        t = torch.randint(0, model.diffusion.num_train_timesteps, (len(items),), generator=g)
        xt = sched.add_noise(x0, torch.randn(x0.shape, generator=g), t)
        pred = net(xt, t, text, mask, torch.zeros(len(items), dtype=torch.bool))
        losses.append(float(masked_mse(pred.float(), x0, mask)))
    return float(np.mean(losses))
