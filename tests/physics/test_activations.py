"""Muscle-activation stand-ins from inverse dynamics, on real Bandai clips (walk, run)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from physmotion.errors import ShapeError
from physmotion.io.importer import import_clip, load_manifest
from physmotion.physics.activations import ACTIVATION_CHANNELS, activations
from physmotion.skeleton import mirror_joints

WALK = "bandai2_dataset-2_walk_normal_001"
RUN = "bandai2_dataset-2_run_normal_001"  # same capture set and actor rig as WALK
KNEES = [ACTIVATION_CHANNELS.index(c) for c in ("left_knee", "right_knee")]
ELBOWS = [ACTIVATION_CHANNELS.index(c) for c in ("left_elbow", "right_elbow")]
# Channel order of the mirrored motion: left and right swapped.
SWAP = [ACTIVATION_CHANNELS.index(c.replace("left", "@").replace("right", "left").replace("@", "right"))
        for c in ACTIVATION_CHANNELS]  # fmt: skip


@pytest.fixture(scope="module")
def clips(mocap_dir: Path) -> dict[str, np.ndarray]:
    """clip -> joints (T, 22, 3) at 20 fps, in the data convention ``activations`` takes (the clip's lowest
    joint at y = 0, as the dataset build gives it), not the importer's surface floor."""
    from physmotion.diffusion.physdiff import on_data_floor

    infos = {c.clip: c for c in load_manifest(mocap_dir)}
    out = {}
    for clip in (WALK, RUN):
        motion = import_clip(infos[clip])
        assert motion.fps == 20
        out[clip] = on_data_floor(motion.joints)
    return out


def test_shape_range_and_speed(clips: dict[str, np.ndarray]) -> None:
    activations(clips[RUN][:5])  # MuJoCo import and first model outside the timing
    for clip, joints in clips.items():
        start = time.perf_counter()
        act = activations(joints)
        seconds = time.perf_counter() - start
        assert act.shape == (len(joints), len(ACTIVATION_CHANNELS)) and act.dtype == np.float32
        assert np.all(np.isfinite(act)) and act.min() >= 0 and act.max() <= 1
        assert act.max() > 0.05  # the legs do work
        minutes = len(joints) / 20 / 60
        print(
            f"\n{clip}: {len(joints)} frames in {seconds:.3f} s ({seconds / minutes:.2f} s per minute of "
            f"motion); mean {dict(zip(ACTIVATION_CHANNELS, (round(float(v), 3) for v in act.mean(0))))}"
        )


def test_standing_is_light_running_loads_the_knees(clips: dict[str, np.ndarray]) -> None:
    stand = activations(np.repeat(clips[WALK][:1], 20, axis=0))  # the walk's first pose, held still
    walk, run = activations(clips[WALK]), activations(clips[RUN])
    assert stand[:, KNEES].max() < 0.05 and stand[:, ELBOWS].max() < 0.02
    assert np.ptp(stand, axis=0).max() < 1e-6  # a still pose: the same effort every frame
    knee = {
        name: round(float(np.percentile(a[:, KNEES], 90)), 3)
        for name, a in (("stand", stand), ("walk", walk), ("run", run))
    }
    print(f"\nknee activation, 90th percentile: {knee}")
    assert knee["walk"] > 1.5 * knee["stand"]
    assert knee["run"] > 1.5 * knee["walk"]
    assert run[:, KNEES].mean() > 2 * stand[:, KNEES].mean()


def test_mirrored_motion_swaps_left_and_right(clips: dict[str, np.ndarray]) -> None:
    joints = clips[WALK]
    act, mirrored = activations(joints), activations(mirror_joints(joints))
    assert np.abs(mirrored - act).mean() > 0.005  # the motion itself is not symmetric ...
    assert np.abs(mirrored[:, SWAP] - act).mean() < 0.002  # ... its mirror image swaps the channels


def test_deterministic(clips: dict[str, np.ndarray]) -> None:
    assert activations(clips[RUN]).tobytes() == activations(clips[RUN].copy()).tobytes()


@pytest.mark.parametrize(
    ("case", "message"),
    [("two_frames", "at least 3 frames"), ("joints_21", "shape"), ("flat", "shape"), ("nan", "NaN"),
     ("fps_0", "fps")],
)  # fmt: skip
def test_bad_input_raises_one_line_shape_error(clips: dict[str, np.ndarray], case: str, message: str) -> None:
    joints, fps = clips[RUN][:10].copy(), 20.0
    if case == "two_frames":
        joints = joints[:2]
    elif case == "joints_21":
        joints = joints[:, :21]
    elif case == "flat":
        joints = joints.reshape(10, -1)
    elif case == "nan":
        joints[4, 7, 1] = np.nan
    else:
        fps = 0.0
    with pytest.raises(ShapeError, match=message) as err:
        activations(joints, fps)
    assert "\n" not in str(err.value)
