"""experiments/torque_cap.py's comparison of two evaluation tables, which experiments/feet_through.py
shares: both means with their intervals, and whether those overlap, per figure present in both."""

from __future__ import annotations

from experiments.torque_cap import compare
from physmotion.eval.table import EvalTable


def test_compare_lists_every_shared_figure_and_whether_the_intervals_overlap() -> None:
    mode = "physdiff:end:2,space:1,fly:last"
    before = EvalTable(rows={mode: {"phys_err": (8.2, 0.5), "FID": (0.106, 0.003), "skate": (5.3, 0.1)}},
                       meta={})  # fmt: skip
    after = EvalTable(rows={mode: {"phys_err": (8.6, 0.4), "FID": (0.120, 0.003), "float": (2.0, 0.2)}},
                      meta={})  # fmt: skip
    rows, out = compare(before, after, [mode], ["phys_err", "FID", "skate", "float"])
    assert [r[1] for r in rows] == ["phys_err", "FID"]  # skate and float are each in one table only
    assert rows[0] == [mode, "phys_err", "8.200 ± 0.500", "8.600 ± 0.400", "yes"]
    assert rows[1][-1] == "**no**"  # 0.014 apart, intervals 0.006 together
    assert out[mode]["FID"] == {"before": (0.106, 0.003), "after": (0.120, 0.003), "intervals_overlap": False}
    _, named = compare(before, after, [mode], ["phys_err"], names=("default", "cap"))
    assert set(named[mode]["phys_err"]) == {"default", "cap", "intervals_overlap"}
