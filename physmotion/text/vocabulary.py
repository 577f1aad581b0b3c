"""The words a model saw in its training captions, and the words of a prompt it never saw.

A model folder may ship ``vocabulary.txt`` (one lower-case word per line, written by
``experiments/model_vocabulary.py``); ``physmotion generate`` then warns about prompt words outside it.
A folder without the file gets no warning: nothing is known about what it saw.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Iterable
from pathlib import Path

from physmotion.errors import PhysmotionError

VOCABULARY_FILE = "vocabulary.txt"

# Letters of any script, with an inner apostrophe ("person's"): "una persona camina" and "人が歩く"
# give words too, so a prompt in another language is reported rather than passed over.
_WORD = re.compile(r"[^\W\d_]+(?:'[^\W\d_]+)*")

STOP_WORDS = frozenset(
    ["a", "an", "the", "and", "or", "but", "then", "than", "as", "at", "by", "for", "from", "in", "into", "of", "off", "on", "onto", "out", "over", "to", "up", "with", "while", "is", "are", "was", "were", "be", "been", "being", "it", "its", "this", "that", "these", "those", "there", "here", "his", "her", "hers", "their", "them", "they", "he", "she", "him", "himself", "herself", "itself", "themselves", "one", "ones", "some", "any", "very", "so", "too", "just", "also", "again", "person", "man", "woman", "human", "someone", "somebody", "people", "figure", "character", "guy", "lady"]
)
"""Words not worth a warning: function words, and who moves (the captions' subject, not the motion)."""


def words(text: str) -> list[str]:
    """The lower-case words of ``text``, in order (letters of any script; digits and punctuation split)."""
    return _WORD.findall(text.lower())


def stem(word: str) -> str:
    """A crude inflection fold, so "walking" counts as seen where the captions say "walks".

    Strips one of -ing/-ed/-s, then a final -e, then a doubled final consonant; stems stay >= 3 letters.
    """
    for suffix in ("ing", "ed", "s"):
        if word.endswith(suffix) and len(word) - len(suffix) >= 3:
            word = word[: -len(suffix)]
            break
    if word.endswith("e") and len(word) > 3:
        word = word[:-1]
    if len(word) > 3 and word[-1] == word[-2] and word[-1] not in "aeiou":
        word = word[:-1]
    return word


def caption_vocabulary(captions: Iterable[str]) -> Counter:
    """word -> count over ``captions`` (the tokenisation :func:`unknown_words` uses)."""
    counts: Counter = Counter()
    for caption in captions:
        counts.update(words(caption))
    return counts


def training_vocabulary(data: str | Path, max_frames: int, split: str = "train") -> tuple[Counter, int]:
    """word -> count over the captions of the motions a training run draws from ``data``'s split.

    max_frames: the length filter the run applied (motions of ``max_frames + 4`` frames or more are
    dropped, see :func:`physmotion.data.dataset.load_items`). Returns (counts, number of motions).
    """
    from physmotion.data.dataset import load_items

    items = load_items(data, split, max_frames=max_frames)
    return caption_vocabulary(c for item in items for c in item.captions), len(items)


def load_vocabulary(model_dir: str | Path) -> frozenset[str] | None:
    """The words of ``<model_dir>/vocabulary.txt``, or None where the folder has no such file."""
    path = Path(model_dir) / VOCABULARY_FILE
    if not path.is_file():
        return None
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise PhysmotionError(f"{path}: unreadable vocabulary file ({exc})") from None
    return frozenset(w.strip().lower() for w in lines if w.strip() and not w.startswith("#"))


def unknown_words(text: str, vocabulary: Iterable[str]) -> list[str]:
    """Words of ``text`` (lower case, first occurrence order, no repeats) that neither the vocabulary
    nor the stop-words hold, even after folding inflections with :func:`stem`."""
    known = set(vocabulary)
    stems = {stem(w) for w in known}
    out: list[str] = []
    for word in words(text):
        if word in STOP_WORDS or word in known or stem(word) in stems or word in out:
            continue
        out.append(word)
    return out


def write_vocabulary(path: str | Path, counts: Counter, header: str = "") -> None:
    """Write the words of ``counts`` one per line, sorted, atomically; ``header`` lines become comments."""
    from physmotion.motion import write_atomic

    lines = [f"# {line}" for line in header.splitlines()] + sorted(counts)
    data = ("\n".join(lines) + "\n").encode("utf-8")
    write_atomic(path, lambda f: f.write(data))
