"""A torch ``Dataset`` over a HumanML3D-layout folder: our own build or a real HumanML3D folder.

Follows HumanML3D's ``Text2MotionDatasetV2`` (EricGuo5513/text-to-motion, data/dataset.py): items
shorter than ``min_frames`` or of ``max_frames + 4`` frames or more are dropped; a caption line
``caption#tokens#start#end`` with a non-zero time span makes its own sub-motion; each access picks a
caption at random, rounds the length down to a multiple of ``unit_length`` (one unit less a third
of the time) and crops at a random start. Unlike the original it does not pad to 196 frames:
:func:`collate` pads a batch to its longest item and returns a mask. Randomness comes from
``(seed, epoch, index)``, so a run is reproducible with any number of workers.

``crop`` (default ``max_frames``) sets the longest window drawn, apart from which motions are kept:
training on 120-frame windows keeps the motions of up to 196 frames and crops them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from physmotion.conventions import FPS, MAX_FRAMES, MIN_FRAMES
from physmotion.errors import PhysmotionError
from physmotion.features.normalize import Normalizer


@dataclass
class MotionItem:
    """One entry of the dataset: a motion (features, not normalised) and its captions."""

    id: str
    features: np.ndarray  # (T, D) float32
    captions: list[str]
    activations: np.ndarray | None = None  # (T, 8) float32, when loaded (BioMoDiffuse's muscle term)


def read_captions(path: Path) -> list[tuple[str, float, float]]:
    """Captions of one text file as (caption, start_s, end_s); plain lines have span (0, 0).

    Reads both our one-caption-per-line files and HumanML3D's ``caption#tokens#start#end`` lines.
    """
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        parts = line.strip().split("#")
        if not parts[0]:
            continue
        start = end = 0.0
        if len(parts) >= 4:
            start, end = (0.0 if np.isnan(float(x)) else float(x) for x in parts[2:4])
        out.append((parts[0], start, end))
    return out


def read_split(root: str | Path, split: str) -> list[str]:
    """The ids listed in ``<root>/<split>.txt``."""
    path = Path(root) / f"{split}.txt"
    if not path.is_file():
        raise PhysmotionError(f"{root}: no split file {split}.txt (is this a HumanML3D-layout folder?)")
    return [line.strip() for line in path.read_text().splitlines() if line.strip()]


def length_limit(max_frames: int) -> int:
    """HumanML3D's length filter: a run with max length ``max_frames`` keeps motions of fewer frames than
    this (fewer than 200 for 196)."""
    return max_frames + 4


def load_items(
    root: str | Path,
    split: str,
    min_frames: int = MIN_FRAMES,
    max_frames: int = MAX_FRAMES,
    activations: bool = False,
) -> list[MotionItem]:
    """Every usable (motion, captions) entry of a split, with HumanML3D's length filter.

    activations: also load each motion's cached muscle activations (``data build --activations``)."""
    from physmotion.data.build import load_activations  # here: build imports MuJoCo, which few callers need

    root = Path(root)
    limit = length_limit(max_frames)
    items: list[MotionItem] = []
    for mid in read_split(root, split):
        vec_path, text_path = root / "new_joint_vecs" / f"{mid}.npy", root / "texts" / f"{mid}.txt"
        if not vec_path.is_file() or not text_path.is_file():
            continue  # HumanML3D's split files name a few ids with no files; it skips them too
        feats = np.load(vec_path).astype(np.float32)
        acts = load_activations(root, mid) if activations else None
        if acts is not None and len(acts) != len(feats):
            raise PhysmotionError(f"{root}: activations of '{mid}' have {len(acts)} frames, its features "
                                  f"{len(feats)}; rebuild them with `physmotion data activations {root}`")
        whole: list[str] = []
        for k, (caption, start, end) in enumerate(read_captions(text_path)):
            if start == 0.0 and end == 0.0:
                whole.append(caption)
                continue
            span = slice(int(start * FPS), int(end * FPS))
            part = feats[span]
            if min_frames <= len(part) < limit:
                items.append(MotionItem(f"{mid}#{k}", part, [caption], None if acts is None else acts[span]))
        if whole and min_frames <= len(feats) < limit:
            items.append(MotionItem(mid, feats, whole, acts))
    return items


class MotionDataset(Dataset):
    """Text-motion pairs from a HumanML3D-layout folder.

    Each item is a dict: ``motion`` (T, D) float32 tensor (normalised with the folder's Mean/Std
    unless ``normalize=False``), ``length`` int, ``text`` str, ``id`` str, and with ``activations=True``
    ``activations`` (T, 8) float32 tensor of the same window.
    """

    def __init__(
        self,
        root: str | Path,
        split: str = "train",
        *,
        max_frames: int = MAX_FRAMES,
        min_frames: int = MIN_FRAMES,
        unit_length: int = 4,
        random_crop: bool = True,
        normalize: bool = True,
        seed: int = 0,
        crop: int | None = None,
        activations: bool = False,
    ) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise PhysmotionError(f"{root}: no such dataset folder")
        self.items = load_items(self.root, split, min_frames, max_frames, activations)
        if not self.items:
            raise PhysmotionError(f"{root}: split '{split}' has no usable motion")
        self.normalizer = Normalizer.load(self.root) if normalize else None
        if crop is not None and not 0 < crop <= max_frames:
            raise PhysmotionError(f"crop must be 1..{max_frames} frames, got {crop}")
        # Longest window drawn; a separate knob from max_frames, which also decides which motions are kept.
        self.crop, self.unit_length = crop or max_frames, unit_length
        self.random_crop, self.seed, self.epoch = random_crop, seed, 0

    def set_epoch(self, epoch: int) -> None:
        """Change the random crops and captions drawn, reproducibly."""
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict:
        item = self.items[index]
        rng = np.random.default_rng((self.seed, self.epoch, index))
        feats = item.features
        if self.random_crop:
            text = item.captions[rng.integers(len(item.captions))]
            units = min(len(feats), self.crop) // self.unit_length
            if rng.integers(3) == 2 and units > 1:  # HumanML3D's 'double' coin: one unit shorter
                units -= 1
            length = units * self.unit_length
            start = int(rng.integers(len(feats) - length + 1))
        else:
            text = item.captions[0]
            length, start = min(len(feats), self.crop), 0
        motion = feats[start : start + length]
        if self.normalizer is not None:
            motion = self.normalizer.normalize(motion)
        out = {"motion": torch.from_numpy(np.ascontiguousarray(motion, dtype=np.float32)),
               "length": length, "text": text, "id": item.id}  # fmt: skip
        if item.activations is not None:
            out["activations"] = torch.from_numpy(np.ascontiguousarray(item.activations[start : start + length]))
        return out


def collate(batch: list[dict]) -> dict:
    """Pad a list of items to the longest one.

    Returns motion (B, T, D) zero-padded, mask (B, T) bool (True on real frames), lengths (B,),
    text list[str], id list[str], and activations (B, T, 8) zero-padded when the items have them.
    """
    lengths = torch.tensor([b["length"] for b in batch])
    width = int(lengths.max())
    motion = torch.zeros(len(batch), width, batch[0]["motion"].shape[-1])
    for i, b in enumerate(batch):
        motion[i, : b["length"]] = b["motion"]
    mask = torch.arange(width)[None, :] < lengths[:, None]
    out = {"motion": motion, "mask": mask, "lengths": lengths,
           "text": [b["text"] for b in batch], "id": [b["id"] for b in batch]}  # fmt: skip
    if all("activations" in b for b in batch):
        acts = torch.zeros(len(batch), width, batch[0]["activations"].shape[-1])
        for i, b in enumerate(batch):
            acts[i, : b["length"]] = b["activations"]
        out["activations"] = acts
    return out
