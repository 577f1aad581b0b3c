"""experiments/search_quality.py: the captured set by category, the per-motion figures and the table."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from experiments.search_quality import captured_set, main, rows, summary


def test_the_captured_set_spans_every_category(mocap_dir: Path, hdm05_dir: Path) -> None:
    picked = captured_set(str(mocap_dir), str(hdm05_dir), 2)
    cats = {cat for cat, _ in picked}
    assert {"walk", "run", "turn", "dance", "jump", "kick", "other"} <= cats
    assert sum(cat.startswith("hdm05 ") for cat in cats) == 11  # HDM05's classes
    assert all(sum(c == cat for c, _ in picked) <= 2 for cat in cats)
    assert {cat for cat, _ in captured_set(str(mocap_dir), str(hdm05_dir), 1, "squat,jump")} == \
        {"jump", "hdm05 squat1Reps"}


def test_rows_compare_the_hand_and_the_cone() -> None:
    configs = rows(["fast"], None)
    assert configs["tracker, hand on, pyramidal"].tracking.residual_force > 0
    off = configs["tracker, hand off, elliptic"]
    assert off.tracking.residual_force == off.tracking.residual_torque == off.tracking.residual_lift == 0
    assert off.humanoid.cone == "elliptic" and off.humanoid.impratio == 10
    assert configs["search default, pyramidal"].humanoid.cone == "pyramidal"
    assert configs["search fast, elliptic"].search.candidates == 16


def test_summary_pools_motions() -> None:
    base = {"completed": 1.0, "mpjpe_mm": 50.0, "rel_mpjpe_mm": 30.0, "drift_mm": 10.0, "help": 0.0,
            "over_limit": 0.0, "penetrate_in": 1.0, "penetrate_out": 0.5, "float_in": 2.0, "float_out": 1.0,
            "skate_in": 3.0, "skate_out": 4.0, "wall_per_s": 2.0, "cpu_per_s": 3.0}  # fmt: skip
    jump = base | {"completed": 0.0, "skate_out": 2.0, "flight_in_cm": 20.0, "flight_out_cm": 15.0}
    s = summary([base, jump])
    assert s["completed"] == 0.5 and s["skate_not_above_in"] == 0.5 and s["flight_kept"] == pytest.approx(0.75)


def test_main_writes_the_table(mocap_dir: Path, hdm05_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "sq"
    main(["--allow-dirty", "--mocap", str(mocap_dir), "--hdm05", str(hdm05_dir),
          "--captured-per", "1", "--categories", "walk",
          "--seeds", "0", "--efforts", "fast", "--max-seconds", "1", "--out", str(out)])
    table = (tmp_path / "sq.md").read_text()
    assert "| captured | search fast, elliptic | 1 |" in table
    per = json.loads((tmp_path / "sq.json").read_text())["per_motion"]["captured"]
    search = per["search fast, elliptic"][0]
    assert search["help"] == 0.0 and search["over_limit"] == 0.0 and search["kind"] == "walk"
    assert per["tracker, hand on, pyramidal"][0]["help"] > 0.0
