"""experiments/flight_kept.py's pieces that run without a model: its variants of generation's P and its
CPU clock, which must see the worker pool that lives on between P's calls."""

from __future__ import annotations

import time

import pytest

from experiments.flight_kept import VARIANTS, _cpu_wall, _variant
from physmotion.physics.projection import ProjectionConfig


def test_every_variant_is_the_sampling_preset_with_one_change() -> None:
    base = ProjectionConfig.sampling()
    assert _variant("sampling") == base
    for name in VARIANTS[1:]:
        assert _variant(name) != base, name
    assert _variant("fallback").fallback and not base.fallback
    assert base.recover and not _variant("no_recover").recover
    assert base.reach_arms and not _variant("copied_arms").reach_arms
    assert base.shaping.push_off and not _variant("no_push_off").shaping.push_off
    assert _variant("rescue").rescue_flight == 0.8 and base.rescue_flight == 0.0
    through = _variant("feet_through_actuators").tracking  # the feet balance, through the actuators
    assert through.feet_balance and through.feet_through_actuators and not base.tracking.feet_balance
    searched = _variant("search")  # the search has no outside hand, so no fallback or recovery either
    assert searched.controller == "search" and not searched.recover and base.controller == "tracker"
    with pytest.raises(ValueError, match="unknown variant"):
        _variant("bogus")


def _spin(n: int) -> int:
    total = 0
    for i in range(n):
        total += i * i % 7
    return total


def test_the_cpu_clock_counts_live_worker_processes() -> None:
    """Work done in P's persistent worker pool (physics/workers.py) is counted while the workers live."""
    from physmotion.physics.workers import map_in_workers

    map_in_workers(_spin, [10, 10], workers=2)  # the pool started, its processes alive
    before = _cpu_wall()
    own = time.process_time()
    map_in_workers(_spin, [8_000_000, 8_000_000], workers=2)
    own = time.process_time() - own
    cpu, wall = _cpu_wall() - before
    print(f"\nCPU {cpu:.2f} s in {wall:.2f} s of wall time, {own:.2f} s of it this process's")
    assert own < 0.1 and cpu >= 0.6  # two workers' loops (about 0.4 s each); this process only waited


def test_an_unknown_category_is_refused_before_any_work(capsys: pytest.CaptureFixture) -> None:
    from experiments.flight_kept import main

    argv = ["--categories", "swim", "--variants", "", "--allow-dirty", "--out", "/nonexistent/never"]
    assert main(argv) == 1
    assert "--categories: choose from run, jog" in capsys.readouterr().err
