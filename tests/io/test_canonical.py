"""Canonicalisation: resampling, up axis, T-pose frame, placement."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from physmotion.conventions import FPS
from physmotion.io import import_clip, import_clip_with_report
from physmotion.io.amc import read_amc
from physmotion.io.bvh import write_bvh
from physmotion.io.canonical import canonicalize, is_tpose_start, resample
from physmotion.io.floor import best_floor, stance_frames
from physmotion.io.rigs import RIGS, RigMotion
from physmotion.physics.surface import HumanoidSurface
from physmotion.skeleton import JOINT_INDEX, bone_lengths, facing_direction


def test_resample_is_slerp_and_lerp() -> None:
    frames, nodes = 41, 3
    rot = Rotation.random(frames * nodes, random_state=4).as_matrix().reshape(frames, nodes, 3, 3)
    trans = np.random.default_rng(4).normal(size=(frames, nodes, 3))
    rig = RigMotion(("a", "b", "c"), np.array([-1, 0, 1]), rot, trans)
    out = resample(rig, fps=120.0, target_fps=FPS)
    assert out.num_frames == 7 and out.fps == FPS  # 40 / 120 s = 0.333 s -> frames at 0, 0.05, ... 0.3
    times, query = np.arange(frames) / 120.0, np.arange(7) / FPS
    for j in range(nodes):
        expected = Slerp(times, Rotation.from_matrix(rot[:, j]))(query).as_matrix()
        assert np.allclose(out.rotations[:, j], expected, atol=1e-10)
        for k in range(3):
            assert np.allclose(out.translations[:, j, k], np.interp(query, times, trans[:, j, k]))
    assert resample(rig, fps=FPS) is rig


def test_resampled_rig_keeps_bone_lengths(clip) -> None:
    info = clip("cmu_02_05")
    rig = read_amc(info.path, info.skeleton)
    pos = resample(rig, info.fps).forward_kinematics()
    parents = rig.parents[1:]
    lengths = np.linalg.norm(pos[:, 1:] - pos[:, parents], axis=-1)
    assert lengths.std(axis=0).max() < 1e-9


def _z_up(rig: RigMotion) -> RigMotion:
    """The same motion in a Z-up world: x stays, y (up) becomes z, z (forward) becomes -y."""
    to_z = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    rot, trans = rig.rotations.copy(), rig.translations.copy()
    rot[:, 0] = to_z @ rot[:, 0]
    trans[:, 0] = trans[:, 0] @ to_z.T
    return replace(rig, rotations=rot, translations=trans)


def test_z_up_input_comes_out_like_y_up(clip) -> None:
    info = clip("cmu_02_01")
    rig = read_amc(info.path, info.skeleton)
    table = RIGS["cmu_asf"]
    y_up = canonicalize(rig, table, info.fps, units=rig.units)
    z_up = canonicalize(_z_up(rig), table, info.fps, units=rig.units, up_axis="Z")
    assert np.allclose(y_up.joints, z_up.joints, atol=1e-9)
    assert (
        z_up.joints[0, JOINT_INDEX["left_hip"], 0] > z_up.joints[0, JOINT_INDEX["right_hip"], 0]
    )  # not mirrored


def test_placement(clip) -> None:
    motion, report = import_clip_with_report(clip("cmuiclone_02_05"))
    j = motion.joints
    assert motion.fps == FPS and j.dtype == np.float32
    # the floor where Penetrate + Float over the stance frames is least
    lowest = HumanoidSurface().lowest_height(j.astype(np.float64))
    stance = stance_frames(j)
    assert stance.mean() > 0.5 and report.grounding.hand_share == 0  # a walk: some foot planted most of the time
    assert abs(best_floor(lowest, stance)) < 1e-5
    assert np.allclose(j[0, 0, [0, 2]], 0, atol=1e-6)
    assert np.allclose(facing_direction(j[0].astype(np.float64)), [0, 0, 1], atol=1e-5)


def _with_frames_first(rig: RigMotion, count: int) -> RigMotion:
    """``count`` rest-pose (all rotations identity) frames prepended; CMU's rest pose is a T-pose."""
    rot = np.concatenate([np.broadcast_to(np.eye(3), (count,) + rig.rotations.shape[1:]), rig.rotations])
    trans = np.concatenate([np.repeat(rig.translations[:1], count, axis=0), rig.translations])
    return replace(rig, rotations=rot, translations=trans)


def test_tpose_frame_is_detected_and_dropped(clip) -> None:
    info = clip("cmu_02_01")
    rig = read_amc(info.path, info.skeleton)
    table = RIGS["cmu_asf"]
    plain = canonicalize(rig, table, info.fps, units=rig.units)
    padded = canonicalize(_with_frames_first(rig, 1), table, info.fps, units=rig.units)
    assert padded.dropped_tpose and not plain.dropped_tpose
    assert np.allclose(padded.joints, plain.joints, atol=1e-9)
    held = canonicalize(_with_frames_first(rig, 3), table, info.fps, units=rig.units)
    assert not held.dropped_tpose  # a take that holds a T-pose for a while keeps it


def test_tpose_frame_in_a_bvh_file(clip, tmp_path: Path) -> None:
    """A user's BVH with a T-pose frame 0: the AMC take written as BVH on its own rig, re-imported
    through a user mapping (the CMU table as a plain dict)."""
    info = clip("cmu_02_01")
    rig = read_amc(info.path, info.skeleton)
    path = tmp_path / "tpose_first.bvh"
    write_bvh(path, _with_frames_first(rig, 1), fps=info.fps)
    mapping = dict(RIGS["cmu_asf"].joints)
    motion, report = import_clip_with_report(path, mapping=mapping, units=rig.units, fps=info.fps)
    assert report.dropped_tpose and report.source_frames == rig.num_frames + 1
    reference = import_clip(info)
    assert motion.num_frames == reference.num_frames
    assert np.abs(motion.joints - reference.joints).max() < 1e-3


def test_is_tpose_start_on_the_first_frames(clip) -> None:
    info = clip("cmu_02_01")
    rig = read_amc(info.path, info.skeleton)
    table = RIGS["cmu_asf"]

    def first_frames(r: RigMotion) -> np.ndarray:
        return np.einsum("ij,tjk->tik", table.weights(r.names), r.forward_kinematics()[:3])

    assert is_tpose_start(first_frames(_with_frames_first(rig, 1)))
    assert not is_tpose_start(first_frames(rig))


def test_bone_lengths_constant_after_import(clip) -> None:
    for clip_id in ("cmu_02_10", "cmuiclone_02_10", "bandai1_dataset-1_dance-short_normal_001"):
        joints = import_clip(clip(clip_id)).joints.astype(np.float64)
        assert bone_lengths(joints).std(axis=0).max() < 1e-4, clip_id


@pytest.mark.parametrize("bad", ["W", "y-up"])
def test_bad_up_axis(clip, bad: str) -> None:
    from physmotion.errors import PhysmotionError

    with pytest.raises(PhysmotionError, match="up axis"):
        import_clip(clip("cmu_02_01"), up_axis=bad)


def test_z_up_bvh_file(clip, tmp_path: Path) -> None:
    """A user's Z-up BVH (the AMC take turned Z-up, written in centimetres) imports upright."""
    info = clip("cmu_02_01")
    rig = read_amc(info.path, info.skeleton)
    cm = replace(_z_up(rig), translations=_z_up(rig).translations * rig.units * 100)
    path = tmp_path / "z_up_cm.bvh"
    write_bvh(path, cm, fps=info.fps)
    motion = import_clip(path, mapping=dict(RIGS["cmu_asf"].joints), units="cm", up_axis="Z", fps=120)
    assert np.abs(motion.joints - import_clip(info).joints).max() < 1e-3
