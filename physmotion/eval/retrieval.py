"""Text-to-motion retrieval of an evaluator on a dataset split: R@1 / R@3 in batches of 32.

The standard protocol (Guo et al. 2022's R-Precision; TMR's "protocol (d)", batches of 32): each motion is
paired with one of its captions, drawn at random; the pairs are shuffled and cut into batches of 32 (an
incomplete last batch is dropped); within a batch each caption ranks the 32 motions by distance, and R@k
is the fraction whose own motion is among the k nearest. Our splits are small (58 test motions: one
batch per draw), so the draw is repeated ``repeats`` times and the mean and 95% interval reported.

``shuffle_texts`` pairs every motion with another motion's caption: the chance-level control that real
motions with their own captions must beat by far.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physmotion.data.dataset import MotionItem, load_items
from physmotion.errors import PhysmotionError
from physmotion.eval.evaluator import Evaluator
from physmotion.metrics.generation import confidence_interval, r_precision

BATCH = 32


@dataclass
class RetrievalResult:
    """Mean and 95% half-width over the repeats, for R@1, R@2, R@3 and MM-Dist."""

    r_at: list[tuple[float, float]]  # R@1, R@2, R@3
    mm_dist: tuple[float, float]
    pairs: int  # pairs per repeat (in full batches)
    repeats: int

    def to_dict(self) -> dict:
        out = {f"R@{k + 1}": {"mean": m, "ci95": c} for k, (m, c) in enumerate(self.r_at)}
        out["MM-Dist"] = {"mean": self.mm_dist[0], "ci95": self.mm_dist[1]}
        return {**out, "pairs": self.pairs, "repeats": self.repeats}


def retrieval(
    evaluator: Evaluator,
    items: list[MotionItem],
    repeats: int = 10,
    seed: int = 0,
    shuffle_texts: bool = False,
    batch_size: int = BATCH,
) -> RetrievalResult:
    """Retrieval of ``items`` (whole motions, up to the evaluator's length) by their captions."""
    if len(items) < batch_size:
        raise PhysmotionError(f"retrieval needs at least {batch_size} motions, the split has {len(items)}")
    motion_emb = evaluator.encode_motions([it.features for it in items])
    r_at, mm = [], []
    for rep in range(repeats):
        rng = np.random.default_rng((seed, rep))
        captions = [it.captions[rng.integers(len(it.captions))] for it in items]
        if shuffle_texts:
            captions = [captions[i] for i in _derangement(len(items), rng)]
        order = rng.permutation(len(items))
        text_emb = evaluator.encode_texts([captions[i] for i in order])
        acc, dist = r_precision(text_emb, motion_emb[order], top_k=3, batch_size=batch_size)
        r_at.append(acc)
        mm.append(dist)
    r_at_arr = np.array(r_at)
    return RetrievalResult(r_at=[confidence_interval(r_at_arr[:, k]) for k in range(3)],
                           mm_dist=confidence_interval(mm), pairs=len(items) // batch_size * batch_size,
                           repeats=repeats)  # fmt: skip


def split_retrieval(evaluator: Evaluator, root: str | Path, split: str = "test", **kw) -> RetrievalResult:
    """:func:`retrieval` on the whole motions of a HumanML3D-layout split."""
    return retrieval(evaluator, load_items(root, split, max_frames=evaluator.config.max_frames), **kw)


def _derangement(n: int, rng: np.random.Generator) -> np.ndarray:
    """A permutation with no fixed point (so no motion keeps its own caption)."""
    while True:
        perm = rng.permutation(n)
        if n < 2 or not np.any(perm == np.arange(n)):
            return perm
