"""Caption rewrites on the real captions of both collections: what they keep, what they change, and
that they are drawn from the step's seed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physmotion.io.importer import load_manifest
from physmotion.text.augment import SUBJECTS, cut_points, rewrite, rewrite_batch


def _captions(folder: Path) -> list[str]:
    return sorted({c for clip in load_manifest(folder) for c in clip.captions})


def _after_subject(caption: str) -> list[str]:
    subject = next(s for s in sorted(SUBJECTS, key=len, reverse=True) if caption.lower().startswith(s + " "))
    return caption.split()[len(subject.split()) :]


@pytest.fixture(scope="module")
def captions(mocap_dir: Path, hdm05_dir: Path) -> list[str]:
    return _captions(mocap_dir) + _captions(hdm05_dir)


def test_known_rewrites() -> None:
    caption = "a person kicks forward with the left leg"
    assert cut_points(caption) == [4]
    assert cut_points("a person bends over, scoops something up, stands up and lifts an arm") == [4, 7, 9]
    rng = np.random.default_rng(0)
    seen = {rewrite(caption, rng, 1.0) for _ in range(200)}
    # p = 1: always cut (one cut point here) and always another subject, each of the six others drawn
    assert seen == {f"{s} kicks forward" for s in SUBJECTS if s != "a person"}
    assert {rewrite(caption, rng, 0.0) for _ in range(20)} == {caption}


def test_rewrites_keep_the_action_of_every_real_caption(captions: list[str]) -> None:
    """Every rewrite of a real caption keeps its first word after the subject (the verb) and is a
    shortened copy of the caption's own words; captions without a subject (class labels) never change."""
    rng = np.random.default_rng(1)
    changed = 0
    with_subject = [c for c in captions if c.lower().startswith(tuple(s + " " for s in SUBJECTS))]
    assert len(with_subject) > 0.4 * len(captions)  # the rest are class labels ("walk", "kick left front")
    for caption in captions:
        for _ in range(5):
            new = rewrite(caption, rng, 0.7)
            if caption not in with_subject:
                assert new == caption
                continue
            changed += new != caption
            rest, original_rest = _after_subject(new), _after_subject(caption)
            assert rest[0] == original_rest[0], (caption, new)
            assert [w.rstrip(",;:") for w in rest] == [w.rstrip(",;:") for w in original_rest[: len(rest)]]
    assert changed > 0.5 * 5 * len(with_subject)


def test_batches_are_drawn_from_seed_and_step(captions: list[str]) -> None:
    batch = captions[:32]
    assert rewrite_batch(batch, 0, 7, 0.5) == rewrite_batch(batch, 0, 7, 0.5)
    assert rewrite_batch(batch, 0, 7, 0.5) != rewrite_batch(batch, 0, 8, 0.5)
    assert rewrite_batch(batch, 0, 7, 0.0) == batch
