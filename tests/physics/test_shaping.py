"""Reference shaping on a real walk: grounding and swing-foot clearance."""

from __future__ import annotations

import numpy as np
import pytest

from physmotion.physics.humanoid import HumanoidConfig, body_from_joints, build_model, foot_lift, layout
from physmotion.physics.projection import resample_qpos
from physmotion.physics.retarget import joints_to_qpos
from physmotion.physics.shaping import ShapingConfig, shape_reference, swing_clearance, to_floor
from physmotion.physics.surface import geoms_lowest, lowest_point
from physmotion.skeleton import JOINT_INDEX

DT = HumanoidConfig().control_dt


@pytest.fixture(scope="module")
def walk_qpos(real_walk: np.ndarray):
    """(model, qpos (N, 70) at the control rate) of 4 s of the real walk, soles at the floor."""
    x = real_walk[:80]
    body = body_from_joints(x)
    model = build_model(body)
    qpos = resample_qpos(joints_to_qpos(x, model, lift=foot_lift(body)), 20.0, 1.0 / DT)
    return model, qpos


def _lowest(model, qpos: np.ndarray) -> np.ndarray:
    import mujoco

    data = mujoco.MjData(model)
    out = []
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out.append(lowest_point(model, data))
    return np.array(out)


def test_to_floor_raises_sunk_frames_and_lowers_a_floating_motion(walk_qpos) -> None:
    model, qpos = walk_qpos
    grounded = to_floor(model, qpos, DT, float_window=1.0)
    assert _lowest(model, grounded).min() > -1e-9  # nothing under the floor
    assert np.all(grounded[:, 2] >= qpos[:, 2] - 0.005)  # a walk touches the floor: hardly lowered

    lifted = qpos.copy()
    lifted[:, 2] += 0.1
    down = to_floor(model, lifted, DT, float_window=1.0)
    low = _lowest(model, down)
    assert low.min() > -1e-9 and np.median(low) < 0.01  # back on the floor, not 10 cm above it
    # Off: only raised, never lowered.
    np.testing.assert_allclose(to_floor(model, lifted, DT, float_window=0.0), lifted)


def test_to_floor_keeps_a_jump(walk_qpos) -> None:
    """Half a second of flight 10 cm up in the middle of a stand: a jump, not floating."""
    model, qpos = walk_qpos
    stand = np.repeat(to_floor(model, qpos[:1], DT, 0.0), 60, axis=0)
    t = np.arange(60) * DT
    flight = (t > 0.8) & (t < 1.3)
    stand[flight, 2] += 0.1 * np.sin(np.pi * (t[flight] - 0.8) / 0.5)
    out = to_floor(model, stand, DT, float_window=1.0)
    np.testing.assert_allclose(out[:, 2], stand[:, 2], atol=1e-9)


def test_swing_clearance_lifts_swing_feet_only(walk_qpos) -> None:
    import mujoco

    model, qpos = walk_qpos
    qpos = to_floor(model, qpos, DT, 1.0)
    cfg = ShapingConfig()
    out = swing_clearance(model, qpos, DT, cfg)
    lay = layout(model)
    data = mujoco.MjData(model)
    feet = {}
    for side in ("left", "right"):
        ankle, foot = (int(lay.body_ids[JOINT_INDEX[f"{side}_{j}"]]) for j in ("ankle", "foot"))
        feet[side] = (ankle, np.flatnonzero(np.isin(model.geom_bodyid, [ankle, foot])))

    def pose(q):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        return {s: (data.xpos[a].copy(), data.xquat[a].copy(), geoms_lowest(model, data, g).min())
                for s, (a, g) in feet.items()}  # fmt: skip

    lifted, errs = 0, []
    poses = [pose(q) for q in qpos]
    speed = {s: np.linalg.norm(np.gradient(np.array([p[s][0][:2] for p in poses]), DT, axis=0), axis=-1)
             for s in feet}  # fmt: skip
    for k, (before, after_q) in enumerate(zip(poses, out)):
        after = pose(after_q)
        for side, other in (("left", "right"), ("right", "left")):
            (p0, q0, _), (p1, q1, _) = before[side], after[side]
            moving = np.clip(speed[side][k] / cfg.clearance_speed - 1.0, 0.0, 1.0)
            supported = before[other][2] <= cfg.support
            expected = cfg.clearance * moving if supported else 0.0
            errs.append(abs(p1[2] - p0[2] - expected))
            assert p1[2] - p0[2] == pytest.approx(expected, abs=2e-4)
            assert np.linalg.norm(p1[:2] - p0[:2]) < 2e-4  # the foothold's place is kept
            assert abs(abs(q0 @ q1) - 1.0) < 1e-5  # and the foot's orientation
            lifted += expected > 0.005
    print(f"\nlift error max {1000 * max(errs):.3f} mm, {lifted} lifted")
    assert lifted > 20  # the walk has swing phases, and they were lifted
    np.testing.assert_array_equal(out[:, :7], qpos[:, :7])  # the root is not touched
    unlifted = shape_reference(model, qpos, DT, ShapingConfig(clearance=0.0))
    np.testing.assert_array_equal(unlifted, to_floor(model, qpos, DT, 1.0))


def test_hover_support_lifts_the_swing_foot_of_a_hovering_walk(walk_qpos) -> None:
    """The real walk raised 2.5 cm, as a generated stance foot hovers: the floor-based rule sees no support
    and lifts nothing; with ``hover_support`` the lifts are the grounded walk's; a frame higher than
    ``hover_support`` (a flight) is still left alone."""
    model, qpos = walk_qpos
    grounded = to_floor(model, qpos, DT, 1.0)
    hovering = grounded.copy()
    hovering[:, 2] += 0.025
    lifts = swing_clearance(model, grounded, DT, ShapingConfig()) - grounded
    assert np.abs(lifts).max() > 0.01  # the grounded walk's swing feet are lifted

    np.testing.assert_array_equal(swing_clearance(model, hovering, DT, ShapingConfig()), hovering)
    hover = ShapingConfig(hover_support=0.05)
    np.testing.assert_allclose(swing_clearance(model, hovering, DT, hover) - hovering, lifts, atol=1e-6)
    flying = grounded.copy()
    flying[:, 2] += 0.08
    np.testing.assert_array_equal(swing_clearance(model, flying, DT, hover), flying)


def _foot_lowest(model, qpos: np.ndarray) -> np.ndarray:
    """(N, 2) lowest point of each foot (left, right: ankle and toe bodies) of every frame."""
    import mujoco

    lay = layout(model)
    sides = ("left", "right")
    ids = {s: [int(lay.body_ids[JOINT_INDEX[f"{s}_{j}"]]) for j in ("ankle", "foot")] for s in sides}
    geoms = [np.flatnonzero(np.isin(model.geom_bodyid, ids[s])) for s in sides]
    data = mujoco.MjData(model)
    out = np.zeros((len(qpos), 2))
    for k, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out[k] = [geoms_lowest(model, data, g).min() for g in geoms]
    return out


def test_a_swing_foot_dipped_into_the_floor_is_lifted_and_the_stance_foot_grounded(walk_qpos) -> None:
    """Generated motions often dip the swing foot into the floor; grounding then lifts the whole frame by it
    and the stance foot hangs in the air (the tracker then dragged the swing toe along the floor: Skate).
    Here the real walk's swing feet are pushed 4 cm under the floor in mid-swing."""
    from physmotion.physics.shaping import _Geometry, _move_ankles

    model, qpos = walk_qpos
    walk = to_floor(model, qpos, DT, 1.0)
    geo = _Geometry(model, walk)
    speed = np.linalg.norm(np.gradient(geo.ankles, DT, axis=0), axis=-1)  # (N, 2)
    feet = _foot_lowest(model, walk)
    # Mid-swing: this foot fast and 2 cm up, the other foot still and on the floor.
    swing = (speed > 1.5) & (feet > 0.02) & (feet[:, ::-1] < 0.005) & (speed[:, ::-1] < 0.3)
    frames, sides = np.nonzero(swing)
    assert len(frames) >= 8
    dipped = walk.copy()
    for i, leg in enumerate(geo.legs):
        on = frames[sides == i]
        moves = np.zeros((len(on), 3))
        moves[:, 2] = -feet[on, i] - 0.04  # MuJoCo z is up
        _move_ankles(model, dipped, on, leg, moves)
    config = ShapingConfig()
    fixed = shape_reference(model, dipped, DT, config)
    old = shape_reference(model, dipped, DT, ShapingConfig(stance_by_speed=False))
    stance = np.arange(len(frames)), 1 - sides
    lifted = np.arange(len(frames)), sides
    before, after = _foot_lowest(model, old)[frames], _foot_lowest(model, fixed)[frames]
    mm = {k: 1000 * np.median(v) for k, v in
          (("s0", before[stance]), ("s1", after[stance]), ("w0", before[lifted]), ("w1", after[lifted]))}
    print(f"\nstance foot {mm['s0']:.1f} -> {mm['s1']:.1f} mm, "
          f"swing foot {mm['w0']:.1f} -> {mm['w1']:.1f} mm")
    assert np.median(before[stance]) > 0.035  # without: the stance foot hangs 4 cm up
    assert np.all(after[stance] < 0.006)  # with: it stands on the floor ...
    assert np.all(after[lifted] > 0.02)  # ... and the swing foot is off the floor
    assert _lowest(model, fixed).min() > -1e-9
    # This real walk has no such frames: it is shaped exactly as before.
    np.testing.assert_array_equal(shape_reference(model, qpos, DT, config),
                                  shape_reference(model, qpos, DT, ShapingConfig(stance_by_speed=False)))


def test_toe_off_is_flattened_only_before_flight(mocap_dir) -> None:
    """A Bandai sprint: its flight frames are found from the centre of mass, and only the ankles' y
    hinges change, only within the lead before a flight, where the toe box dug into the floor; what is
    flattened lies no deeper than ``toe_off_depth``. A walk (no flight) is left as it is."""
    from physmotion.io.importer import import_clip, load_manifest
    from physmotion.physics.shaping import flatten_toe_off, flight_frames

    info = {c.clip: c for c in load_manifest(mocap_dir)}["bandai1_dataset-1_dash_proud_001"]
    run = import_clip(info, floor="frame0").joints.astype(np.float64)  # P's input convention
    body = body_from_joints(run)
    model = build_model(body)
    qpos = resample_qpos(joints_to_qpos(run, model, lift=foot_lift(body)), 20.0, 1.0 / DT)
    cfg = ShapingConfig()
    flight = flight_frames(model, qpos, DT, cfg.flight_load)
    assert 0.05 < flight.mean() < 0.6  # a sprint flies in part of its frames
    out = flatten_toe_off(model, qpos, DT, cfg)
    ankles = [model.joint(f"{s}_ankle_y").qposadr[0] for s in ("left", "right")]
    changed = np.abs(out - qpos) > 0
    assert changed.any() and not np.delete(changed, ankles, axis=1).any()
    lead = round(cfg.toe_off_lead / DT)
    near = np.array([flight[k : k + lead + 1].any() for k in range(len(qpos))])
    assert not changed[~near].any()
    assert np.all(out[:, ankles] <= qpos[:, ankles] + 1e-12)  # dorsiflexed only (y: -)
    from physmotion.physics.surface import lowest_of, pose_frames

    for side, adr in zip(("left", "right"), ankles):
        rows = np.flatnonzero(changed[:, adr])
        geoms = np.array([model.geom(f"{side}_foot").id, model.geom(f"{side}_ankle").id])
        _, gpos, gmat = pose_frames(model, qpos[rows])
        toe_before, heel = lowest_of(model, gpos, gmat, geoms).T
        _, gpos, gmat = pose_frames(model, out[rows])
        toe = lowest_of(model, gpos, gmat, geoms[:1])[:, 0]
        assert len(rows) and np.all(toe > toe_before) and toe_before.max() < -cfg.toe_off_depth
        # Lifted to the allowed depth, or to the heel's height where the heel was deeper still.
        assert np.all(toe >= np.minimum(heel, -cfg.toe_off_depth) - 1e-3)


def test_a_walk_has_no_toe_off_to_flatten(walk_qpos) -> None:
    from physmotion.physics.shaping import flatten_toe_off, flight_frames

    model, qpos = walk_qpos
    assert not flight_frames(model, qpos, DT, ShapingConfig().flight_load).any()
    np.testing.assert_array_equal(flatten_toe_off(model, qpos, DT), qpos)


def test_flight_phases_fly_ballistically(mocap_dir) -> None:
    """A Bandai sprint, grounded: in every flight phase the root moves so that the humanoid's centre of
    mass accelerates at -g and not at all horizontally (where no frame had to be raised back out of the
    floor); frames on the floor and every hinge are left as they were."""
    from physmotion.io.importer import import_clip, load_manifest
    from physmotion.physics.shaping import _com_positions, ballistic_flight
    from physmotion.physics.tracking import STANDARD_GRAVITY

    info = {c.clip: c for c in load_manifest(mocap_dir)}["bandai1_dataset-1_dash_proud_001"]
    run = import_clip(info).joints.astype(np.float64)
    body = body_from_joints(run)
    model = build_model(body)
    qpos = to_floor(model, resample_qpos(joints_to_qpos(run, model, lift=foot_lift(body)), 20.0, 1.0 / DT),
                    DT, 1.0)
    support = ShapingConfig().support
    out = ballistic_flight(model, qpos, DT, support, 1.0)
    air = _lowest(model, qpos) > support
    changed = np.abs(out - qpos).max(axis=1) > 0
    assert 0.05 < air.mean() < 0.6 and changed.any()
    assert not changed[~air].any() and np.array_equal(out[:, 3:], qpos[:, 3:])
    assert _lowest(model, out).min() > -1e-9
    com = _com_positions(model, out)
    acc = (com[2:] - 2 * com[1:-1] + com[:-2]) / DT**2  # at frames 1..N-2
    # Inside each flight phase (take-off and landing frames are on the path as they were).
    edges = np.flatnonzero(np.diff(np.r_[0, air.astype(np.int8), 0]))
    inside = [t for s, e in zip(edges[::2], edges[1::2]) if s > 0 and e < len(qpos) for t in range(s, e)]
    raised = np.flatnonzero(air & np.isclose(_lowest(model, out), 0.0, atol=1e-9))  # back out of the floor
    rows = np.array([t for t in inside if not np.isin([t - 1, t, t + 1], raised).any()])
    print(f"\n{len(inside)} flight frames, {len(raised)} raised back out of the floor")
    assert len(rows) >= 5
    free_fall = np.tile([0.0, 0.0, -STANDARD_GRAVITY], (len(rows), 1))
    np.testing.assert_allclose(acc[rows - 1], free_fall, atol=1e-6)


def test_a_hover_is_not_made_ballistic(walk_qpos) -> None:
    """Half a second 10 cm up in the middle of a stand: gravity would take a flight that long 20-30 cm
    high, so the phase moves by more than ``ballistic_max`` and is left as it is; without the bound it is
    moved."""
    from physmotion.physics.shaping import ballistic_flight

    model, qpos = walk_qpos
    stand = np.repeat(to_floor(model, qpos[:1], DT, 0.0), 60, axis=0)
    t = np.arange(60) * DT
    flight = (t > 0.8) & (t < 1.3)
    stand[flight, 2] += 0.1 * np.sin(np.pi * (t[flight] - 0.8) / 0.5)
    cfg = ShapingConfig()
    kept = ballistic_flight(model, stand, DT, cfg.support, 1.0, cfg.ballistic_max)
    np.testing.assert_array_equal(kept, stand)
    flung = ballistic_flight(model, stand, DT, cfg.support, 1.0)
    assert (flung[:, 2] - stand[:, 2]).max() > 0.15


@pytest.fixture(scope="module")
def generated_jump():
    """(model, qpos (N, 70)) the shipped model's plain sample of "a person jumps forward" (seed 0, 6 s) as
    generation's P shapes it, but with its push-off as sampled: its centre of mass rises about 25 cm over a
    flight that leaves the floor at about 1.5 m/s, where such a rise takes about 2.2 m/s (measured)."""
    from dataclasses import replace

    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.physdiff import on_data_floor
    from physmotion.generate import GenerateConfig, generate
    from physmotion.physics.projection import ProjectionConfig, prepare_motion

    sample = generate(["a person jumps forward"], GenerateConfig(seconds=6.0, physics="none", seed=0),
                      model=MotionDiffusion.load()).motions[0].joints  # fmt: skip
    config = ProjectionConfig.sampling()
    config = replace(config, shaping=replace(config.shaping, push_off=False))
    prep = prepare_motion(on_data_floor(sample).astype(np.float64), 20.0, config)
    return prep.model, prep.target


def test_a_slow_take_off_is_played_faster(generated_jump) -> None:
    """``push_off``: only the frames from a crouch to a take-off change; each such window ends on its
    take-off frame as it was, starts on the crouch pose held, and holds the reference's own poses in
    between (every hinge within the range it had there); the body leaves the floor faster than it did, at
    the speed the flight's rise needs or the most the speed-up's bound allows."""
    from physmotion.physics.shaping import _com_heights, _flight_spans, push_off
    from physmotion.physics.tracking import STANDARD_GRAVITY

    model, qpos = generated_jump
    cfg = ShapingConfig(push_off=True)
    out = push_off(model, qpos, DT, cfg)
    changed = np.abs(out - qpos).max(axis=1) > 0
    assert changed.any()
    edges = np.flatnonzero(np.diff(np.r_[0, changed.astype(np.int8), 0]))
    takeoffs = {a: b for a, b in _flight_spans(model, qpos, DT, cfg.support, cfg.float_window)}
    com, com_out = _com_heights(model, qpos), _com_heights(model, out)
    for start, stop in zip(edges[::2], edges[1::2]):  # changed frames start..stop-1
        crouch, a = start - 1, stop  # the crouch frame and the take-off frame are kept as they were
        assert a in takeoffs and np.array_equal(out[a], qpos[a]) and np.array_equal(out[crouch], qpos[crouch])
        window = qpos[crouch : a + 1, 7:]
        assert np.all(out[start:stop, 7:] >= window.min(axis=0) - 1e-9)
        assert np.all(out[start:stop, 7:] <= window.max(axis=0) + 1e-9)
        have, now = (com[a] - com[a - 1]) / DT, (com_out[a] - com_out[a - 1]) / DT
        need = np.sqrt(2 * STANDARD_GRAVITY * (com[a : takeoffs[a] + 1].max() - com[a]))
        print(f"\ntake-off at step {a}: {have:.2f} -> {now:.2f} m/s, the rise needs {need:.2f}")
        # At most: the rise of the last push_off_speedup steps (none before the crouch) in one step.
        most = (com[a] - np.interp(max(a - cfg.push_off_speedup, crouch), np.arange(len(com)), com)) / DT
        # 0.9: the replay is timed on the centre of mass interpolated between frames, not posed.
        assert now > cfg.push_off_margin * have and now >= 0.9 * min(need, most)


def test_a_walk_has_no_push_off(walk_qpos) -> None:
    from physmotion.physics.shaping import push_off

    model, qpos = walk_qpos
    np.testing.assert_array_equal(push_off(model, qpos, DT, ShapingConfig(push_off=True)), qpos)
