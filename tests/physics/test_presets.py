"""P's preset registry: every name builds a valid config, the sampling preset is the classmethod's, and an
unknown name fails in one line that lists the known ones."""

from __future__ import annotations

import pytest

from physmotion.errors import PhysmotionError
from physmotion.physics.presets import describe, preset, preset_names
from physmotion.physics.projection import ProjectionConfig


def test_every_preset_builds_and_describes_itself() -> None:
    names = preset_names()
    assert {"plain", "sampling", "fine"} <= set(names) and len(set(names)) == len(names)
    for name in names:
        assert isinstance(preset(name), ProjectionConfig)
        assert describe(name) and "\n" not in describe(name)
    assert preset("plain") is not preset("plain")  # a fresh config each call: callers may change it


def test_presets_agree_with_the_config_methods() -> None:
    assert preset("plain") == ProjectionConfig()
    assert preset("sampling") == ProjectionConfig.sampling()
    assert preset("fine") == ProjectionConfig().at_fine_step()
    assert preset("sampling_fine") == ProjectionConfig.sampling().at_fine_step()
    assert preset("ilc") == ProjectionConfig(ilc_passes=2)


def test_residual_bound_is_the_cap_of_whoever_drives() -> None:
    assert ProjectionConfig().residual_bound() == 0.2
    assert ProjectionConfig.sampling().residual_bound() == 0.3
    # the shipped policy brings its own tracker settings at a quarter of their cap (its card: 0.05 W)
    assert ProjectionConfig.sampling().with_controller("policy").residual_bound() == pytest.approx(0.05)


def test_the_tracker_history_changes_one_thing_at_a_time() -> None:
    v01, held = preset("tracker_v01"), preset("plain_held_residual")
    assert not v01.tracking.feet_balance and not v01.shaping.flatten_toe_off and not v01.shaping.ballistic_flight
    assert (held.tracking.residual_force, held.humanoid.residual_every) == (0.3, 4)
    assert preset("tracker_v01_toe_off").shaping.flatten_toe_off
    assert preset("tracker_v01_feet_balance").tracking.feet_balance
    both = preset("tracker_v01_toe_off_feet_balance")
    assert both.tracking.feet_balance and both.shaping.flatten_toe_off and not both.shaping.ballistic_flight


def test_an_unknown_preset_names_the_known_ones() -> None:
    with pytest.raises(PhysmotionError, match="unknown projection preset 'fast'; known: plain, sampling") as exc:
        preset("fast")
    assert "\n" not in str(exc.value)


def test_docs_list_every_preset() -> None:
    """docs/cli.md's project section lists each preset of the registry."""
    from pathlib import Path

    text = (Path(__file__).parents[2] / "docs" / "cli.md").read_text()
    project = text.split("\n## project\n", 1)[1].split("\n## ", 1)[0]
    assert [name for name in preset_names() if f"| `{name}` |" not in project] == []


def test_project_takes_a_preset_by_name(mocap_dir, tmp_path) -> None:
    """`physmotion project --preset sampling` runs generation's P (a reset count, no input kept); an unknown
    name fails in one line that lists the known ones."""
    from physmotion.io.importer import import_clip, load_manifest
    from physmotion.motion import Motion
    from tests.cli_runner import invoke

    info = {c.clip: c for c in load_manifest(mocap_dir)}["bandai2_dataset-2_walk_normal_001"]
    motion = import_clip(info, floor="frame0", fps=20)
    Motion(joints=motion.joints[:40], fps=20).save(tmp_path / "walk.npz")
    res = invoke("project", tmp_path / "walk.npz", "-o", tmp_path / "out.npz", "--preset", "sampling")
    assert res.returncode == 0, res.stderr
    resets = Motion.load(tmp_path / "out.npz").resets
    assert resets is not None and f"put back onto the motion {resets} time(s)" in res.stdout
    res = invoke("project", tmp_path / "walk.npz", "-o", tmp_path / "bad.npz", "--preset", "fast")
    assert res.returncode == 1 and "unknown projection preset 'fast'; known: plain, sampling" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
