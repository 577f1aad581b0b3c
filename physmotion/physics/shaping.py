"""Reference shaping: what the tracker is asked to follow, made from the motion it must imitate.

Corrections of a retargeted reference (qpos at the control rate), each measured on all 203
walking/running clips of the bundled mocap (experiments/projection_quality.py) and on the issue's test
motions (tests/physics/test_projection.py); the figures, and the alternatives measured against them,
are in docs/decisions/projection.md:

- :func:`to_floor` raises a frame whose geometry dips under the floor, since the stiff legs would press
  the feet toward targets under the floor and launch the body; a reference that floats for a second or
  more is first lowered onto the floor (docs/decisions/projection.md: "reference raised out of the floor").
- :func:`swing_clearance` lifts a moving swing foot 3 cm further from the floor while the other foot is
  on it: mocap toes clear the floor by only about 1.5 cm in mid-swing, and a body a few degrees off its
  reference scuffs the floor with them (docs/decisions/projection.md: "swing-foot clearance of a fixed 3 cm").
- :func:`flatten_toe_off` dorsiflexes the ankle where a push-off into a flight phase (a run's stride,
  a jump) digs the rigid toe box into the floor: a human's toes bend there, ours cannot, and raising the
  whole frame instead (``to_floor``) bent the reference's centre of mass into a path that needs the floor
  to pull, which the tracker followed with a launch (docs/decisions/projection.md: "toe-off flattened before
  flight").
- :func:`ballistic_flight` moves the root in each flight phase so that the humanoid's centre of mass flies
  the path gravity allows between take-off and landing: retargeted onto our humanoid's masses, a captured
  flight is not free fall, and the feed-forward asked the root residual for the difference
  (docs/decisions/projection.md: "residual within 0.1 W on walks and runs").
- :func:`push_off` (generation's P only) replays the rise into a flight faster where the flight needs a
  faster take-off than the reference has: a generated jump often goes on rising after its feet leave the
  floor, and the tracker, leaving at the reference's speed, flew lower (docs/decisions/projection.md: "a
  push-off fast enough for the flight").
- Support by speed (``stance_by_speed``): a generated swing foot that dips under the floor makes
  grounding raise the frame, and the slow stance foot then hangs centimetres up; such a swing foot is
  lifted above the stance foot and the frame lowered onto it (docs/decisions/projection.md: "support found by
  speed").

MPJPE and the metrics are always measured against the unshaped input.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physmotion.physics.humanoid import layout
from physmotion.physics.retarget import qpos_at
from physmotion.physics.surface import body_lowest, lowest_of, pose_frames
from physmotion.physics.tracking import STANDARD_GRAVITY
from physmotion.skeleton import JOINT_INDEX

_IK_STEPS = 4  # most Gauss-Newton steps of swing_clearance's leg IK


@dataclass(frozen=True)
class ShapingConfig:
    """How :func:`shape_reference` corrects a reference (metres, seconds, m/s)."""

    ground: bool = True  # raise frames out of the floor (to_floor)
    float_window: float = 1.0  # lower a reference that does not touch the floor for this long; 0: never
    clearance: float = 0.03  # lift a swing foot by this much; 0: off
    clearance_speed: float = 0.5  # no lift below this horizontal foot speed, the full lift from twice it
    support: float = 0.02  # the other foot counts as on the floor within this height
    # > 0: in a frame whose lowest point hovers less than this over the floor, ``support`` is measured from
    # that point, so a generated stance foot hovering a few centimetres up still lets the swing foot be
    # lifted (P puts the body down on it anyway). 0.05 in generation's preset
    # (``ProjectionConfig.sampling``); off here, for captured motion (docs/decisions/sampling.md: "support
    # judged against a hovering frame in the sampling preset").
    hover_support: float = 0.0  # m
    # A fast foot on the floor under a slow foot in the air is a swing foot that dipped into the floor
    # (grounding then lifted the frame by it): lift it above the slow foot and lower the frame onto that.
    stance_by_speed: bool = True
    # flatten_toe_off: dorsiflex the ankle where the toe box dips more than ``toe_off_depth`` under the
    # floor and under its heel, in the ``toe_off_lead`` seconds before a flight phase: a frame where the
    # reference's centre of mass falls faster than (1 - ``flight_load``) g, i.e. the feet would carry less
    # than that share of W. Flattened fully (depth 0) the simulated runner pushed off too little, landed
    # early and skidded (docs/decisions/projection.md: "toe-off flattened before flight").
    flatten_toe_off: bool = True
    toe_off_lead: float = 0.2  # s
    flight_load: float = 0.3  # fraction of W
    toe_off_depth: float = 0.005  # m
    # ballistic_flight: in each flight phase of the shaped reference (no geom within ``support`` of the
    # floor, shorter than ``float_window``), move the root so that the humanoid's centre of mass flies
    # the path gravity allows between take-off and landing, unless that moves it by more than
    # ``ballistic_max`` (a hover, a step onto something: not a flight the tracker can make ballistic).
    ballistic_flight: bool = True
    ballistic_max: float = 0.05  # m
    # push_off: before each such flight phase whose centre of mass rises more than its take-off speed
    # carries it (sqrt(2 g rise) over ``push_off_margin`` x that speed, and within ``push_off_speedup`` x),
    # play the rise into take-off (from the crouch's lowest centre of mass, at most ``push_off_lead`` s
    # back) up to ``push_off_speedup`` x faster, holding the crouch for the time freed, so that the body
    # leaves the floor at the speed its flight needs (docs/decisions/projection.md: "a push-off fast enough
    # for the flight").
    push_off: bool = False
    # m: a flight whose centre of mass rises less is a stride or a hover (a generated walk's frames that
    # float a few centimetres for 0.1 s: rises of 2.5-3 cm), not a jump, and keeps its pace
    push_off_rise: float = 0.05
    push_off_speedup: float = 2.0
    push_off_lead: float = 0.5  # s
    push_off_margin: float = 1.1


def shape_reference(model, qpos: np.ndarray, dt: float, config: ShapingConfig | None = None) -> np.ndarray:
    """The reference qpos (N, 70) at step ``dt`` corrected as ``config`` says (a new array)."""
    cfg = config or ShapingConfig()
    out = flatten_toe_off(model, qpos, dt, cfg) if cfg.flatten_toe_off else qpos.copy()
    geo = _Geometry(model, out)  # one kinematics pass serves both corrections
    shift = _floor_shift(geo.lowest, dt, cfg.float_window) if cfg.ground else np.zeros(len(qpos))
    out[:, 2] += shift
    geo.lowest += shift  # a vertical shift moves every height by as much
    geo.feet += shift[:, None]
    if cfg.clearance > 0.0:
        _lift_swing_feet(model, out, geo, dt, cfg)
    if cfg.push_off:
        out = push_off(model, out, dt, cfg)
    if cfg.ballistic_flight:
        out = ballistic_flight(model, out, dt, cfg.support, cfg.float_window, cfg.ballistic_max)
    return out


def ballistic_flight(
    model, qpos: np.ndarray, dt: float, support: float, longest: float, max_shift: float = np.inf
) -> np.ndarray:
    """qpos (N, 70) at step ``dt`` with the root moved in each flight phase so that the centre of mass
    follows a ballistic path (a new array).

    A flight phase is a run of frames with no geom within ``support`` of the floor, between a last
    frame on the floor (take-off) and a first one back (landing), at most ``longest`` seconds apart.
    In it the centre of mass is put on the one path gravity allows between those two frames: linear
    horizontally, a parabola of -g vertically. The retargeted humanoid's mass is spread unlike the
    captured person's, so its centre of mass, as retargeted, does not fly free; the tracker's
    feed-forward then asked the root residual for the difference (0.1-0.2 W through a run's flights).
    A phase whose root would move by more than ``max_shift`` metres is left as it is: captured runs and
    jumps move by up to 4 and 5 cm, while a generated jump that hovers for half a second would be flung
    a metre up. Frames the move puts into the floor are raised back out of it.
    """
    out = qpos.copy()
    spans = _flight_spans(model, qpos, dt, support, longest)
    if not spans:
        return out
    com = _com_positions(model, qpos)
    moved = []
    for a, b in spans:
        t = np.arange(a + 1, b)
        s = ((t - a) / (b - a))[:, None]
        path = (1 - s) * com[a] + s * com[b]
        path[:, 2] += 0.5 * STANDARD_GRAVITY * ((t - a) * dt) * ((b - t) * dt)
        shift = path - com[t]
        if np.linalg.norm(shift, axis=1).max() <= max_shift:
            out[t, :3] += shift
            moved.append(t)
    if moved:
        rows = np.concatenate(moved)
        out[rows, 2] -= np.minimum(_lowest(model, out[rows]), 0.0)
    return out


def push_off(model, qpos: np.ndarray, dt: float, config: ShapingConfig) -> np.ndarray:
    """qpos (N, 70) at step ``dt`` with the rise into each flight phase played faster where the flight
    needs a faster take-off (a new array; ``ShapingConfig.push_off``).

    A flight phase is as in :func:`ballistic_flight`, from its take-off frame a. Its centre of mass rises
    ``rise`` above a's (at least ``push_off_rise``: a jump), which takes a vertical speed of sqrt(2 g rise)
    at a. Where the reference leaves the floor slower than that by more than ``push_off_margin``, but no
    slower than 1 / ``push_off_speedup`` of it (a body that rises with hardly any push-off floats, and a
    faster replay only disturbs the body before it), the frames from the crouch (the lowest centre of
    mass within ``push_off_lead`` s before a) to a are replayed faster, at most ``push_off_speedup`` x, so
    that the last step before a rises at that speed; the crouch pose is held for the time freed.
    Every pose is one of the reference's own, so feet that stand stay where they stood. A generated jump
    often goes on rising for a few frames after its feet have left the floor, which no body can do; its
    tracker left the floor at the reference's speed and flew lower (docs/decisions/projection.md: "a
    push-off fast enough for the flight").
    """
    out = qpos.copy()
    spans = _flight_spans(model, qpos, dt, config.support, config.float_window)
    if not spans:
        return out
    com = _com_heights(model, qpos)
    lead = int(round(config.push_off_lead / dt))
    for a, b in spans:
        rise = com[a : b + 1].max() - com[a]
        have = (com[a] - com[a - 1]) / dt if a > 0 else 0.0
        need = np.sqrt(2.0 * STANDARD_GRAVITY * max(rise, 0.0))
        slow = config.push_off_margin * have < need <= config.push_off_speedup * have
        if rise < config.push_off_rise or not slow:  # no jump; fast enough; or a float no replay could launch
            continue
        crouch = a
        while crouch > max(a - lead, 0) and com[crouch] > com[crouch - 1]:
            crouch -= 1
        if a - crouch < 2:  # no rise to replay
            continue
        # The frame before take-off becomes the pose where the rise was need x dt under take-off's height,
        # so that the last step leaves at that speed: 1 / pace source frames per frame (at most the bound).
        before = np.interp(com[a] - need * dt, com[crouch : a + 1], np.arange(crouch, a + 1))
        pace = max(1.0 / (a - before), 1.0 / config.push_off_speedup)
        frames = np.arange(crouch + 1, a, dtype=np.float64)  # the crouch and the take-off stay as they are
        out[crouch + 1 : a] = qpos_at(qpos, np.maximum(a - (a - frames) / pace, crouch))
    return out


def flights(model, qpos: np.ndarray, dt: float, support: float,
            longest: float) -> list[tuple[int, int, float]]:  # fmt: skip
    """The flight phases of qpos (N, 70) at step ``dt`` (as :func:`ballistic_flight` finds them): for each,
    its take-off frame, the frame where the body's lowest point is highest, and that height (m)."""
    low = _lowest(model, qpos)
    spans = _flight_spans(model, qpos, dt, support, longest, low)
    tops = [a + 1 + int(np.argmax(low[a + 1 : b])) for a, b in spans]
    return [(a, top, float(low[top])) for (a, _), top in zip(spans, tops)]


def _flight_spans(model, qpos: np.ndarray, dt: float, support: float, longest: float,
                  low: np.ndarray | None = None) -> list[tuple[int, int]]:  # fmt: skip
    """Flight phases of qpos (N, 70) at step ``dt``: (take-off frame, landing frame) pairs around each run
    of frames with no geom within ``support`` of the floor, at most ``longest`` seconds from one to the
    other, with a frame on the floor at both ends. low: (N,) the frames' lowest points, if known already."""
    air = (_lowest(model, qpos) if low is None else low) > support
    edges = np.flatnonzero(np.diff(np.r_[0, air.astype(np.int8), 0]))
    spans = [(s - 1, e) for s, e in zip(edges[::2], edges[1::2]) if s > 0 and e < len(qpos)]
    return [(a, b) for a, b in spans if (b - a) * dt <= longest]


def to_floor(model, qpos: np.ndarray, dt: float, float_window: float) -> np.ndarray:
    """qpos (N, 70) at step ``dt`` with each frame raised (never lowered) so that no geom is under the
    floor, after the whole reference has been lowered wherever it floated for ``float_window`` seconds.

    A motion that does not touch the floor at any instant within ``float_window`` (centred on a frame)
    is taken to float, not to jump: a jump's flight lasts well under a second. It is lowered by the
    least height it keeps over that window (a running minimum, smoothed over 0.1 s), so that it stands
    on the floor: tracked floating, the body hops as the root PD pulls it up toward the reference
    (docs/decisions/projection.md: "reference raised out of the floor"). 0: never lowered.
    """
    out = qpos.copy()
    out[:, 2] += _floor_shift(_Geometry(model, qpos).lowest, dt, float_window)
    return out


def swing_clearance(model, qpos: np.ndarray, dt: float, config: ShapingConfig) -> np.ndarray:
    """qpos (N, 70) at step ``dt`` with each swing foot raised by ``clearance`` metres while the other
    foot is within ``support`` of the floor (of the frame's lowest point where it hovers less than
    ``hover_support`` over the floor), scaled from 0 at a horizontal ankle speed of
    ``clearance_speed`` to 1 at twice that. A foot that stands still is left alone, so footholds do not
    move; a foot that slides along the floor in the reference is lifted like any other moving foot.

    With ``stance_by_speed``, a moving foot within ``support`` of the floor while the other foot stands
    still (slower than ``clearance_speed``) above it is a swing foot under its stance foot: it is raised
    to the other foot's height plus the clearance (scaled the same way), and the frame is lowered by
    what that raised its lowest point, so the stance foot stands on the floor (:func:`_lower_onto_stance`).

    The foot keeps its orientation and horizontal position: damped least-squares steps on the leg's
    nine hinges (hip, knee, ankle) for the ankle body's pose (:func:`_move_ankles`).
    """
    out = qpos.copy()
    _lift_swing_feet(model, out, _Geometry(model, qpos), dt, config)
    return out


_ANKLE_STEPS = -np.linspace(0.05, 1.0, 20)  # rad: candidate dorsiflexions, smallest first


def flatten_toe_off(model, qpos: np.ndarray, dt: float, config: ShapingConfig | None = None) -> np.ndarray:
    """qpos (N, 70) at step ``dt`` with the ankles dorsiflexed at push-offs into flight (a new array).

    A frame is flattened on one side when it lies within ``toe_off_lead`` seconds before a flight frame
    (:func:`flight_frames`) and that foot's toe box dips more than ``toe_off_depth`` under the floor and
    lower than its heel (ankle) box: the ankle's y hinge turns by the smallest of 20 steps up to 1 rad
    (within its limit) that lifts the toe box to that depth or to the heel's height, whichever is lower.
    """
    cfg = config or ShapingConfig()
    out = qpos.copy()
    flight = flight_frames(model, qpos, dt, cfg.flight_load)
    lead = max(int(round(cfg.toe_off_lead / dt)), 0)
    gate = flight.copy()
    for s in range(1, lead + 1):
        gate[:-s] |= flight[s:]
    if not gate.any():
        return out
    for side in ("left", "right"):
        geoms = np.array([model.geom(f"{side}_foot").id, model.geom(f"{side}_ankle").id])
        hinge = model.joint(f"{side}_ankle_y")
        adr, (lo, hi) = int(hinge.qposadr[0]), model.jnt_range[hinge.id]
        _, gpos, gmat = pose_frames(model, out)
        toe, heel = lowest_of(model, gpos, gmat, geoms).T
        frames = np.flatnonzero(gate & (toe < -cfg.toe_off_depth) & (toe < heel))
        if not len(frames):
            continue
        target = np.minimum(heel[frames], -cfg.toe_off_depth) - 1e-4
        turn = np.zeros(len(frames))
        todo = np.ones(len(frames), dtype=bool)
        for step in _ANKLE_STEPS:
            q = out[frames[todo]]
            q[:, adr] = np.clip(q[:, adr] + step, lo, hi)
            _, gpos, gmat = pose_frames(model, q)
            done = lowest_of(model, gpos, gmat, geoms[:1])[:, 0] >= target[todo]
            idx = np.flatnonzero(todo)[done]
            turn[idx], todo[idx] = step, False
            if not todo.any():
                break
        out[frames, adr] = np.clip(out[frames, adr] + turn, lo, hi)  # frames never lifted keep turn 0
    return out


def flight_frames(model, qpos: np.ndarray, dt: float, load: float) -> np.ndarray:
    """(N,) bool: frames of qpos (N, 70) at step ``dt`` whose centre of mass accelerates downward by more
    than (1 - load) g, so that the feet could carry less than ``load`` of the body weight."""
    if len(qpos) < 3:
        return np.zeros(len(qpos), dtype=bool)
    height = _com_heights(model, qpos)
    support = 1.0 + np.gradient(np.gradient(height, dt), dt) / STANDARD_GRAVITY
    return support < load


def _com_heights(model, qpos: np.ndarray) -> np.ndarray:
    """(N,) height (MuJoCo z) of the whole body's centre of mass in each frame of qpos (N, 70)."""
    return _com_positions(model, qpos)[:, 2]


def _com_positions(model, qpos: np.ndarray) -> np.ndarray:
    """(N, 3) whole-body centre of mass (MuJoCo world frame) in each frame of qpos (N, 70)."""
    import mujoco

    data = mujoco.MjData(model)
    mass = model.body_mass[1:]
    out = np.empty((len(qpos), 3))
    for k in range(len(qpos)):
        data.qpos[:] = qpos[k]
        mujoco.mj_kinematics(model, data)
        out[k] = mass @ data.xipos[1:] / mass.sum()
    return out


def _floor_shift(lowest: np.ndarray, dt: float, float_window: float) -> np.ndarray:
    """Vertical shift (N,) of each frame for :func:`to_floor`, from its lowest point (N,)."""
    from scipy.ndimage import gaussian_filter1d, minimum_filter1d

    drop = np.zeros_like(lowest)
    if float_window > 0.0:
        width = 2 * round(float_window / dt / 2) + 1  # odd, so the window is centred
        drop = np.maximum(minimum_filter1d(lowest, size=width, mode="nearest"), 0.0)
        drop = gaussian_filter1d(drop, 0.1 / dt, mode="nearest")
    return -drop + np.maximum(drop - lowest, 0.0)  # down where it floated, then up out of the floor


class _Geometry:
    """Per-frame geometry of a reference: lowest (N,) point of the body, feet (N, 2) lowest point of
    each foot (left, right), ankles (N, 2, 2) horizontal position of each ankle body; legs: the two
    :class:`_Leg`."""

    def __init__(self, model, qpos: np.ndarray) -> None:
        lay = layout(model)
        self.legs = [_Leg(model, lay, side) for side in ("left", "right")]
        xpos, gpos, gmat = pose_frames(model, qpos)
        self.lowest = body_lowest(model, gpos, gmat)
        feet = [lowest_of(model, gpos, gmat, leg.geoms).min(axis=-1) for leg in self.legs]
        self.feet = np.stack(feet, axis=-1)
        self.ankles = xpos[:, [leg.ankle for leg in self.legs], :2]


def _lift_swing_feet(model, qpos: np.ndarray, geo: _Geometry, dt: float, config: ShapingConfig) -> None:
    """:func:`swing_clearance` in place on ``qpos``, whose geometry (heights up to date) is ``geo``; the
    frames whose support was found by speed are then lowered onto it (:func:`_lower_onto_stance`)."""
    moved = np.gradient(geo.ankles, dt, axis=0) if len(qpos) > 1 else np.zeros_like(geo.ankles)
    speed = np.linalg.norm(moved, axis=-1)  # (N, 2)
    weight = np.clip(speed / config.clearance_speed - 1.0, 0.0, 1.0)
    lifts = config.clearance * weight
    # Where the frame hovers (0 <= lowest < hover_support) support is measured from its lowest point; with
    # hover_support 0 no frame qualifies and the floor (0) is used.
    floor = np.where(geo.lowest < config.hover_support, np.maximum(geo.lowest, 0.0), 0.0)
    other_up = geo.feet[:, ::-1] > floor[:, None] + config.support
    swapped = np.zeros_like(other_up)
    if config.stance_by_speed:
        # This foot moves and is on the floor; the other stands still above it: the other is the stance.
        swapped = other_up & (geo.feet <= config.support) & (speed[:, ::-1] < config.clearance_speed)
        lifts += np.where(swapped, weight * (geo.feet[:, ::-1] - geo.feet), 0.0)
    lifts[other_up & ~swapped] = 0.0  # the other foot is off the floor too
    for i, leg in enumerate(geo.legs):
        frames = np.flatnonzero(lifts[:, i] > 0.0)
        moves = np.zeros((len(frames), 3))
        moves[:, 2] = lifts[frames, i]  # MuJoCo z is up
        _move_ankles(model, qpos, frames, leg, moves)
    lowered = (swapped & (lifts > 0.0)).any(axis=1)
    if lowered.any():
        _lower_onto_stance(model, qpos, lowered, geo.lowest, dt)


def _move_ankles(model, qpos: np.ndarray, frames: np.ndarray, leg: _Leg, moves: np.ndarray) -> None:
    """Move the ankle body of ``leg`` by ``moves`` (F, 3) (MuJoCo world frame) in the ``frames`` (F,) of
    ``qpos`` (N, 70), in place, keeping its orientation: damped least-squares steps on the leg's nine
    hinges (hip, knee, ankle), every frame on its own but the linear algebra of all frames at once.
    Near a straight knee the map is far from linear: on a real walk three steps missed a 3 cm lift by up
    to 1 mm, four land within 0.1 mm; a frame stops once it is within 0.1 mm and 0.006 degrees."""
    import mujoco

    frames = np.asarray(frames)
    if not len(frames):
        return
    data = mujoco.MjData(model)
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    q = qpos[frames].copy()
    f = len(frames)
    pos, quat, rot, jac = np.zeros((f, 3)), np.zeros((f, 4)), np.zeros((f, 3, 3)), np.zeros((f, 6, 9))

    def pose(which: np.ndarray) -> None:
        """Ankle pose and Jacobian (world frame) of the frames ``which`` in their current ``q``."""
        for m in which:
            data.qpos[:] = q[m]
            mujoco.mj_kinematics(model, data)
            pos[m], quat[m] = data.xpos[leg.ankle], data.xquat[leg.ankle]
            rot[m] = data.xmat[leg.ankle].reshape(3, 3)
            mujoco.mj_comPos(model, data)  # the Jacobian needs the com-based frames
            mujoco.mj_jacBody(model, data, jacp, jacr, leg.ankle)
            jac[m, :3], jac[m, 3:] = jacp[:, leg.dofs], jacr[:, leg.dofs]

    active = np.arange(f)
    pose(active)
    goal_pos, goal_quat = pos + moves, quat.copy()
    err = np.zeros((f, 6))
    for step in range(_IK_STEPS):
        if step:
            pose(active)  # the frames still moving, after the last step
        err[active, :3] = goal_pos[active] - pos[active]
        for m in active:
            mujoco.mju_subQuat(err[m, 3:], goal_quat[m], quat[m])  # local rotation vector
        active = active[np.abs(err[active]).max(axis=1) >= 1e-4]
        if not len(active):
            break
        e = err[active].copy()
        e[:, 3:] = np.einsum("fij,fj->fi", rot[active], e[:, 3:])  # to the world frame, as the Jacobian
        j = jac[active]
        step = np.linalg.solve(j @ j.transpose(0, 2, 1) + 1e-4 * np.eye(6), e[..., None])
        q[np.ix_(active, leg.qpos)] += (j.transpose(0, 2, 1) @ step)[..., 0]
    qpos[frames[:, None], leg.qpos] = q[:, leg.qpos]


def _lower_onto_stance(model, qpos: np.ndarray, frames: np.ndarray, before: np.ndarray, dt: float) -> None:
    """Lower the ``frames`` (N,) bool of ``qpos`` (N, 70) in place by what lifting their swing foot raised
    their lowest point above ``before`` (N,) (the frame's lowest point before the lift, floor at 0), so
    that the stance foot stands on the floor. The drop is widened by 0.1 s either side and smoothed, so
    the root does not jump; frames it pushes into the floor are raised back out."""
    from scipy.ndimage import gaussian_filter1d, maximum_filter1d

    idx = np.flatnonzero(frames)
    drop = np.zeros(len(qpos))
    drop[idx] = np.maximum(_lowest(model, qpos[idx]) - np.maximum(before[idx], 0.0), 0.0)
    width = 2 * round(0.1 / dt) + 1
    drop = gaussian_filter1d(maximum_filter1d(drop, size=width, mode="nearest"), 0.05 / dt, mode="nearest")
    qpos[:, 2] -= drop
    moved = np.flatnonzero(drop > 0.0)
    qpos[moved, 2] -= np.minimum(_lowest(model, qpos[moved]), 0.0)


def _lowest(model, qpos: np.ndarray) -> np.ndarray:
    """(N,) height of the lowest geom point (floor excluded) of each frame of qpos (N, 70)."""
    _, gpos, gmat = pose_frames(model, qpos)
    return body_lowest(model, gpos, gmat)


class _Leg:
    """Where one leg lives in the model: its hinges from hip to ankle, the ankle body, the foot geoms."""

    def __init__(self, model, lay, side: str) -> None:
        joints = [JOINT_INDEX[f"{side}_{name}"] for name in ("hip", "knee", "ankle")]
        self.dofs = lay.hinge_dof[joints].ravel()
        self.qpos = lay.hinge_qpos[joints].ravel()
        self.ankle = int(lay.body_ids[JOINT_INDEX[f"{side}_ankle"]])
        foot = int(lay.body_ids[JOINT_INDEX[f"{side}_foot"]])
        self.geoms = np.flatnonzero(np.isin(model.geom_bodyid, [self.ankle, foot]))
