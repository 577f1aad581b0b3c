"""Counts, minutes and caption vocabulary of a HumanML3D-layout folder."""

from __future__ import annotations

import csv
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from physmotion.conventions import FPS
from physmotion.data.build import SPLITS
from physmotion.data.dataset import read_captions, read_split
from physmotion.errors import PhysmotionError

_WORD = re.compile(r"[a-z]+(?:'[a-z]+)?")


@dataclass
class DatasetStats:
    """What ``physmotion data stats`` prints."""

    items: dict[str, int] = field(default_factory=dict)  # split -> motions
    minutes: dict[str, float] = field(default_factory=dict)  # split -> minutes of motion
    captions: int = 0
    vocabulary: Counter = field(default_factory=Counter)  # word -> count over all captions
    licences: dict[str, int] = field(default_factory=dict)  # licence tag ("open" or "NC") -> motions

    @property
    def total_minutes(self) -> float:
        return sum(self.minutes.values())


def dataset_stats(root: str | Path) -> DatasetStats:
    """Read a dataset folder (our build or HumanML3D) and count what is in it.

    Minutes are feature frames / 20 fps and include mirrored copies when the folder has them.
    """
    root = Path(root)
    if not root.is_dir():
        raise PhysmotionError(f"{root}: no such dataset folder")
    stats = DatasetStats()
    for split in SPLITS:
        ids = read_split(root, split)
        frames = 0
        for mid in ids:
            vec = root / "new_joint_vecs" / f"{mid}.npy"
            if vec.is_file():
                frames += np.load(vec, mmap_mode="r").shape[0]
            text = root / "texts" / f"{mid}.txt"
            if text.is_file():
                for caption, _, _ in read_captions(text):
                    stats.captions += 1
                    stats.vocabulary.update(_WORD.findall(caption.lower()))
        stats.items[split] = len(ids)
        stats.minutes[split] = frames / FPS / 60
    index = root / "index.csv"
    if index.is_file():
        with open(index, newline="") as f:
            tags = Counter(row["licence_tag"] or "open" for row in csv.DictReader(f))
        stats.licences = dict(sorted(tags.items()))
    return stats
