"""Captured clips by category of motion, airborne shares and the per-category summary, and the two
experiments that write them (experiments/projection_quality.py, experiments/projection_dynamic.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from experiments.projection_quality import (
    AIRBORNE_HEIGHT,
    airborne_share,
    by_category,
    category,
    main,
    measure_clips,
)
from physmotion.io.importer import load_manifest


@pytest.mark.parametrize(
    "captions, expected",
    [(["a person jumps forward several times and turns around"], "jump"),
     (["a person walks and turns left"], "turn"), (["walk", "a person walks"], "walk"),
     (["run/jog"], "run"), (["a person dashes forward at a sprint"], "run"),
     (["a person dances the charleston"], "dance"), (["a person kicks"], "kick"),
     (["a person bows"], "other"), (["a person stepped aside"], "other")],
)  # fmt: skip
def test_category_by_caption_words(captions: list[str], expected: str) -> None:
    assert category(captions) == expected


def test_every_category_of_the_mocap_is_present(mocap_dir) -> None:
    """The bundled mocap: 123 walks, 53 runs, 45 turns, 10 dances, 5 jumps, 1 kick, 132 other."""
    counts: dict[str, int] = {}
    for info in load_manifest(mocap_dir):
        counts[category(info.captions)] = counts.get(category(info.captions), 0) + 1
    assert counts == {"walk": 123, "run": 53, "turn": 45, "dance": 10, "jump": 5, "kick": 1, "other": 132}


def test_airborne_share_counts_frames_with_both_feet_up(mocap_dir) -> None:
    from physmotion.io.importer import import_clip
    from physmotion.physics.surface import HumanoidSurface, ground_on_surface

    info = {c.clip: c for c in load_manifest(mocap_dir)}["bandai2_dataset-2_walk_normal_001"]
    walk, body = ground_on_surface(import_clip(info).joints[:60].astype(np.float64))
    surface = HumanoidSurface(body)
    assert airborne_share(walk, surface) < 0.05  # a walk always has a foot down
    lifted = walk.copy()
    lifted[20:40, :, 1] += 2 * AIRBORNE_HEIGHT
    assert airborne_share(lifted, surface) == pytest.approx(airborne_share(walk, surface) + 20 / 60, abs=0.02)


def test_by_category_summarises_measured_clips(mocap_dir) -> None:
    clips = {c.clip: c for c in load_manifest(mocap_dir)}
    chosen = [clips[n] for n in ("bandai2_dataset-2_walk_normal_001", "bandai2_dataset-2_run_feminine_001",
                                 "cmubvh_131_03")]  # fmt: skip
    measured = measure_clips(chosen)
    rows = by_category(chosen, measured, bound=0.2)
    assert [k for k in rows] == ["jump", "run", "walk", "walks+runs", "all"]
    assert rows["all"]["clips"] == 3 and rows["walks+runs"]["clips"] == 2
    force = np.concatenate([m.result.residual_force for m in measured])
    over = np.concatenate([m.result.over_limit for m in measured])
    assert rows["all"]["residual_at_cap"] == pytest.approx(np.mean(force >= 0.99 * 0.2))
    assert rows["all"]["over_limit"] == pytest.approx(over.mean())
    assert "residual_at_cap" not in by_category(chosen, measured)["all"]  # no cap given, no share at it
    for row in rows.values():
        assert 0.0 <= row["success"] <= 1.0 and row["mpjpe_mm"] > 0
        assert 0.0 <= row["residual_at_cap"] <= 1.0 and 0.0 <= row["over_limit"] <= 1.0
        assert row["residual_force_p95"] >= row["residual_force_mean"] >= 0.0
        assert 0.0 <= row["airborne_out"] <= 1.0
        assert 0.0 <= row["contact_out"] <= 1.0 and row["slide_out"] >= 0.0


def test_the_experiment_writes_its_table_and_meta(mocap_dir, tmp_path: Path) -> None:
    """Two walking clips under the ``fine`` preset: <out>.md and <out>.json, the JSON's meta naming the preset,
    the commit, the CPU, the date and the command."""
    out = tmp_path / "pq"
    main(["--mocap", str(mocap_dir), "--walks-runs", "--limit", "2", "--preset", "fine", "--out", str(out),
          "--allow-dirty"])
    data = json.loads(out.with_suffix(".json").read_text())
    meta = data["meta"]
    assert meta["preset"] == "fine" and meta["clips"] == 2
    assert meta["command"].startswith("python -m experiments.projection_quality --mocap")
    assert meta["commit"] and meta["cpu"] and meta["date"].endswith("+00:00")
    assert data["rows"]["all"]["clips"] == 2
    assert "| walks+runs | 2 |" in out.with_suffix(".md").read_text()


def test_projection_dynamic_rows_are_presets() -> None:
    from experiments.projection_dynamic import ROWS
    from physmotion.physics.presets import preset_names

    assert set(ROWS.values()) <= set(preset_names()) and ROWS["default"] == "plain"
