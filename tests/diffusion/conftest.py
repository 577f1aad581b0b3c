"""Tiny training runs on the real bundled data, shared by the diffusion tests."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from physmotion.diffusion.denoiser import DenoiserConfig
from physmotion.diffusion.train import TrainConfig


def tiny_config(data: Path, out: Path, **kw) -> TrainConfig:
    """A small transformer that trains in seconds on 2 CPU cores."""
    den = DenoiserConfig(d_model=kw.pop("d_model", 64), layers=kw.pop("layers", 2), heads=4, dropout=0.1)
    base = dict(batch_size=8, crop=64, steps=20, lr=1e-3, warmup=5, log_every=5, checkpoint_minutes=60.0)
    base.update(kw)
    return TrainConfig(data=str(data), out=str(out), denoiser=den, **base)


@pytest.fixture(scope="session")
def one_clip_dir(built_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A HumanML3D-layout folder whose train split is one real walking window, eight times over."""
    out = tmp_path_factory.mktemp("one_clip")
    for sub in ("new_joint_vecs", "texts"):
        (out / sub).mkdir()
    ids = (built_dir / "train.txt").read_text().split()
    pick = next(i for i in ids if "walk_normal" in i and not i.startswith("M"))
    feats = np.load(built_dir / "new_joint_vecs" / f"{pick}.npy")[:64]
    names = [f"copy{k}" for k in range(8)]
    for name in names:
        np.save(out / "new_joint_vecs" / f"{name}.npy", feats)
        (out / "texts" / f"{name}.txt").write_text("a person walks forward\n")
    (out / "train.txt").write_text("\n".join(names) + "\n")
    for f in ("Mean.npy", "Std.npy", "build_info.json"):
        shutil.copy(built_dir / f, out / f)
    return out
