"""Training the evaluator: TMR's filtered contrastive loss on the train split, model chosen on val.

Recipe (TMR, github.com/Mathux/TMR ``configs/``): AdamW, lr 1e-4, batch 32, temperature 0.1, negative
filtering at caption similarity 0.8. Our train split is small (652 motions), so instead of TMR's fixed
epoch count we score retrieval on the val split every few epochs and keep the best weights: the
contrastive loss keeps falling long after val retrieval has stopped improving. The random windows and
captions of each item follow HumanML3D's training crops (:class:`MotionDataset`).

The output folder is an evaluator folder (:class:`Evaluator`) whose ``info`` records the data, its licence
tags, the training summary and val/test retrieval with the shuffled-caption control.
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from physmotion.data.dataset import MotionDataset, collate, load_items
from physmotion.errors import PhysmotionError
from physmotion.eval.evaluator import Evaluator, EvaluatorConfig, EvaluatorNet, contrastive_loss
from physmotion.eval.retrieval import BATCH, retrieval
from physmotion.motion import write_atomic
from physmotion.text.encoder import load_text_encoder
from physmotion.training import (
    batch_indices,
    check_finite,
    loss_bar,
    seed_dropout,
    seeded_generator,
    warmup_lr,
)

LOSS_FILE = "loss.csv"


@dataclass
class EvaluatorTrainConfig:
    """Everything an evaluator training run depends on."""

    data: str
    out: str
    evaluator: EvaluatorConfig = field(default_factory=EvaluatorConfig)
    epochs: int = 150  # the shipped evaluator: val retrieval plateaus after about 50
    batch_size: int = BATCH
    lr: float = 1e-4
    weight_decay: float = 0.01
    warmup: int = 100
    grad_clip: float = 1.0
    eval_every: int = 5  # epochs between val retrieval checks
    eval_repeats: int = 5
    seed: int = 0
    device: str = "cpu"


@dataclass
class EvaluatorTrainResult:
    evaluator: Evaluator
    best_epoch: int
    val: dict  # retrieval at the kept weights
    test: dict | None  # ... on the test split, own captions and shuffled ones
    seconds: float


def train_evaluator(cfg: EvaluatorTrainConfig, progress: bool = True) -> EvaluatorTrainResult:
    """Train an evaluator on ``cfg.data``'s train split and write it to ``cfg.out``.

    ``cfg`` is not changed: the text and feature widths the run takes from its data go into a copy."""
    out = Path(cfg.out)
    if (out / "model.safetensors").is_file():
        raise PhysmotionError(f"{out} already holds a model: choose another --out")
    c = cfg.evaluator
    dataset = MotionDataset(cfg.data, "train", max_frames=c.max_frames, random_crop=True, seed=cfg.seed)
    if len(dataset) < cfg.batch_size:
        raise PhysmotionError(f"{cfg.data}: the train split has {len(dataset)} motions, fewer than a batch")
    val_items = _items_or_none(cfg.data, "val", c.max_frames, cfg.batch_size)
    encoder = load_text_encoder(c.text_encoder)
    c = replace(c, text_dim=encoder.dim, feature_dim=dataset.normalizer.dim)
    cfg = replace(cfg, evaluator=c)
    torch.manual_seed(cfg.seed)
    net = EvaluatorNet(c).to(cfg.device)
    evaluator = Evaluator(net, c, dataset.normalizer, _info(cfg, len(dataset)))
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    per_epoch = len(dataset) // cfg.batch_size
    total = cfg.epochs * per_epoch
    best = (-1.0, 0, copy.deepcopy(net.state_dict()), {})
    losses: list[tuple[int, float]] = []
    history: list[dict] = []  # val retrieval at each check
    window: list[float] = []
    bar = loss_bar(progress, total, 0, "training evaluator")
    t0 = time.monotonic()
    for step in range(total):
        net.train()
        epoch, idx = batch_indices(len(dataset), cfg.batch_size, cfg.seed, step)
        dataset.set_epoch(epoch)
        batch = collate([dataset[i] for i in idx])
        text = encoder.encode(batch["text"])
        x = batch["motion"][..., : c.motion_in].to(cfg.device)
        g = seeded_generator(cfg.seed, 2, step)
        seed_dropout(g)  # this step's dropout masks
        for group in opt.param_groups:
            group["lr"] = warmup_lr(cfg.lr, cfg.warmup, step)
        t_emb = net.embed_text(text.to(cfg.device))
        m_emb = net.embed_motion(x, batch["mask"].to(cfg.device))
        caption_sim = (text.pooled @ text.pooled.T).to(cfg.device)
        loss = contrastive_loss(t_emb, m_emb, caption_sim, c.temperature, c.filter_threshold)
        check_finite(loss, step, "evaluator training")
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.grad_clip)
        opt.step()
        window.append(loss.item())
        if (step + 1) % per_epoch == 0:
            losses.append((epoch + 1, float(np.mean(window))))
            window = []
            last = epoch + 1 == cfg.epochs
            if val_items is not None and ((epoch + 1) % cfg.eval_every == 0 or last):
                net.eval()
                val = retrieval(evaluator, val_items, repeats=cfg.eval_repeats, seed=cfg.seed).to_dict()
                score = val["R@1"]["mean"] + val["R@3"]["mean"]
                history.append({"epoch": epoch + 1, "R@1": val["R@1"]["mean"], "R@3": val["R@3"]["mean"]})
                if score > best[0]:
                    best = (score, epoch + 1, copy.deepcopy(net.state_dict()), val)
        if bar is not None:
            bar.update(step + 1, losses[-1][1] if losses else loss.item())
    if bar is not None:
        bar.close()
    if val_items is not None:  # keep the weights that retrieved best on val
        net.load_state_dict(best[2])
    net.eval()
    best_epoch = best[1] if val_items is not None else cfg.epochs
    test = _test_report(evaluator, cfg)
    evaluator.info.update(best_epoch=best_epoch, val_retrieval=best[3], val_history=history, test_retrieval=test,
                          train_minutes=round((time.monotonic() - t0) / 60, 2))  # fmt: skip
    evaluator.save(out)
    lines = "epoch,loss\n" + "".join(f"{e},{v:.6f}\n" for e, v in losses)
    write_atomic(out / LOSS_FILE, lambda f: f.write(lines), "w")
    return EvaluatorTrainResult(evaluator, best_epoch, best[3], test, time.monotonic() - t0)


def _items_or_none(root: str, split: str, max_frames: int, batch: int):
    """The split's items, or None when it is missing or smaller than one retrieval batch."""
    try:
        items = load_items(root, split, max_frames=max_frames)
    except PhysmotionError:
        return None
    return items if len(items) >= batch else None


def _test_report(evaluator: Evaluator, cfg: EvaluatorTrainConfig) -> dict | None:
    items = _items_or_none(cfg.data, "test", cfg.evaluator.max_frames, cfg.batch_size)
    if items is None:
        return None
    own = retrieval(evaluator, items, repeats=20, seed=cfg.seed)
    shuffled = retrieval(evaluator, items, repeats=20, seed=cfg.seed, shuffle_texts=True)
    return {"own_captions": own.to_dict(), "shuffled_captions": shuffled.to_dict()}


def _info(cfg: EvaluatorTrainConfig, train_items: int) -> dict:
    build_path = Path(cfg.data) / "build_info.json"
    build = json.loads(build_path.read_text()) if build_path.is_file() else {}
    summary = asdict(cfg)
    summary.pop("evaluator")
    return {"data": str(cfg.data), "licence_tags": build.get("licence_tags", ["unknown"]),
            "train_items": train_items, "train": summary}  # fmt: skip
