"""PhysDiff's projection schedules, as Sec. 4.4 of the paper defines them."""

from __future__ import annotations

import pytest

from physmotion.diffusion.physdiff import parse_schedule
from physmotion.errors import PhysmotionError


def _t(indices: list[int], steps: int = 50) -> set[int]:
    """Loop indices -> the paper's t (steps still to come; 0 = last step)."""
    return {steps - 1 - i for i in indices}


def test_paper_examples() -> None:
    assert _t(parse_schedule("uniform:4", 50)) == {0, 15, 30, 45}
    assert _t(parse_schedule("end:4,space:3", 50)) == {0, 3, 6, 9}
    assert _t(parse_schedule("end:4,space:1", 50)) == {0, 1, 2, 3}
    assert _t(parse_schedule("start:3,end:1", 50)) == {49, 48, 47, 0}
    assert parse_schedule("end:4,space:1", 50) == [46, 47, 48, 49]


def test_counts_and_zero() -> None:
    assert parse_schedule("uniform:0", 50) == []
    assert len(parse_schedule("uniform:50", 50)) >= 40
    assert len(parse_schedule("start:2,end:2", 50)) == 4


@pytest.mark.parametrize("bad", ["", "end:4", "uniform:x", "end:4,space:0", "sideways:2", "end:20,space:3",
                                 "uniform:-1"])
def test_bad_schedules(bad: str) -> None:
    with pytest.raises(PhysmotionError):
        parse_schedule(bad, 50)
