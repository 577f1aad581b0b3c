"""The benchmark prompt sets: the unseen-prompt set shares no caption with the data the models saw."""

from pathlib import Path

from experiments.prompts import NEW_PROMPTS
from physmotion.data.dataset import read_captions, read_split


def test_new_prompts_are_no_caption_of_the_data(built_dir: Path) -> None:
    captions = {caption.lower().strip()
                for split in ("train", "val", "test") for item in read_split(built_dir, split)
                for caption, _, _ in read_captions(built_dir / "texts" / f"{item}.txt")}  # fmt: skip
    prompts = [p for group in NEW_PROMPTS.values() for p in group]
    assert len(captions) > 300 and len(prompts) >= 32
    assert all(len(group) >= 4 for group in NEW_PROMPTS.values())
    assert not {p.lower() for p in prompts} & captions
    assert len(set(prompts)) == len(prompts)
