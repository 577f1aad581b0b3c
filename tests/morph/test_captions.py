"""The grounded-caption rule list on hand-built captions and on the real train captions."""

from __future__ import annotations

import pytest

from physmotion.morph.captions import NON_GROUNDED_RULES, is_grounded, non_grounded_reason


@pytest.mark.parametrize("caption", [
    "a person sits down on a chair", "someone is sitting", "a man lies on the bed", "person lying down",
    "a person climbs the stairs", "walks up stairs", "a person climbs a ladder", "a person swims forward",
    "a baby crawls on all fours", "a person kneels", "a person rides a bike", "walk on uneven terrain",
    "a person leans against the wall", "does push-ups", "a person hangs from monkey bars",
    "a person walks over uneven ground", "SITS ON A STOOL",
])  # fmt: skip
def test_non_grounded_captions_are_flagged(caption: str) -> None:
    assert not is_grounded(caption)
    assert non_grounded_reason(caption)


@pytest.mark.parametrize("caption", [
    "a person walks forward", "a person jumps", "a person does a backflip", "a person dances ballet",
    "a person swings their arms", "a boxing stance",
    "a person bends over, scoops something up, stands up and lifts an arm", "playground - forward jumps, turn around", "a person lifts an arm", "a person runs",
    "a person sidesteps", "a person steps forward",
])  # fmt: skip
def test_grounded_captions_pass(caption: str) -> None:
    # whole words only: "boxing" is not "box", "lifts an arm" is not "lifts a ...", "swings" arms is grounded
    assert is_grounded(caption)


def test_every_rule_says_why() -> None:
    assert all(words and why for words, why in NON_GROUNDED_RULES)


def test_train_captions_flagged(built_dir) -> None:
    from physmotion.morph.synth import train_captions

    captions = train_captions(built_dir)
    flagged = sorted(c for c in captions if not is_grounded(c))
    # our mocap has almost no interaction motion: only the uneven-terrain walks
    assert flagged == ["a person walks over uneven ground", "walk on uneven terrain"]
