"""Physical metrics against hand-computed values, independent ports of the source code, and real mocap."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console
from scipy.spatial.transform import Rotation

from physmotion.errors import ShapeError
from physmotion.metrics import (
    DEFAULT_BODY,
    METRICS,
    BodySurface,
    MetricParams,
    acceleration_consistency,
    clip_ratio,
    float_,
    float_ratio,
    format_table,
    imitation_failure_rate,
    lowest_surface_height,
    mpjpe,
    penetrate,
    penetration_ratio,
    per_motion_metrics,
    pfc,
    phys_err,
    physical_metrics,
    skate,
    skating_ratio,
    smoothness,
    speed,
    velocity_consistency,
)
from physmotion.skeleton import JOINT_INDEX, JOINT_NAMES, REST_OFFSETS, bone_lengths, rest_joints

from .conftest import MakeMotion

J = JOINT_INDEX
REL = 0.01  # "within 1%"


# ------------------------------------------------------------------------------------------------
# Geometry


def test_rest_body_soles_are_flat_and_below_the_foot_joints() -> None:
    pose = rest_joints()  # lowest joint (the foot joints) on y = 0
    feet = DEFAULT_BODY.foot_heights(pose[None])[0]
    assert np.ptp(feet) < 1e-9  # heel and toe boxes share one sole plane, 14.5 mm below the foot joints
    assert lowest_surface_height(pose[None])[0] == pytest.approx(-0.0145, abs=1e-9)
    assert feet[0] == pytest.approx(pose[J["left_ankle"], 1] - 0.052 - 0.0145, abs=1e-9)


def test_default_body_stands_as_the_humanoid(planted_pose: np.ndarray) -> None:
    from physmotion.physics.humanoid import standing_height

    assert planted_pose[0, 1] == pytest.approx(standing_height(), abs=1e-9)
    bigger = REST_OFFSETS * 1.1
    assert -DEFAULT_BODY.lowest_height(rest_joints(bigger, root_height=0.0)[None])[0] == pytest.approx(
        standing_height(bigger), abs=1e-9
    )


# Parts of BodyGeometry.part_heights: capsules, spheres, hands (L, R), ankle/toe boxes (L, R).
_PART_BODIES = [JOINT_NAMES[c.joint] for c in DEFAULT_BODY.capsules]
_PART_BODIES += [JOINT_NAMES[j] for j, _ in DEFAULT_BODY.spheres]
_PART_BODIES += ["left_wrist", "right_wrist", "left_ankle", "left_foot", "right_ankle", "right_foot"]


def _mujoco_pose(local: dict[str, np.ndarray], yaw: float = 0.0) -> tuple[np.ndarray, dict[str, float]]:
    """Pose the physics humanoid (default body) with local rotations given in our frame.

    Returns its joints (22, 3) in our frame and the lowest point (our y) of each body's geoms.
    """
    mujoco = pytest.importorskip("mujoco")
    from physmotion.physics.frames import from_mujoco, rot_to_mujoco
    from physmotion.physics.humanoid import build_model, layout

    model = build_model()
    lay = layout(model)
    data = mujoco.MjData(model)
    qpos = model.qpos0.copy()
    qpos[3:7] = Rotation.from_rotvec([0.0, 0.0, yaw]).as_quat(scalar_first=True)
    for name, rot in local.items():
        j = J[name]
        euler = Rotation.from_matrix(rot_to_mujoco(rot)).as_euler(lay.hinge_order[j].upper())  # intrinsic
        qpos[lay.hinge_qpos[j]] = euler
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    lowest: dict[str, float] = {}
    for g in range(1, model.ngeom):  # geom 0 is the floor
        z, rot, size = data.geom_xpos[g, 2], data.geom_xmat[g].reshape(3, 3), model.geom_size[g]
        kind = model.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            low = z - size[0]
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            low = z - abs(rot[2, 2]) * size[1] - size[0]
        else:
            low = z - np.abs(rot[2]) @ size
        body = JOINT_NAMES[list(lay.body_ids).index(model.geom_bodyid[g])]
        lowest[body] = min(lowest.get(body, np.inf), float(low))
    return from_mujoco(data.xpos[lay.body_ids]), lowest


def test_geometry_matches_the_mujoco_humanoid_at_rest() -> None:
    joints, lowest = _mujoco_pose({})
    ours = DEFAULT_BODY.part_heights(joints[None])[0]
    for name, h in zip(_PART_BODIES, ours):
        # Hands: MuJoCo frames the box about the (1.9 deg rising) forearm its own way: 0.8 mm apart.
        assert h == pytest.approx(lowest[name], abs=1e-3 if name.endswith("wrist") else 1e-6), name


def test_capsules_and_spheres_match_the_mujoco_humanoid_in_any_pose() -> None:
    rng = np.random.default_rng(1)
    local = {n: Rotation.from_rotvec(rng.uniform(-0.5, 0.5, 3)).as_matrix() for n in JOINT_NAMES[1:]}
    joints, lowest = _mujoco_pose(local, yaw=0.7)
    ours = DEFAULT_BODY.part_heights(joints[None])[0]
    n = len(DEFAULT_BODY.capsules) + len(DEFAULT_BODY.spheres)
    for name, h in zip(_PART_BODIES[:n], ours[:n]):
        assert h == pytest.approx(lowest[name], abs=1e-6), name


@pytest.mark.parametrize("pitch_deg, yaw_deg", [(25.0, 0.0), (-20.0, 40.0), (50.0, -110.0)])
def test_ankle_box_matches_the_mujoco_humanoid_when_the_foot_pitches(
    pitch_deg: float, yaw_deg: float
) -> None:
    # Pitch about the foot's own lateral axis (no roll): Ry(rest yaw) Rx(pitch) Ry(-rest yaw), ours.
    rest_yaw = np.arctan2(REST_OFFSETS[J["left_foot"], 0], REST_OFFSETS[J["left_foot"], 2])
    ry = Rotation.from_rotvec([0.0, rest_yaw, 0.0])
    rx = Rotation.from_rotvec([np.deg2rad(pitch_deg), 0.0, 0.0])
    left, right = (ry * rx * ry.inv()).as_matrix(), (ry.inv() * rx * ry).as_matrix()  # mirror images
    joints, lowest = _mujoco_pose({"left_ankle": left, "right_ankle": right}, yaw=np.deg2rad(yaw_deg))
    ours = DEFAULT_BODY.part_heights(joints[None])[0]
    for name in ("left_ankle", "right_ankle"):
        assert ours[_PART_BODIES.index(name)] == pytest.approx(lowest[name], abs=1e-6), name


def test_hand_and_toe_geometry(planted_pose: np.ndarray) -> None:
    pose = planted_pose.copy()
    elbow, wrist = pose[J["left_elbow"]], pose[J["left_wrist"]]
    pose[J["left_wrist"]] = elbow + [0.0, -np.linalg.norm(wrist - elbow), 0.0]  # forearm hanging down
    hand = DEFAULT_BODY.part_heights(pose[None])[0, _PART_BODIES.index("left_wrist")]
    assert hand == pytest.approx(pose[J["left_wrist"], 1] - 0.19, abs=1e-9)
    # The toe box stays level whatever the foot's pitch: its sole is 14.5 mm below the foot joint.
    pose = planted_pose.copy()
    pose[J["left_foot"], 1] -= 0.04
    scale = bone_lengths(pose).sum() / bone_lengths(planted_pose).sum()
    toe = DEFAULT_BODY.foot_heights(pose[None])[0, 1]
    assert toe == pytest.approx(pose[J["left_foot"], 1] - 0.0145 * scale)


class _LowestJoint:
    """A swapped-in surface: the joints themselves (what CLoSD uses)."""

    def lowest_height(self, joints: np.ndarray) -> np.ndarray:
        return joints[..., 1].min(axis=-1)

    def foot_heights(self, joints: np.ndarray) -> np.ndarray:
        return joints[..., [7, 10, 8, 11], 1]


def test_body_surface_is_pluggable(make_motion: MakeMotion) -> None:
    body = _LowestJoint()
    assert isinstance(body, BodySurface) and isinstance(DEFAULT_BODY, BodySurface)
    motion = make_motion(lift=0.037)  # soles at 37 mm, foot joints at 37 + 14.5 mm
    assert float_(motion) == pytest.approx(32.0, rel=REL)
    assert float_(motion, body=body) == pytest.approx(37.0 + 14.5 - 5.0, rel=REL)


# ------------------------------------------------------------------------------------------------
# PhysDiff: Penetrate, Float, Skate, Phys-Err


def test_planted_motion_scores_zero(make_motion: MakeMotion) -> None:
    m = physical_metrics(make_motion())
    for name in ("penetrate", "float", "skate", "phys_err", "pfc", "skate_ratio", "float_ratio",
                 "penetrate_ratio", "clip_ratio", "speed", "smoothness"):  # fmt: skip
        assert m[name] == pytest.approx(0.0, abs=1e-9), name
    assert np.isnan(m["vc"]) and np.isnan(m["ac"])  # no movement, no spectrum


def test_float_and_penetrate_known_offsets(make_motion: MakeMotion) -> None:
    up, down = make_motion(lift=0.037), make_motion(lift=-0.023)
    assert float_(up) == pytest.approx(37.0 - 5.0, rel=REL) and penetrate(up) == 0.0
    assert penetrate(down) == pytest.approx(23.0 - 5.0, rel=REL) and float_(down) == 0.0
    # Half the frames up, half down: each metric is a mean over all frames.
    mixed = np.concatenate([up[:20], down[:20]])
    assert float_(mixed) == pytest.approx(32.0 / 2, rel=REL)
    assert penetrate(mixed) == pytest.approx(18.0 / 2, rel=REL)
    assert phys_err(mixed) == pytest.approx(25.0, rel=REL)


@pytest.mark.parametrize("lift_mm, expect_float, expect_pen", [
    (4.0, 0.0, 0.0), (5.0, 0.0, 0.0), (6.0, 1.0, 0.0), (-4.0, 0.0, 0.0), (-6.0, 0.0, 1.0),
])  # fmt: skip
def test_five_mm_tolerance(
    make_motion: MakeMotion, lift_mm: float, expect_float: float, expect_pen: float
) -> None:
    motion = make_motion(lift=lift_mm / 1000)
    assert float_(motion) == pytest.approx(expect_float, abs=1e-6)
    assert penetrate(motion) == pytest.approx(expect_pen, abs=1e-6)


def test_skate_of_feet_sliding_in_contact(make_motion: MakeMotion) -> None:
    sliding = make_motion(velocity=(0.3, 0.0, 0.0))  # 0.3 m/s = 15 mm per 20-fps frame
    assert skate(sliding) == pytest.approx(15.0, rel=REL)
    # The same slide captured at 40 fps is still 15 mm per reference (20 fps) frame.
    at_40 = make_motion(frames=81, velocity=(0.0, 0.0, 0.3), fps=40)
    assert skate(at_40, fps=40) == pytest.approx(15.0, rel=REL)
    # Lifted 37 mm the feet are out of contact: gliding through the air is not skating.
    assert skate(make_motion(lift=0.037, velocity=(0.3, 0.0, 0.0))) == 0.0
    # Sliding only while planted (first 20 pairs of 40): the mean is over all pairs.
    half = make_motion(velocity=(0.3, 0.0, 0.0))
    half[21:, :, 1] += 0.05
    assert skate(half) == pytest.approx(15.0 * 20 / 40, rel=REL)
    assert phys_err(half) == pytest.approx(skate(half) + float_(half), rel=1e-9)


def test_skate_counts_only_the_feet_in_contact(make_motion: MakeMotion) -> None:
    motion = make_motion()
    motion[:, J["left_foot"], 2] += 0.2 / 20 * np.arange(41)  # left toe slides forward at 0.2 m/s
    motion[:, J["right_ankle"], 1] += 0.1  # right heel lifted (heel box out of contact)
    # Per pair: heels/toes in contact = L heel (0 mm), L toe (10 mm), R toe (0 mm): mean 10/3 mm.
    assert skate(motion) == pytest.approx(10.0 / 3, rel=REL)


# ------------------------------------------------------------------------------------------------
# EDGE's PFC


def _edge_pfc(motions: list[np.ndarray], fps: float) -> float:
    """Stanford-TML/EDGE eval/eval_pfc.py calc_physical_score, line by line, Y up, DT = 1/fps."""
    up_dir, flat_dirs, dt = 1, [0, 2], 1.0 / fps
    scores = []
    for joint3d in motions:
        root_v = (joint3d[1:, 0, :] - joint3d[:-1, 0, :]) / dt
        root_a = (root_v[1:] - root_v[:-1]) / dt
        root_a[:, up_dir] = np.maximum(root_a[:, up_dir], 0)
        root_a = np.linalg.norm(root_a, axis=-1)
        root_a /= root_a.max()
        feet = joint3d[:, [7, 10, 8, 11]]
        foot_v = np.linalg.norm(feet[2:, :, flat_dirs] - feet[1:-1, :, flat_dirs], axis=-1)
        foot_mins = np.zeros((len(foot_v), 2))
        foot_mins[:, 0] = np.minimum(foot_v[:, 0], foot_v[:, 1])
        foot_mins[:, 1] = np.minimum(foot_v[:, 2], foot_v[:, 3])
        scores.append((foot_mins[:, 0] * foot_mins[:, 1] * root_a).mean())
    return float(np.mean(scores) * 10000)


def test_pfc_matches_edge_code(random_batch: np.ndarray) -> None:
    assert pfc(random_batch) == pytest.approx(_edge_pfc(list(random_batch), 20.0), rel=1e-9)


def test_pfc_of_an_accelerating_slide(make_motion: MakeMotion) -> None:
    # x = a t^2 / 2 for every joint: |root acceleration| = a everywhere (normalised to 1), and both feet
    # step 0.5 a dt^2 (2k + 3) from frame k+1 to k+2, so PFC = 1e4 * mean_k (0.5 a dt^2 (2k + 3))^2.
    a, dt, frames = 2.0, 0.05, 41
    motion = make_motion(frames=frames)
    motion[..., 0] += 0.5 * a * (np.arange(frames) * dt)[:, None] ** 2
    expect = 1e4 * np.mean([(0.5 * a * dt**2 * (2 * k + 3)) ** 2 for k in range(frames - 2)])
    assert pfc(motion) == pytest.approx(expect, rel=REL)
    # Falling (downward root acceleration) needs no foot contact: clamped to 0.
    falling = make_motion(frames=frames, velocity=(0.3, 0.0, 0.0))
    falling[..., 1] -= 0.5 * 9.8 * (np.arange(frames) * dt)[:, None] ** 2
    assert pfc(falling) == 0.0


# ------------------------------------------------------------------------------------------------
# BioMoDiffuse


def _gmd_skating_ratio(motions: np.ndarray) -> np.ndarray:
    """korrawe/guided-motion-diffusion calculate_skating_ratio, rewritten as a plain loop."""
    out = []
    for m in motions:
        feet = m[:, [10, 11]]
        vel = np.linalg.norm(feet[1:, :, [0, 2]] - feet[:-1, :, [0, 2]], axis=-1) * 20.0  # (T-1, 2)
        padded = np.concatenate([np.zeros((2, 2)), vel, np.zeros((2, 2))])
        avg = np.array([padded[i : i + 5].mean(axis=0) for i in range(len(vel))])
        h = feet[:, :, 1]
        contact = (h[:-1] < 0.05) & (h[1:] < 0.05)
        sk = contact & (vel > 0.5) & (avg > 0.5)
        out.append((sk[:, 0] | sk[:, 1]).sum() / len(vel))
    return np.array(out)


def test_skating_ratio_matches_gmd(random_batch: np.ndarray) -> None:
    t = np.arange(random_batch.shape[1]) / 20.0
    fast = random_batch.copy()
    fast[..., 0] += 0.15 * np.sin(2 * np.pi * 0.8 * t)[None, :, None]  # speed swings by +-0.75 m/s
    fast[:, 25:35, :, 1] += 0.04  # toes at 5.6 cm for a while: no contact
    expect = _gmd_skating_ratio(fast)
    assert 0.1 < expect.min() and expect.max() < 0.9
    assert skating_ratio(fast) == pytest.approx(expect.mean(), rel=1e-9)


def test_skating_ratio_window_edges(make_motion: MakeMotion) -> None:
    # At 0.6 m/s the 5-frame mean (zero-padded) is 0.36 and 0.48 m/s at the two pairs nearest each end.
    frames = 41
    expect = (frames - 5) / (frames - 1)
    assert skating_ratio(make_motion(velocity=(0.6, 0, 0))) == pytest.approx(expect, rel=1e-9)
    assert skating_ratio(make_motion(velocity=(0.4, 0, 0))) == 0.0
    assert skating_ratio(make_motion(lift=0.06, velocity=(0.6, 0, 0))) == 0.0  # toes at 7.6 cm: no contact


def test_float_penetration_clip_ratios(make_motion: MakeMotion, planted_pose: np.ndarray) -> None:
    toe_height = planted_pose[J["left_foot"], 1]  # 14.5 mm: the lowest joint of the planted body
    motion = make_motion(frames=40)
    motion[:10, :, 1] += 0.05 - toe_height + 0.001  # lowest joint 1 mm above 5 cm: floating
    motion[10:20, :, 1] -= toe_height + 0.001  # lowest joint 1 mm below the floor
    assert float_ratio(motion) == pytest.approx(0.25)
    assert penetration_ratio(motion) == pytest.approx(0.25)
    motion[:30, J["right_foot"]] = motion[:30, J["left_foot"]] + [0.03, 0.0, 0.0]  # toes 3 cm apart
    assert clip_ratio(motion) == pytest.approx(0.75)


def test_speed_and_smoothness(make_motion: MakeMotion) -> None:
    assert speed(make_motion(velocity=(0.3, 0.0, 0.4))) == pytest.approx(0.5, rel=1e-9)
    # x = j t^3 / 6: the third difference / dt^3 is exactly j for every joint.
    motion = make_motion()
    t = np.arange(41) / 20.0
    motion[..., 2] += (1.7 * t**3 / 6)[:, None]
    assert smoothness(motion) == pytest.approx(1.7, rel=1e-6)
    assert smoothness(make_motion(velocity=(0.3, 0, 0))) == pytest.approx(0.0, abs=1e-9)


def test_velocity_and_acceleration_consistency(make_motion: MakeMotion) -> None:
    # Velocity = c + B cos(2 pi 2 t): DC is the low band, 2 Hz the mid band, 40 samples = 4 whole periods,
    # so VC = (N B / 2) / (N c) = B / (2 c) with B = (2 A / dt) sin(pi f dt) for a finite difference.
    c, amp, f, dt = 0.5, 0.02, 2.0, 0.05
    t = np.arange(41) * dt
    motion = make_motion(frames=41)
    motion[..., 2] += (c * t + amp * np.sin(2 * np.pi * f * t))[:, None]
    b1 = (2 * amp / dt) * np.sin(np.pi * f * dt)
    assert velocity_consistency(motion) == pytest.approx(b1 / (2 * c), rel=1e-6)
    # Acceleration = g + B' cos(...) over 40 samples (42 frames): AC = B' / (2 g).
    g = 1.5
    t = np.arange(42) * dt
    motion = make_motion(frames=42)
    motion[..., 2] += (g * t**2 / 2 + amp * np.sin(2 * np.pi * f * t))[:, None]
    b2 = 4 * amp * np.sin(np.pi * f * dt) ** 2 / dt**2
    assert acceleration_consistency(motion) == pytest.approx(b2 / (2 * g), rel=1e-6)


# ------------------------------------------------------------------------------------------------
# Morph: imitation failure rate


def test_imitation_failure_rate() -> None:
    assert imitation_failure_rate(np.array([0.1, 0.6, 0.4, 0.7])) == pytest.approx(0.5)
    per_frame = np.full((3, 10), 0.1)
    per_frame[0, 4] = 0.8  # fails mid-way
    per_frame[1, 8] = 0.8  # only in padding: ignored
    assert imitation_failure_rate(per_frame, lengths=[10, 6, 10]) == pytest.approx(1 / 3)
    assert imitation_failure_rate(per_frame, tau=0.9) == 0.0
    with pytest.raises(ShapeError):
        imitation_failure_rate(np.array([0.1, np.nan]))


def test_ifr_from_a_simulated_reference(random_batch: np.ndarray) -> None:
    sim = random_batch.copy()
    sim[1, 30:] += [0.0, -0.6, 0.0]  # the simulation of motion 1 falls 0.6 m behind
    assert mpjpe(sim, random_batch)[1, 40] == pytest.approx(0.6)
    assert physical_metrics(sim, reference=random_batch)["ifr"] == pytest.approx(0.25)
    assert "ifr" not in physical_metrics(sim)


# ------------------------------------------------------------------------------------------------
# Batches, masks, errors, table


def test_batch_equals_one_by_one(random_batch: np.ndarray) -> None:
    lengths = np.array([60, 45, 30, 52])
    padded = random_batch.copy()
    for b, n in enumerate(lengths):
        padded[b, n:] = np.nan  # padding must never be read
    batch = physical_metrics(padded, lengths=lengths)
    singles = [physical_metrics(random_batch[b, :n]) for b, n in enumerate(lengths)]
    for name, info in METRICS.items():
        if name in ("ifr", "phys_err"):
            continue
        values = np.array([s[name] for s in singles])
        weights = lengths - info.offset if info.aggregate == "frames" else np.ones(len(lengths))
        assert batch[name] == pytest.approx(np.average(values, weights=weights), rel=1e-9), name
    assert batch["phys_err"] == pytest.approx(batch["penetrate"] + batch["float"] + batch["skate"])
    per = per_motion_metrics(padded, lengths=lengths)
    assert per["skate"][2] == pytest.approx(singles[2]["skate"], rel=1e-9)


def test_mask_equals_lengths(random_batch: np.ndarray) -> None:
    lengths = [60, 20, 33, 4]
    mask = np.arange(60)[None, :] < np.array(lengths)[:, None]
    garbage = random_batch.copy()
    garbage[~mask] = 1e6
    expect = physical_metrics(random_batch, lengths=lengths)
    assert physical_metrics(garbage, mask=mask) == pytest.approx(expect, nan_ok=True)


def test_float32_single_motion_equals_batch_of_one(random_batch: np.ndarray) -> None:
    one = random_batch[0].astype(np.float32)
    assert physical_metrics(one) == pytest.approx(physical_metrics(one[None]), nan_ok=True)


@pytest.mark.parametrize("bad, kwargs", [
    (np.zeros((10, 21, 3)), {}),
    (np.zeros((10, 22, 2)), {}),
    (np.zeros((22, 3)), {}),
    (np.zeros((0, 10, 22, 3)), {}),
    (np.zeros((3, 22, 3)), {}),  # too few frames
    (np.full((10, 22, 3), np.nan), {}),
    (np.full((2, 10, 22, 3), np.inf), {"lengths": [10, 5]}),
    (np.zeros((2, 10, 22, 3)), {"lengths": [10, 3]}),
    (np.zeros((2, 10, 22, 3)), {"lengths": [10, 11]}),
    (np.zeros((2, 10, 22, 3)), {"lengths": [10]}),
    (np.zeros((2, 10, 22, 3)), {"mask": np.array([[True] * 10, [True, False] * 5])}),
    (np.zeros((2, 10, 22, 3)), {"mask": np.ones((2, 10), bool), "lengths": [10, 10]}),
    (np.zeros((10, 22, 3)), {"fps": 0.0}),
    ([["a"]], {}),
])  # fmt: skip
def test_bad_input_raises_one_line_shape_error(bad: object, kwargs: dict) -> None:
    with pytest.raises(ShapeError) as err:
        physical_metrics(bad, **kwargs)  # type: ignore[arg-type]
    assert "\n" not in str(err.value) and str(err.value)


def test_params_are_used(make_motion: MakeMotion) -> None:
    motion = make_motion(lift=0.037)
    assert float_(motion, params=MetricParams(tolerance=0.0)) == pytest.approx(37.0, rel=REL)


def test_format_table_lists_every_metric_with_units(make_motion: MakeMotion) -> None:
    results = {
        "planted": physical_metrics(make_motion()),
        "floating": physical_metrics(make_motion(lift=0.037)),
    }
    table = format_table(results, title="physical metrics")
    console = Console(file=io.StringIO(), width=200, record=True)
    console.print(table)
    text = console.export_text()
    assert [c.header for c in table.columns] == ["metric", "unit", "paper", "planted", "floating"]
    assert table.row_count == len(results["planted"])
    assert "32.000" in text and "mm" in text and "PhysDiff" in text and "m/s^3" in text


# ------------------------------------------------------------------------------------------------
# Real mocap

REAL_WALKS = ("bandai1_dataset-1_walk_normal_001", "bandai2_dataset-2_walk_normal_001", "cmu_02_01")


def test_real_walking_is_nearly_physical(mocap_root: Path) -> None:
    from physmotion.io.importer import import_clip, load_manifest  # lands with the importer

    infos = {info.clip: info for info in load_manifest(mocap_root)}
    for clip in REAL_WALKS:
        motion = import_clip(infos[clip], floor="frame0")  # the importer's floor when this was written
        # Data puts its floor at the lowest joint (HumanML3D); the body surface puts soles under the
        # toe joints, so raise the data by the default sole depth before asking about penetration.
        joints = motion.joints + np.array([0.0, DEFAULT_BODY.sole_below_toe, 0.0], dtype=np.float32)
        m = physical_metrics(joints, fps=motion.fps)
        print(clip, {k: round(v, 3) for k, v in m.items()})
        assert m["penetrate"] < 10.0 and m["float"] < 15.0, clip  # mm (CMU feet sit ~1 cm higher)
        # Real capture slides a little (CMU 02_01: 6.7 mm per frame in the data itself).
        assert m["skate"] < 8.0 and m["skate_ratio"] < 0.3, clip
        assert 0.3 < m["speed"] < 3.0, clip


def test_skate_factors_multiply_back_to_skate(mocap_dir: Path) -> None:
    """Skate = share of frame pairs with a foot touching x Skate over those pairs, on a captured run."""
    from physmotion.io.importer import import_clip, load_manifest
    from physmotion.metrics.physical import skate_factors
    from physmotion.physics.surface import HumanoidSurface, ground_on_surface

    info = {c.clip: c for c in load_manifest(mocap_dir)}["bandai2_dataset-2_run_feminine_001"]
    motion = import_clip(info)
    run, body = ground_on_surface(motion.joints.astype(np.float64))
    surface = HumanoidSurface(body)
    share, slide = skate_factors(run, motion.fps, body=surface)
    assert 0.0 < share < 1.0 and slide > 0.0
    skate = physical_metrics(run, fps=motion.fps, body=surface)["skate"]
    assert share * slide == pytest.approx(skate, rel=1e-9)
    # feet lifted over the tolerance: no contact, no Skate, however they move
    assert skate_factors(run + [0.0, 0.05, 0.0], motion.fps, body=surface) == (0.0, 0.0)
    with pytest.raises(ShapeError):
        skate_factors(np.stack([run, run]), motion.fps, body=surface)
