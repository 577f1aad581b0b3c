"""Caption rewrites for training that keep a caption true of its motion.

Our sources caption in one voice each: nearly every sentence starts "a person", and HDM05 gives one
sentence per class. A model trained on them alone learns the exact wording, so "someone squats" or
"a man lies down" reads as unknown text. HumanML3D's captions, written by many annotators, start with
many subjects ("a person", "a man", "someone", "the person", "a figure") and often say only the action
("a person kicks"). Two rewrites bring that variety to any caption, with no list of prompts behind them:

- **subject**: a leading subject phrase is replaced by another of :data:`SUBJECTS`;
- **clause**: the caption is cut just before a word that opens a modifier (a preposition, "and", a
  comma: :data:`CUT_BEFORE`), keeping the subject and at least one word after it: "a person kicks
  forward with the left leg" becomes "a person kicks forward".

Captions that do not start with a subject (class labels such as "kick left front") are left as they are.
See docs/decisions/data.md, "Caption rewrites".
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# Subjects HumanML3D's annotators open their captions with, "a person" (ours) first.
SUBJECTS: tuple[str, ...] = ("a person", "someone", "a man", "a woman", "the person", "a figure", "a human")
# Words that open a modifier after the main verb phrase; a cut before one leaves the action itself.
CUT_BEFORE = frozenset({"with", "in", "on", "at", "to", "into", "onto", "from", "like", "and", "then",
                        "while", "as", "for", "using", "before", "after", "towards", "toward"})  # fmt: skip


def _subject(words: list[str]) -> int:
    """Number of leading words that form one of SUBJECTS (0 where the caption opens otherwise)."""
    lower = [w.lower() for w in words]
    for s in sorted(SUBJECTS, key=len, reverse=True):
        n = len(s.split())
        if lower[:n] == s.split() and len(words) > n:
            return n
    return 0


def cut_points(caption: str) -> list[int]:
    """Word counts at which ``caption`` may be cut (each < its length); empty for a caption with no
    subject. A word ending in a comma also ends a clause."""
    words = caption.split()
    return _cut_points(words, _subject(words))


def _cut_points(words: list[str], n: int) -> list[int]:
    """:func:`cut_points` of ``words`` whose first ``n`` form the subject (none where n is 0)."""
    if n == 0:
        return []
    # subject + at least one word kept
    return [i for i in range(n + 1, len(words)) if words[i].lower() in CUT_BEFORE or words[i - 1].endswith(",")]


def rewrite(caption: str, rng: np.random.Generator, p: float) -> str:
    """``caption`` with each rewrite applied with probability ``p`` (independently): another subject,
    then a cut at one of :func:`cut_points`, drawn uniformly."""
    words = caption.split()
    n = _subject(words)
    if n == 0 or p <= 0:
        return caption
    swap, cut = rng.random(2) < p
    points = _cut_points(words, n)
    if cut and points:
        words = words[: points[rng.integers(len(points))]]
        words[-1] = words[-1].rstrip(",;:")
    if swap:
        current = " ".join(words[:n]).lower()
        others = [s for s in SUBJECTS if s != current]
        words = others[rng.integers(len(others))].split() + words[n:]
    return " ".join(words)


def rewrite_batch(captions: Sequence[str], seed: int, step: int, p: float) -> list[str]:
    """:func:`rewrite` over a batch, drawn from the stream ``(seed, step)`` so a resumed run redraws the
    same rewrites."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 4, step]))
    return [rewrite(c, rng, p) for c in captions]
