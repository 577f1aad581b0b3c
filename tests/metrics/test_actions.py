"""The verb checks on captured motion: each HDM05 action passes its own check and a captured walk passes
none but its own kind (the checks a test of a model's new verbs relies on)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from physmotion.io import import_clip, load_manifest
from physmotion.metrics.actions import ACTION_CHECKS, squat_depth

CLIPS = {
    "squat": "squat1Reps",
    "kick": "kickLFront1Reps",
    "lie down": "lieDownFloor",
    "hop": "hopBothLegs1hops",
}


@pytest.fixture(scope="module")
def actions(hdm05_dir: Path) -> dict[str, object]:
    manifest = load_manifest(hdm05_dir)
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # HDM05's Latin-1 headers
        for verb, key in CLIPS.items():
            motion = import_clip(next(c for c in manifest if key in c.clip))
            out[verb] = motion.joints
    return out


def test_each_captured_action_passes_only_its_own_check(actions: dict[str, object]) -> None:
    for verb, joints in actions.items():
        passed = {v for v, check in ACTION_CHECKS.items() if check.passes(joints)}
        assert verb in passed, (verb, {v: c.measure(joints) for v, c in ACTION_CHECKS.items()})
        assert "lie down" not in passed - {verb} and "squat" not in passed - {verb}, (verb, passed)


def test_a_captured_walk_does_none_of_them(mocap_dir: Path) -> None:
    walk = next(c for c in load_manifest(mocap_dir) if "walk_normal" in c.clip)
    joints = import_clip(walk).joints
    assert not any(check.passes(joints) for check in ACTION_CHECKS.values())
    down, up = squat_depth(joints)
    assert down < 0.1 and up < 0.1
