"""The simulation core: run a controller along a reference, one episode at a time.

One closed-loop episode is a Python loop over control steps (30 Hz) of ``substeps`` ``mj_step`` calls
(360 Hz in the projection), on its own ``MjData``. A batch of motions is the projection's business: it
runs each motion whole in a worker process (:mod:`physmotion.physics.workers`), since the controller's
Python holds the GIL. ``mujoco.rollout`` cannot be used: it steps a fixed, open-loop control sequence,
and this controller is closed-loop (the root residual's PD reads the simulated state at every step);
docs/decisions/projection.md: "worker processes for a batch of motions". ``experiments/physics_speed.py`` compares raw
stepping with the projection.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from physmotion.physics.humanoid import HumanoidConfig, layout
from physmotion.physics.surface import body_lowest, lowest_point, pose_frames
from physmotion.physics.tracking import STANDARD_GRAVITY, Controller, Reference
from physmotion.skeleton import FOOT_JOINTS


@dataclass
class Rollout:
    """What one episode produced, at control steps 0..N-1 (step 0 is the reset state).

    qpos: (N, 70); mpjpe: (N,) metres, mean distance of the 22 bodies to the reference;
    residual_force, residual_torque: (N,) root residual used, fractions of W and W x 1 m (0 at step 0);
    contacts: (N, 4) bool, left ankle, left foot, right ankle, right foot touching the floor;
    failed_at: first control step whose MPJPE exceeded the failure threshold, or None (with
    ``reset_on_fail`` and ``follow_drift``: the first step that needed a reset).
    resets: how many times the humanoid was put back on the reference (``reset_on_fail``).
    shifts: how many times the rest of the reference was moved to where the body had drifted
    (``follow_drift``) or let land (``let_land``).
    over_limit: (N,) bool, control steps in which a hinge's actuator force plus the joint torque applied
    directly (``qfrc_applied``: the tracker's feet-balance path) passed the actuator's force limit.
    residual_force_peak, residual_torque_peak: (N,) the largest root residual of any residual update within
    the step (the step's mean averages a peak away), fractions of W and W x 1 m.
    at_cap: (N,) bool, steps in which some residual update was held at one of the controller's caps
    (force, lift or torque: :meth:`~physmotion.physics.tracking.Controller.caps`).
    reset_steps: (N,) bool, steps at which the humanoid was put back on the reference (``reset_on_fail``).
    recovered: how many stretches another controller carried in place of a reset or re-did where a take-off
    fell short (``simulate``'s ``recover`` and ``flights``); recovered_steps: (N,) bool, the steps it
    simulated (each from the state before it), with no outside hand.
    """

    qpos: np.ndarray
    mpjpe: np.ndarray
    residual_force: np.ndarray
    residual_torque: np.ndarray
    contacts: np.ndarray
    failed_at: int | None
    resets: int = 0
    shifts: int = 0
    over_limit: np.ndarray | None = None  # (N,) bool: a hinge's total torque passed its actuator's limit
    residual_force_peak: np.ndarray | None = None  # (N,) None: as the means (no residual)
    residual_torque_peak: np.ndarray | None = None
    at_cap: np.ndarray | None = None  # (N,) bool; None: never (no residual)
    reset_steps: np.ndarray | None = None  # (N,) bool; None: no reset
    recovered: int = 0
    recovered_steps: np.ndarray | None = None  # (N,) bool; None: none

    def __post_init__(self) -> None:
        n = len(self.qpos)
        if self.residual_force_peak is None:
            self.residual_force_peak = np.asarray(self.residual_force).copy()
        if self.residual_torque_peak is None:
            self.residual_torque_peak = np.asarray(self.residual_torque).copy()
        if self.at_cap is None:
            self.at_cap = np.zeros(n, dtype=bool)
        if self.reset_steps is None:
            self.reset_steps = np.zeros(n, dtype=bool)
        if self.recovered_steps is None:
            self.recovered_steps = np.zeros(n, dtype=bool)


class StepHelp(NamedTuple):
    """The outside help over one control step (:func:`control_step`): the root residual's mean and peak
    over the step's residual updates (fractions of W, W x 1 m), whether a hinge's total torque passed its
    actuator's limit, and whether some update was held at one of the controller's caps."""

    force: float
    torque: float
    over_limit: bool
    force_peak: float
    torque_peak: float
    at_cap: bool


def _quiet_mujoco_warnings() -> None:
    """Route MuJoCo's C warnings (printed to stdout and MUJOCO_LOG.TXT by default) to Python's logging.

    A diverging step ("Nan, Inf or huge value in QACC") is expected on badly broken input motions: MuJoCo
    then resets the state, the tracking error jumps past the failure threshold, and the episode reports
    it. A line on the user's terminal (and a log file in their working directory) would only confuse.
    """
    import logging

    import mujoco

    log = logging.getLogger("physmotion.physics")
    mujoco.set_mju_user_warning(lambda msg: log.debug("mujoco: %s", msg))


def reset_state(model, data, ref: Reference, frame: int = 0) -> None:
    """Put the humanoid on a reference frame (the first by default), lifted out of the floor if it starts
    inside it."""
    import mujoco

    mujoco.mj_resetData(model, data)
    data.qpos[:] = ref.qpos[frame]
    data.qvel[:] = ref.qvel[frame]
    mujoco.mj_kinematics(model, data)
    low = lowest_point(model, data)
    if low < 0.0:
        data.qpos[2] -= low
    mujoco.mj_forward(model, data)


@dataclass
class Recovery:
    """Control steps ``start`` .. ``start`` + len(qpos) - 1 carried by another controller with no outside
    hand, in place of a reset (``simulate``'s ``recover``): qpos (M, nq), qvel (M, nv), mpjpe (M,) metres to
    the reference, contacts (M, 4) bool, as :class:`Rollout` holds them."""

    start: int
    qpos: np.ndarray
    qvel: np.ndarray
    mpjpe: np.ndarray
    contacts: np.ndarray


# recover(ref, states (k + 1, nq + nv) of steps 0..k, k, earliest start, accept) -> a Recovery ending after
# k, or None; accept (None: any): whether a stretch that did not fall is good enough to keep
Recover = Callable[[Reference, np.ndarray, int, int, "Callable[[Recovery], bool] | None"], "Recovery | None"]


class FlightCheck(NamedTuple):
    """A flight of the reference that ``simulate`` checks the body makes: its take-off step, the step at which
    the simulation's flight so far is judged (just past the reference's highest), and the reference body's
    clearance over the floor at its highest (m)."""

    takeoff: int
    check: int
    height: float


def simulate(
    model,
    ref: Reference,
    controller: Controller,
    config: HumanoidConfig | None = None,
    fail_mpjpe: float = 0.5,
    reset_on_fail: bool = False,
    follow_drift: bool = False,
    let_land: bool = False,
    recover: Recover | None = None,
    flights: Sequence[FlightCheck] = (),
    flight_kept: float = 0.8,
) -> Rollout:
    """Run ``controller`` along ``ref`` (at the control rate of ``config``) from the reference's start.

    The episode ends early when the MPJPE to the reference exceeds ``fail_mpjpe`` (Morph's 0.5 m);
    the remaining steps then repeat the last state and ``failed_at`` is set. With ``reset_on_fail`` the
    humanoid is instead put back on the reference at that step and the episode goes on (the usual
    practice when evaluating imitation policies, e.g. PHC); ``resets`` counts how often. With
    ``follow_drift`` as well, a body whose pose is still within ``fail_mpjpe`` once its horizontal
    offset from the reference is taken out has only drifted (on generated motions whose feet slide, it
    lags behind): the rest of the reference is moved to it instead, and nothing jumps. With ``let_land``
    too, a body *below* the reference whose pose is within ``fail_mpjpe`` once its whole offset is taken
    out has fallen short of a flight (a jump's push came up short): the horizontal offset is followed as
    above and the body lands, where a reset would lift it into the air. With ``recover`` too, a step that
    would be reset is first handed to it: given the states so far, it may carry the body from an earlier
    step to a later one (the search with no outside hand), and the episode goes on from there; a stretch
    it returned is not handed to it again, and where it returns None the reset happens as before
    (``recovered`` counts the stretches, ``recovered_steps`` marks them). A stretch it carried to the last
    step is kept whatever its error there. With ``recover`` and ``flights``, a flight whose body has cleared
    the floor by less than ``flight_kept`` x the reference's at the check step is handed to it too, and what
    it returns is kept where the body flies higher in it (a take-off the tracker left too slowly, with no
    reset to trigger it: docs/decisions/projection.md, "the search where a take-off falls short").
    """
    import mujoco

    cfg = config or HumanoidConfig()
    _quiet_mujoco_warnings()
    data = mujoco.MjData(model)
    lay = layout(model)
    foot_bodies = lay.body_ids[list(FOOT_JOINTS)]  # (4,) in the order of Rollout.contacts
    n = len(ref.qpos)
    qpos = np.zeros((n, model.nq))
    states = np.zeros((n, model.nq + model.nv)) if recover is not None else None
    mpjpe = np.zeros(n)
    res_f, res_t = np.zeros(n), np.zeros(n)
    peak_f, peak_t = np.zeros(n), np.zeros(n)
    over, at_cap, reset_steps = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    recovered_steps = np.zeros(n, dtype=bool)
    contacts = np.zeros((n, 4), dtype=bool)
    weight = float(model.body_subtreemass[0]) * STANDARD_GRAVITY
    reset_state(model, data, ref)
    failed_at, resets, shifts, recovered = None, 0, 0, 0
    earliest = 0  # the first step a recovery may start from: none goes back over an earlier one
    checks = {f.check: f for f in flights if recover is not None and 0 < f.takeoff < f.check < n}
    watch = np.zeros(n, dtype=bool)  # steps whose lowest point a flight check reads
    for f in checks.values():
        watch[f.takeoff : f.check + 1] = True
    low = np.full(n, -np.inf)

    def take(got: Recovery) -> int:
        """Keep the recovered stretch in the rollout and put ``data`` at its end; returns that step."""
        s, e = got.start, got.start + len(got.qpos) - 1
        qpos[s : e + 1], mpjpe[s : e + 1], contacts[s : e + 1] = got.qpos, got.mpjpe, got.contacts
        for a in (res_f, res_t, peak_f, peak_t):
            a[s + 1 : e + 1] = 0.0  # no outside hand while it carries the body
        over[s + 1 : e + 1] = at_cap[s + 1 : e + 1] = False
        recovered_steps[s + 1 : e + 1] = True  # the steps it simulated, from the state at s
        data.qpos[:], data.qvel[:] = got.qpos[-1], got.qvel[-1]
        mujoco.mj_forward(model, data)
        return e

    k = 0
    while True:
        qpos[k] = data.qpos
        mpjpe[k] = mpjpe_of(data, lay, ref.joints_mj[k])
        offset = None
        if mpjpe[k] > fail_mpjpe and reset_on_fail and follow_drift:
            offset = _drift(data, lay, ref, k, fail_mpjpe, let_land)
            if offset is not None:  # the copy of the reference is made only now
                ref = ref.shifted(k, offset, cfg.substeps)
                mpjpe[k] = mpjpe_of(data, lay, ref.joints_mj[k])
                shifts += 1
        contacts[k] = contacts_of(model, data, foot_bodies)
        if states is not None:
            states[k] = np.concatenate([data.qpos, data.qvel])
        if watch[k]:
            low[k] = lowest_point(model, data)
        flight = checks.get(k)
        if flight is not None and flight.takeoff > earliest and not recovered_steps[k]:
            kept = float(low[flight.takeoff : k + 1].max())
            if kept < flight_kept * flight.height:
                got = recover(ref, states[: k + 1], k, earliest, lambda r: _clearance(model, r.qpos) > kept)
                if got is not None:
                    recovered += 1
                    k = earliest = take(got)
                    continue
        # A stretch the recovery carried to the last step stands: its controller judges a fall, not the error.
        carried_to_end = k == n - 1 and recovered_steps[k]
        if mpjpe[k] > fail_mpjpe and reset_on_fail and offset is None and not carried_to_end:
            # A body handed back still off the motion goes on with the search from where it was handed back.
            again = recover is not None and (k > earliest or recovered_steps[k])
            got = recover(ref, states[: k + 1], k, earliest, None) if again else None
            if got is not None:
                recovered += 1
                k = earliest = take(got)
                continue
            failed_at = k if failed_at is None else failed_at
            resets += 1
            reset_steps[k] = True
            reset_state(model, data, ref, k)
            qpos[k] = data.qpos
            mpjpe[k] = mpjpe_of(data, lay, ref.joints_mj[k])
            earliest = k
            if states is not None:
                states[k] = np.concatenate([data.qpos, data.qvel])
        elif mpjpe[k] > fail_mpjpe and not reset_on_fail:
            failed_at = k
            qpos[k:] = data.qpos
            mpjpe[k:] = mpjpe[k]
            break
        if k == n - 1:
            break
        step = control_step(model, data, ref, controller, k, cfg, weight)
        res_f[k + 1], res_t[k + 1], over[k + 1] = step.force, step.torque, step.over_limit
        peak_f[k + 1], peak_t[k + 1], at_cap[k + 1] = step.force_peak, step.torque_peak, step.at_cap
        k += 1
    return Rollout(qpos, mpjpe, res_f, res_t, contacts, failed_at, resets, shifts, over, peak_f, peak_t, at_cap,
                   reset_steps, recovered, recovered_steps)  # fmt: skip


def control_step(
    model, data, ref: Reference, controller: Controller, k: int, config: HumanoidConfig, weight: float
) -> StepHelp:
    """Advance ``data`` over control step k -> k+1 under ``controller``: its controls held, its root
    residual recomputed every ``config.residual_every`` simulation steps. Returns the residual force and
    torque over the step, mean and peak, as fractions of ``weight`` (N) and ``weight`` x 1 m; whether any
    hinge's total torque (its actuator's force plus the joint torque the controller applies directly, as
    the feet-balance path does) passed the actuator's limit at one of the residual updates; and whether
    one of the updates was held at a cap of the controller (force, lift or torque)."""
    import mujoco

    every = config.residual_every  # sim steps per root-residual update (one mj_step call of that many)
    ctrl, qfrc = controller.act(data, ref, k)
    data.ctrl[:] = ctrl
    data.qfrc_applied[:] = qfrc
    force = torque = peak_f = peak_t = 0.0
    over = held = False
    cap_force, cap_lift, cap_torque = (_AT_CAP * c for c in controller.caps())
    limits = model.actuator_forcerange[:, 1]  # actuator i drives hinge dof 6 + i (humanoid.build_mjcf)
    through, gains = getattr(controller, "joints_through_actuators", False), model.actuator_gainprm[:, 0]
    for s in range(every, config.substeps + 1, every):
        # The wrench held over simulation steps s - every + 1 .. s is the one ending at step s.
        applied = qfrc + controller.residual(data, ref, k * config.substeps + s, config.substeps)
        if through:  # the joint torques as target offsets: the actuators' force range clips the total
            data.ctrl[:] = ctrl + applied[6:] / gains
            applied[6:] = 0.0
        data.qfrc_applied[:] = applied
        wrench = applied[:6]
        f, t = math.hypot(*wrench[:3]), math.hypot(*wrench[3:])
        force, torque, peak_f, peak_t = force + f, torque + t, max(peak_f, f), max(peak_t, t)
        # MuJoCo z is up: the lift cap bounds the upward force alone
        held = held or (f > 0 and f >= cap_force) or (wrench[2] > 0 and wrench[2] >= cap_lift) or \
            (t > 0 and t >= cap_torque)
        mujoco.mj_step(model, data, every)
        if applied[6:].any():
            over = over or bool(np.any(np.abs(data.actuator_force + applied[6:]) > 1.001 * limits))
    updates = config.substeps // every
    return StepHelp(force / weight / updates, torque / weight / updates, over, peak_f / weight, peak_t / weight,
                    held)  # fmt: skip


# A residual within 0.1 % of a cap is held at it (the clip leaves it exactly at the cap, up to rounding).
_AT_CAP = 0.999


def _clearance(model, qpos: np.ndarray) -> float:
    """The highest the body's lowest point gets over the floor in qpos (M, nq), metres."""
    _, gpos, gmat = pose_frames(model, qpos)
    return float(body_lowest(model, gpos, gmat).max())


def contacts_of(model, data, foot_bodies: np.ndarray) -> np.ndarray:
    """(4,) bool: which of ``foot_bodies`` (left ankle, left foot, right ankle, right foot) touch the floor."""
    # Contacts with the floor (geom 0) by the foot bodies; the other geom of a floor pair is the body's.
    pairs = data.contact.geom[: data.ncon]
    on_floor = model.geom_bodyid[pairs[(pairs == 0).any(axis=1)].max(axis=1)]
    return (foot_bodies[:, None] == on_floor[None, :]).any(axis=1)  # np.isin: 5x slower here


def _drift(data, lay, ref: Reference, k: int, fail_mpjpe: float, let_land: bool) -> np.ndarray | None:
    """The horizontal offset (2,) of the body from reference step k where it has only drifted: its pose is
    within ``fail_mpjpe`` once that offset is taken out, or (``let_land``) once its whole offset is, the
    body being lower (it fell short of a flight and lands below the reference); else None."""
    offset = data.qpos[:2] - ref.qpos[k, :2]  # MuJoCo x/y: horizontal
    moved = ref.joints_mj[k].copy()
    moved[:, :2] += offset
    if mpjpe_of(data, lay, moved) <= fail_mpjpe:
        return offset
    if let_land and data.qpos[2] < ref.qpos[k, 2]:
        moved[:, 2] += data.qpos[2] - ref.qpos[k, 2]
        if mpjpe_of(data, lay, moved) <= fail_mpjpe:
            return offset
    return None


def mpjpe_of(data, lay, target: np.ndarray) -> float:
    """Mean distance (m) of the 22 skeleton bodies to ``target`` (22, 3), MuJoCo frame."""
    return float(np.mean(np.linalg.norm(data.xpos[lay.body_ids] - target, axis=-1)))

