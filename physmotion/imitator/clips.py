"""The motions the imitator trains and is evaluated on: built datasets (captured clips with their mirrors)
and folders of generated motions (``physmotion generate`` output: Morph's motion-free idea, the policy
learns on what P is asked to project)."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physmotion.conventions import FPS
from physmotion.errors import PhysmotionError
from physmotion.skeleton import NUM_JOINTS, mirror_joints


@dataclass(frozen=True)
class ClipSource:
    """One motion to imitate. joints: (T, 22, 3) float32, metres, Y up, at ``fps``."""

    name: str
    joints: np.ndarray
    fps: float
    licence_tag: str
    origin: str  # "captured" or "generated"


def dataset_clips(folder: str | Path, split: str = "train") -> list[ClipSource]:
    """Every item of ``split`` in a built dataset folder (``new_joints/<id>.npy``, ``<split>.txt``; our
    ``index.csv`` for licence tags, absent in a plain HumanML3D folder), mirrored copies included: a
    mirrored item ``M<id>`` whose file is missing is mirrored from ``<id>`` (a copy of a build carried
    without its mirrors to save space)."""
    root = Path(folder)
    split_file = root / f"{split}.txt"
    if not split_file.is_file():
        raise PhysmotionError(f"not a dataset folder: {split_file} is missing (build one with `data build`)")
    ids = [line.strip() for line in split_file.read_text().splitlines() if line.strip()]
    tags: dict[str, str] = {}
    index = root / "index.csv"
    if index.is_file():
        with index.open(newline="") as f:
            tags = {row["id"]: row["licence_tag"] for row in csv.DictReader(f)}
    out = []
    for i in ids:
        path = root / "new_joints" / f"{i}.npy"
        plain = root / "new_joints" / f"{i[1:]}.npy"
        if not path.is_file() and i.startswith("M") and plain.is_file():
            joints = mirror_joints(np.load(plain)).astype(np.float32)  # a copy made without the mirrors
        elif path.is_file():
            joints = np.load(path).astype(np.float32)
        else:
            raise PhysmotionError(f"dataset item {i} has no joints file {path}")
        _check(joints, str(path))
        out.append(ClipSource(i, joints, float(FPS), tags.get(i, ""), "captured"))
    return out


def motion_clips(folder: str | Path) -> list[ClipSource]:
    """Every ``.npz`` motion in ``folder`` (e.g. ``physmotion generate`` output), sorted by name."""
    from physmotion.motion import Motion

    root = Path(folder)
    if not root.is_dir():
        raise PhysmotionError(f"motion folder not found: {root}")
    out = []
    for path in sorted(root.glob("*.npz")):
        m = Motion.load(path)
        _check(m.joints, str(path))
        out.append(ClipSource(path.stem, m.joints.astype(np.float32), float(m.fps), m.licence_tag, "generated"))
    if not out:
        raise PhysmotionError(f"no .npz motions in {root}")
    return out


def _check(joints: np.ndarray, where: str) -> None:
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3) or len(joints) < 2:
        raise PhysmotionError(f"{where}: joints must be (T, 22, 3) with T >= 2, got {joints.shape}")
    if not np.all(np.isfinite(joints)):
        raise PhysmotionError(f"{where}: joints contain NaN or infinite values")


def licence_tags(clips: list[ClipSource]) -> list[str]:
    """The licence tags the clips carry (sorted, empty tags left out)."""
    return sorted({c.licence_tag for c in clips if c.licence_tag})


def training_sets(data: list[str | Path], motions: list[str | Path], eval_clips: int = 16
                  ) -> tuple[list[ClipSource], list[ClipSource]]:  # fmt: skip
    """The clips to train on and the fixed evaluation set, from dataset folders (their train splits; the
    evaluation takes unmirrored test items) and folders of generated motions (every 8th is held out for
    evaluation). The evaluation set, at most ``eval_clips``, is shared evenly between the sources."""
    if not data and not motions:
        raise PhysmotionError("give at least one --data or --motions folder")
    clips, evals = [], []
    per_source = max(1, eval_clips // (len(data) + len(motions)))
    for folder in data:
        clips += dataset_clips(folder, "train")
        evals += [c for c in dataset_clips(folder, "test") if not c.name.startswith("M")][:per_source]
    for folder in motions:
        gen = motion_clips(folder)
        evals += gen[::8][:per_source]
        clips += [c for i, c in enumerate(gen) if i % 8]
    return clips, evals[:eval_clips]
