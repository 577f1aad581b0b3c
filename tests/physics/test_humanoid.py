"""The MuJoCo humanoid: sizes, names, mass, feet, gains, standing under a PD hold, the axis mapping."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physmotion.errors import ShapeError
from physmotion.physics import frames
from physmotion.physics.humanoid import (
    JOINT_GROUP,
    HumanoidConfig,
    body_masses,
    build_mjcf,
    build_model,
    hinge_range,
    layout,
    standing_height,
)
from physmotion.skeleton import JOINT_NAMES, REST_OFFSETS

from .conftest import other_body

FEET = ("left_ankle", "left_foot", "right_ankle", "right_foot")


def _name(model, kind, i: int) -> str:
    return mujoco.mj_id2name(model, kind, i)


def _lowest_point(model, data, geom: str) -> float:
    """Lowest world z of a box geom's corners."""
    g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, geom)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * model.geom_size[g]
    world = data.geom_xpos[g] + corners @ data.geom_xmat[g].reshape(3, 3).T
    return float(world[:, 2].min())


def test_sizes_and_names(default_model) -> None:
    m = default_model
    assert (m.nq, m.nv, m.nu, m.nbody) == (70, 69, 63, 23)
    assert {_name(m, mujoco.mjtObj.mjOBJ_BODY, i) for i in range(1, m.nbody)} == set(JOINT_NAMES)
    hinges = {_name(m, mujoco.mjtObj.mjOBJ_JOINT, i) for i in range(1, m.njnt)}
    assert hinges == {f"{n}_{a}" for n in JOINT_NAMES[1:] for a in "xyz"}
    assert m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    for i in range(6, m.nv):
        group = JOINT_GROUP[_name(m, mujoco.mjtObj.mjOBJ_JOINT, m.dof_jntid[i]).rsplit("_", 1)[0]]
        assert m.dof_armature[i] == pytest.approx(0.03 if group in ("ankle", "foot") else 0.01)


def test_options_follow_config(default_model) -> None:
    m = default_model
    assert m.opt.timestep == pytest.approx(1 / 360)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.opt.solver == mujoco.mjtSolver.mjSOL_NEWTON
    assert m.opt.iterations == 50
    assert m.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL and m.opt.impratio == 1.0 and m.opt.noslip_iterations == 0
    other = build_model(config=HumanoidConfig(cone="elliptic", impratio=10.0, noslip=5))
    assert other.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and other.opt.impratio == 10.0
    assert other.opt.noslip_iterations == 5
    assert set(m.geom_condim) == {3}
    assert set(build_model(config=HumanoidConfig(condim=4)).geom_condim) == {4}
    with pytest.raises(ShapeError, match="condim"):
        HumanoidConfig(condim=2)
    with pytest.raises(ShapeError, match="hand_length"):
        HumanoidConfig(hand_length=0.01)


def test_the_hand_box_ends_at_hand_length(default_model) -> None:
    """The wrist's box runs from 2 cm past the wrist to ``hand_length`` along the forearm (default body)."""
    short = build_model(config=HumanoidConfig(hand_length=0.08))
    for m, length in ((default_model, 0.19), (short, 0.08)):
        for side in ("left", "right"):
            gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{side}_wrist")
            assert m.geom_size[gid, 2] == pytest.approx(0.5 * (length - 0.02), rel=1e-6)
            assert np.linalg.norm(m.geom_pos[gid]) == pytest.approx(0.5 * (length + 0.02), rel=1e-6)
    assert short.body_mass.sum() == pytest.approx(default_model.body_mass.sum())  # the hand keeps its mass
    assert HumanoidConfig().substeps == 12  # control at 30 Hz
    assert HumanoidConfig(sim_dt=1 / 240).substeps == 8
    with pytest.raises(ShapeError):
        HumanoidConfig(sim_dt=1 / 120, control_dt=1 / 50)


def test_actuators_in_qpos_order_with_group_gains(default_model) -> None:
    m = default_model
    cfg = HumanoidConfig()
    for i in range(m.nu):
        jid = m.actuator_trnid[i, 0]
        assert m.jnt_qposadr[jid] == 7 + i  # ctrl[i] is the target of qpos[7 + i]
        gain = cfg.gains[JOINT_GROUP[_name(m, mujoco.mjtObj.mjOBJ_JOINT, jid).rsplit("_", 1)[0]]]
        assert m.actuator_gainprm[i, 0] == pytest.approx(gain.kp)
        assert -m.actuator_biasprm[i, 1] == pytest.approx(gain.kp)
        assert -m.actuator_biasprm[i, 2] == pytest.approx(gain.kv)
        assert tuple(m.actuator_forcerange[i]) == pytest.approx((-gain.torque_limit, gain.torque_limit))


def test_total_mass_and_override(default_model) -> None:
    assert default_model.body_mass.sum() == pytest.approx(70.0, abs=1e-3)
    heavy = build_model(other_body(), HumanoidConfig(total_mass=85.0))
    assert heavy.body_mass.sum() == pytest.approx(85.0, abs=1e-3)
    for name, mass in body_masses().items():
        b = mujoco.mj_name2id(default_model, mujoco.mjtObj.mjOBJ_BODY, name)
        assert default_model.body_mass[b] == pytest.approx(mass, rel=1e-4)


@pytest.mark.parametrize("which", ["default", "other"])
def test_rest_pose_stands_flat_on_both_feet(which: str) -> None:
    offsets = REST_OFFSETS if which == "default" else other_body()
    m = build_model(offsets)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    assert d.qpos[2] == pytest.approx(standing_height(offsets))
    for geom in FEET:
        assert abs(_lowest_point(m, d, geom)) < 0.005, geom
    # heel: the ankle box reaches behind the ankle (removes the backward fall mode)
    for side in ("left", "right"):
        ankle = d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{side}_ankle")]
        g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{side}_ankle")
        assert d.geom_xpos[g][0] - m.geom_size[g][0] < ankle[0] - 0.05
    # no self-contacts in the rest pose: every contact is with the floor
    for c in d.contact[: d.ncon]:
        assert 0 in (c.geom1, c.geom2)
    if which == "default":
        assert standing_height() == pytest.approx(0.9346, abs=1e-4)


def test_pd_hold_stands_for_two_seconds(default_model) -> None:
    m = default_model
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    z0 = d.qpos[2]
    zmin = z0
    for _ in range(240):  # 2 s at 1/120; ctrl = 0 holds the rest pose
        mujoco.mj_step(m, d)
        zmin = min(zmin, d.qpos[2])
    assert z0 - zmin < 0.15
    assert d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 0
    tilt = np.degrees(2 * np.arccos(min(1.0, abs(d.qpos[3]))))
    assert tilt < 20.0


def test_right_side_limits_mirror_the_left() -> None:
    cfg = HumanoidConfig()
    for left in [n for n in JOINT_NAMES if n.startswith("left_")]:
        right = left.replace("left_", "right_")
        for axis in "xyz":
            lo, hi = hinge_range(left, axis, cfg)
            rlo, rhi = hinge_range(right, axis, cfg)
            assert (rlo, rhi) == ((-hi, -lo) if axis in "xz" else (lo, hi))
            assert lo <= 0.0 <= hi  # the rest pose is inside every range


def test_layout_reads_the_model(default_model) -> None:
    lay = layout(default_model)
    assert np.allclose(lay.offsets[1:], REST_OFFSETS[1:])
    assert sorted(lay.hinge_qpos[1:].ravel().tolist()) == list(range(7, 70))
    for j in range(1, len(JOINT_NAMES)):
        assert lay.hinge_order[j] == HumanoidConfig().hinge_order[JOINT_GROUP[JOINT_NAMES[j]]]


def test_hinge_order_is_configurable() -> None:
    cfg = HumanoidConfig()
    order = dict(cfg.hinge_order, hip="xyz")
    m = build_model(None, dataclasses.replace(cfg, hinge_order=order))
    assert layout(m).hinge_order[JOINT_NAMES.index("left_hip")] == "xyz"


@pytest.mark.parametrize(
    "offsets, match",
    [(np.zeros((21, 3)), "shape"), (np.full((22, 3), np.nan), "NaN"), (np.zeros((22, 3)), "zero-length")],
)
def test_bad_offsets_raise_shape_error(offsets: np.ndarray, match: str) -> None:
    with pytest.raises(ShapeError, match=match) as info:
        build_mjcf(offsets)
    assert "\n" not in str(info.value)


def test_axis_mapping_is_one_proper_rotation() -> None:
    rng = np.random.default_rng(0)
    p = rng.normal(size=(5, 3))
    rot = Rotation.random(5, random_state=1)
    assert np.allclose(frames.from_mujoco(frames.to_mujoco(p)), p)
    assert np.allclose(frames.to_mujoco(p), p @ frames.MJ_FROM_OURS.T)
    assert np.linalg.det(frames.MJ_FROM_OURS) == pytest.approx(1.0)  # handedness kept
    # ours: x left, y up, z forward -> MuJoCo: x forward, y left, z up
    axes = frames.to_mujoco(np.eye(3))
    assert np.allclose(axes, [[0, 1, 0], [0, 0, 1], [1, 0, 0]])
    r = rot.as_matrix()
    rotated_mj = np.einsum("nij,nj->ni", frames.rot_to_mujoco(r), frames.to_mujoco(p))
    assert np.allclose(frames.to_mujoco(np.einsum("nij,nj->ni", r, p)), rotated_mj)
    assert np.allclose(frames.rot_from_mujoco(frames.rot_to_mujoco(r)), r)
    q_mj = frames.quat_to_mujoco(rot.as_quat(scalar_first=True))
    assert np.allclose(Rotation.from_quat(q_mj, scalar_first=True).as_matrix(), frames.rot_to_mujoco(r))
    assert np.allclose(frames.quat_from_mujoco(q_mj), rot.as_quat(scalar_first=True))
