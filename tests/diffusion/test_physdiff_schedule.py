"""PhysDiff's projection schedules, as Sec. 4.4 of the paper defines them."""

from __future__ import annotations

import pytest

from physmotion.diffusion.physdiff import flies_last, parse_schedule
from physmotion.errors import PhysmotionError
from physmotion.pipelines.modes import PhysicsMode, parse_modes


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


def test_fly_last_changes_who_is_projected_not_when() -> None:
    """``fly:last`` keeps the steps of the schedule it modifies, and travels through a mode's spelling."""
    assert parse_schedule("end:2,space:1,fly:last", 10) == parse_schedule("end:2,space:1", 10) == [8, 9]
    assert flies_last("fly:last,uniform:4") and not flies_last("end:2,space:1")
    mode = PhysicsMode.parse("physdiff:end:2,space:1,fly:last")
    assert mode.flies_last and str(mode) == "physdiff:end:2,space:1,fly:last" and mode.hook_steps(10) == [8, 9]
    assert PhysicsMode.parse("physdiff").flies_last  # the default schedule carries it
    assert not PhysicsMode.parse("physdiff:end:2,space:1").flies_last
    assert not PhysicsMode.parse("post:1").flies_last
    modes = parse_modes("none,physdiff:end:2,space:1,fly:last,post:1")
    assert [str(m) for m in modes] == ["none", "physdiff:end:2,space:1,fly:last", "post:1"]


@pytest.mark.parametrize("bad", ["", "end:4", "uniform:x", "end:4,space:0", "sideways:2", "end:20,space:3",
                                 "uniform:-1", "end:2,space:1,fly:first", "fly:last"])
def test_bad_schedules(bad: str) -> None:
    with pytest.raises(PhysmotionError):
        parse_schedule(bad, 50)
