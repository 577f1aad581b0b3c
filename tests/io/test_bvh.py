"""BVH reader and writer: channel orders, per-joint translations, line endings, generic writing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physmotion.io.bvh import parse_bvh, read_bvh, write_bvh
from physmotion.io.rigs import RigMotion

# Two joints with different channel orders, a 6-channel child whose OFFSET must lose to its
# channels, a root OFFSET that must lose too, tabs and CRLF mixed with LF.
TRICKY = (
    "HIERARCHY\r\nROOT Hips\r\n{\r\n\tOFFSET 5 5 5\r\n"
    "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\r\n"
    "\tJOINT Arm\n\t{\n\t\tOFFSET 100 100 100\n"
    "\t\tCHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation\n"
    "\t\tJOINT Hand\r\n\t\t{\r\n\t\t\tOFFSET 0 2 0\r\n\t\t\tCHANNELS 3 Xrotation Zrotation Yrotation\r\n"
    "\t\t\tEnd Site\r\n\t\t\t{\r\n\t\t\t\tOFFSET 0 1 0\r\n\t\t\t}\r\n\t\t}\r\n\t}\r\n}\r\n"
    "MOTION\r\nFrames:\t2\r\nFrame Time:\t0.0333333\r\n"
    "1 2 3 90 0 0   1 0 0 0 0 0   0 0 0\r\n"
    "1 2 3 0 90 0   1 0 0 0 0 90  30 40 50\r\n"
)


def test_tricky_bvh_fk() -> None:
    rig = parse_bvh(TRICKY)
    assert rig.names == ("Hips", "Arm", "Hand", "Hand_end") and rig.is_end == (False, False, False, True)
    assert rig.fps == pytest.approx(30.0, rel=1e-5)
    pos = rig.forward_kinematics()
    # frame 0: root at (1,2,3) turned 90 deg about Z; Arm 1 along the root's x -> +y.
    assert np.allclose(pos[0, 0], [1, 2, 3]) and np.allclose(pos[0, 1], [1, 3, 3])
    assert np.allclose(pos[0, 2], [-1, 3, 3])  # Hand: (0, 2, 0) turned by Rz(90) -> (-2, 0, 0)
    # frame 1: channel orders ZXY (root), YXZ (Arm), XZY (Hand), intrinsic as BVH means them.
    r_root = Rotation.from_euler("ZXY", [0, 90, 0], degrees=True)
    r_arm = r_root * Rotation.from_euler("YXZ", [0, 0, 90], degrees=True)
    r_hand = r_arm * Rotation.from_euler("XZY", [30, 40, 50], degrees=True)
    arm = np.array([1, 2, 3]) + r_root.apply([1, 0, 0])
    hand = arm + r_arm.apply([0, 2, 0])
    assert np.allclose(pos[1, 1], arm) and np.allclose(pos[1, 2], hand)
    assert np.allclose(pos[1, 3], hand + r_hand.apply([0, 1, 0]))


def test_bandai_uses_channel_translations(clip) -> None:
    info = clip("bandai1_dataset-1_bow_active_001")
    text = info.path.read_text()
    assert "OFFSET 0.847027 93.984 -452.225" in text  # the Hips OFFSET holds a baked start position
    rig = read_bvh(info.path)
    hips = rig.forward_kinematics()[0, rig.index("Hips")]
    assert np.allclose(hips, [-0.53398, 93.523, -9.02016])  # the channel values, not the OFFSET


def test_crlf_file_reads_like_its_lf_copy(clip, tmp_path: Path) -> None:
    info = clip("cmubvh_131_01")  # CRLF and LF lines mixed, tabs
    raw = info.path.read_bytes()
    assert b"\r\n" in raw
    lf = tmp_path / "lf.bvh"
    lf.write_bytes(raw.replace(b"\r\n", b"\n").replace(b"\t", b"  "))
    a, b = read_bvh(info.path), read_bvh(lf)
    assert a.names == b.names and np.array_equal(a.rotations, b.rotations)


def test_keep_builds_only_needed_nodes(clip) -> None:
    info = clip("cmuiclone_02_01")
    full = read_bvh(info.path)
    part = read_bvh(info.path, keep={"CC_Base_L_Hand"})
    assert len(part.names) < 15 < len(full.names)
    idx = [full.index(n) for n in part.names]
    assert np.allclose(part.forward_kinematics(), full.forward_kinematics()[:, idx])


def _random_rig(rng: np.random.Generator, frames: int = 9) -> RigMotion:
    parents = np.array([-1, 0, 1, 1, 0, 4, 2])
    names = ("root", "a b".replace(" ", "_"), "c", "d", "e", "f", "c_end")
    rot = Rotation.random(frames * 7, random_state=1).as_matrix().reshape(frames, 7, 3, 3)
    rot[:, 6] = np.eye(3)
    trans = np.broadcast_to(rng.normal(size=(7, 3)), (frames, 7, 3)).copy()
    trans[:, 0] = rng.normal(size=(frames, 3))  # root moves
    trans[:, 5] += rng.normal(size=(frames, 3))  # an animated translation (6 channels)
    return RigMotion(names, parents, rot, trans, is_end=(False,) * 6 + (True,))


@pytest.mark.parametrize("order", ["YZX", "ZXY", "ZYX", "XYZ"])
def test_writer_round_trips_any_rig(order: str, tmp_path: Path) -> None:
    rig = _random_rig(np.random.default_rng(3))
    path = tmp_path / "rig.bvh"
    write_bvh(path, rig, fps=24.0, order=order)
    back = read_bvh(path)  # depth-first order; leaves d and f gain End Sites
    assert set(rig.names) | {"d_end", "f_end"} == set(back.names) and back.fps == pytest.approx(24.0)
    same = [back.index(n) for n in rig.names]
    assert np.allclose(back.forward_kinematics()[:, same], rig.forward_kinematics(), atol=1e-5)
    text = path.read_text()
    assert text.count("CHANNELS 6") == 2  # the root and the node with an animated translation
    assert f"CHANNELS 3 {order[0]}rotation {order[1]}rotation {order[2]}rotation" in text
