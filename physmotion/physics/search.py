"""A controller that searches the body's own joint targets: P with no outside hand.

SAMCON-style sampling (Liu et al. 2010, "Sampling-based contact-rich motion control"; 2015, "Improving
sampling-based motion control") in the receding-horizon form of MuJoCo MPC's predictive sampling: the
tracker's PD targets and joint feed-forward (:meth:`ModelBasedTracker.act`, which reads only the
reference) are the nominal control, and every window of ``window`` control steps the search picks an
offset of the 63 joint targets to add to it.

- Candidates: ``candidates`` offsets (constant over the window) drawn around a mean, warm-started from
  ``warm`` x the last committed offset; candidate 0 is the mean itself, candidate 1 the bare tracker.
- Each candidate is simulated for the window plus a lookahead of ``horizon`` control steps, in which its
  offset decays by ``decay`` per step. A candidate is open-loop (the nominal control depends on the
  reference only), so all of them run in one ``mujoco.rollout`` call over threads, in C, with no Python
  per simulation step.
- Cross-entropy: ``rounds`` rounds, the mean and spread refitted to the best ``elites``.
- The best candidate's window is committed: its simulated states are the output.
- Adaptive effort: a window whose best candidate falls inside its lookahead is searched again with more
  candidates, a longer lookahead and a wider spread (``retries`` times); if it still falls, the window
  before it is searched again from its own start (SAMCON's rollback, ``rollback`` windows at most).

No outside help at all: no root residual, no ``qfrc_applied``; every joint torque is an actuator's,
within its force range. A fall is the body down or tipped against the reference (pelvis more than
``fall_drop`` under the reference's, or its up axis ``fall_tilt`` away from the reference's), not a
world-position error: the body may drift from the reference's path, and the drift is reported
(``Rollout.mpjpe`` is world MPJPE). The prototype's figures: ``../shared/notes/search-prototype.md``;
this build's: ``docs/decisions/projection.md``, "a searching controller with no outside hand".
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from physmotion.errors import ShapeError
from physmotion.physics.humanoid import HumanoidConfig, layout
from physmotion.physics.sim import Rollout, contacts_of, mpjpe_of, reset_state
from physmotion.physics.tracking import ModelBasedTracker, Reference, TrackingConfig
from physmotion.skeleton import FOOT_JOINTS


@dataclass(frozen=True)
class SearchCost:
    """Weights of the cost summed over a candidate's control steps (SI units; squared errors)."""

    body: float = 10.0  # mean squared pelvis-relative body-position error, m^2
    world: float = 30.0  # mean squared world body-position error, m^2 (2, the prototype's, let a run drift 0.3 m)
    joint: float = 0.1  # mean squared hinge-angle error, rad^2
    heading: float = 1.0  # pelvis heading error^2, rad^2
    height: float = 20.0  # pelvis height error^2, m^2
    velocity: float = 0.05  # root linear velocity error^2, (m/s)^2
    slip: float = 0.02  # squared horizontal speed of feet low enough to stand, (m/s)^2
    body_velocity: float = 0.0  # mean squared body-velocity error to the reference's, (m/s)^2; 0: off
    # (docs/decisions/projection.md, "the search as generation's P for jumps")
    fall: float = 100.0  # added for every control step after a fall


@dataclass(frozen=True)
class SearchConfig:
    """The search's effort, its cost and what counts as a fall (``EFFORTS`` names three)."""

    candidates: int = 32
    rounds: int = 2
    elites: int = 6
    window: int = 3  # control steps committed per search (0.1 s at 30 Hz)
    horizon: int = 15  # lookahead control steps after the window (0.5 s: a kick's weight shift starts early)
    sigma: float = 0.2  # rad: spread of the first round
    decay: float = 0.7  # per lookahead step, the candidate's offset is multiplied by this
    warm: float = 0.5  # the next window's mean: this times the committed offset
    # Spread on the ankle and toe hinges as a multiple of ``sigma``: their offsets move the feet on the floor.
    foot_sigma: float = 1.0
    # Control steps over which a window's offset blends in from the last committed one (0: a step change).
    blend: int = 0
    retries: int = 2  # a window whose best candidate falls is searched again this many times, harder
    rollback: int = 1  # then, windows before it searched again (SAMCON's rollback)
    # m: a window whose best candidate's pelvis-relative body error averages more than this is retried
    retry_error: float = 0.10
    fall_drop: float = 0.35  # m: pelvis this far under the reference's pelvis is a fall
    fall_tilt: float = 1.0  # rad: pelvis up axis this far from the reference's is a fall
    cost: SearchCost = field(default_factory=SearchCost)
    threads: int = 0  # rollout threads, 0: one per core (a worker process of a batch uses 1)
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("candidates", "rounds", "elites", "window", "horizon"):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= 1):
                raise ShapeError(f"search {name} must be a positive integer, got {getattr(self, name)!r}")
        if self.candidates < 2 or self.elites > self.candidates:
            raise ShapeError("search needs at least 2 candidates and no more elites than candidates")
        if not self.sigma > 0:
            raise ShapeError(f"search sigma must be positive, got {self.sigma}")

    def harder(self, attempt: int) -> SearchConfig:
        """The effort of retry ``attempt`` (1, 2, ...): candidates x (1 + attempt), lookahead + 3 attempt,
        spread x (1 + attempt / 3) (after the prototype's "twice the effort", which carried a kick)."""
        if attempt == 0:
            return self
        return replace(self, candidates=self.candidates * (1 + attempt), horizon=self.horizon + 3 * attempt,
                       sigma=self.sigma * (1 + attempt / 3))  # fmt: skip


# The presets of ``--effort``; their costs are measured in experiments/search_quality.py.
EFFORTS: dict[str, SearchConfig] = {
    "fast": SearchConfig(candidates=16, rounds=2, elites=4, horizon=10, sigma=0.15),
    "default": SearchConfig(),
    "best": SearchConfig(candidates=64, rounds=2, elites=8, horizon=18, sigma=0.25, rollback=2),
}


def effort(name: str, seed: int = 0) -> SearchConfig:
    """The search preset called ``name`` (fast, default, best), seeded."""
    if name not in EFFORTS:
        raise ShapeError(f"unknown search effort {name!r}; known: {', '.join(EFFORTS)}")
    return replace(EFFORTS[name], seed=seed)


def search_humanoid(humanoid: HumanoidConfig) -> HumanoidConfig:
    """The humanoid the search runs on: ``humanoid`` under the elliptic friction cone at impratio 10, with
    the hand box ending at the knuckles (0.08 m past the wrist) instead of PHC's straight hand (0.19 m),
    which the 22-joint body, with no wrist hinge, cannot bend to lay flat (docs/decisions/projection.md:
    "a searching controller with no outside hand" and "the hand box and torsional friction")."""
    return replace(humanoid, cone="elliptic", impratio=10.0, hand_length=0.08)


def no_hand(tracking: TrackingConfig) -> TrackingConfig:
    """``tracking`` with every outside help switched off (residual force, torque and lift 0, no feet
    balance through ``qfrc_applied``): what the search's nominal control is built with."""
    return replace(tracking, residual_force=0.0, residual_torque=0.0, residual_lift=0.0, feet_balance=False)


@dataclass
class SearchRecord:
    """What the search did, per control step 0..N-1 (the teacher's labels for a policy).

    offsets: (N, 63) the committed offset of the joint targets held over step k -> k+1 (rad; 0 at the last);
    effort: (N,) int, the retry level of the search that chose it (0: first try; -1: none, a reset);
    cost: (N,) the winning candidate's cost per control step of its rollout;
    observations: (N, 599) float32, what a policy would see at each committed state
    (:func:`physmotion.physics.policy.observe`, cap 0);
    qpos, qvel: (N, nq), (N, nv) the committed states: the searched trajectory, which the body follows with no
    outside hand by construction;
    rollouts: total candidate rollouts simulated; sim_steps: total simulation steps.
    """

    offsets: np.ndarray
    effort: np.ndarray
    cost: np.ndarray
    observations: np.ndarray | None = None
    qpos: np.ndarray | None = None
    qvel: np.ndarray | None = None
    rollouts: int = 0
    sim_steps: int = 0


Proposal = Callable[[np.ndarray], np.ndarray]  # a policy's observation (599,) -> offsets (63,) rad


class SearchController:
    """Runs one episode of the search along a reference (see the module docstring).

    proposal: where the first round's mean of each window comes from (amortized search: a learned policy
    proposes, a small search refines); None: ``warm`` x the last committed offset."""

    def __init__(self, model, config: SearchConfig | None = None, humanoid: HumanoidConfig | None = None,
                 tracking: TrackingConfig | None = None, proposal: Proposal | None = None) -> None:  # fmt: skip
        import mujoco

        self.model = model
        self.proposal = proposal
        self._planned: tuple | None = None  # (reference, nominal controls, goal) of the last window() call
        self.config = config or SearchConfig()
        self.humanoid = humanoid or HumanoidConfig()
        self.tracker = ModelBasedTracker(model, no_hand(tracking or TrackingConfig()))
        self.substeps = self.humanoid.substeps
        self.layout = layout(model)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self._spec = spec
        self._nstate = mujoco.mj_stateSize(model, spec)
        self._qpos_at = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_TIME)
        self._qvel_at = self._qpos_at + model.nq
        threads = self.config.threads or os.cpu_count() or 1
        self._datas = [mujoco.MjData(model) for _ in range(threads)]
        self._fk = mujoco.MjData(model)
        self._foot_bodies = self.layout.body_ids[list(FOOT_JOINTS)]
        # Per actuator (hinge qpos address 7 + i), the spread's multiple: foot_sigma on ankle and toe hinges.
        self._spread = np.ones(model.nu)
        for j in FOOT_JOINTS:
            self._spread[self.layout.hinge_qpos[j] - 7] = self.config.foot_sigma

    # --- one episode -----------------------------------------------------------------------------------
    def run(self, ref: Reference, reset_on_fail: bool = False, on_step: Callable[[int, int], None] | None = None,
            push: np.ndarray | None = None, start: np.ndarray | None = None) -> tuple[Rollout, SearchRecord]:  # fmt: skip
        """Search along ``ref`` from its first frame. A committed state that has fallen ends the episode
        (``failed_at``, the rest repeating the last state) or, with ``reset_on_fail``, puts the humanoid back
        on the reference there and counts a reset. on_step(done, total): control steps committed.
        push: (6,) added to the root's velocity at the start (linear m/s, angular rad/s, MuJoCo's free-joint
        velocity): a perturbed start, so that teacher data covers recoveries.
        start: (nq + nv,) qpos and qvel to start from instead of the reference's first frame (another
        controller's state: the search taking over a stretch of its episode, ``sim.simulate``'s ``recover``)."""
        import mujoco

        from physmotion.physics.sim import _quiet_mujoco_warnings

        _quiet_mujoco_warnings()
        cfg, model = self.config, self.model
        n = len(ref.qpos)
        rng = np.random.default_rng(cfg.seed)
        nominal = np.stack([self.tracker.act(None, ref, k)[0] for k in range(n)])  # (N, nu)
        goal = SearchGoal(ref, cfg)
        data = mujoco.MjData(model)
        reset_state(model, data, ref)
        if start is not None:
            data.qpos[:], data.qvel[:] = start[: model.nq], start[model.nq :]
            mujoco.mj_forward(model, data)
        if push is not None:
            data.qvel[:6] += push
            mujoco.mj_forward(model, data)
        states = np.zeros((n, self._nstate))
        states[0] = self._get(data)
        offsets = np.zeros((n, model.nu))
        level = -np.ones(n, dtype=int)
        costs = np.zeros(n)
        failed_at, resets = None, 0
        reset_steps = np.zeros(n, dtype=bool)
        record = SearchRecord(offsets, level, costs)
        mean = np.zeros(model.nu)
        last = np.zeros(model.nu)  # the offset committed last, which a window blends from
        k = 0
        rolled_back = 0  # windows re-searched since the last progress past the furthest window
        furthest = 0  # the furthest window start reached; windows before it, re-searched, start hardest
        while k < n - 1:
            w = min(cfg.window, n - 1 - k)
            best, best_attempt = None, 0
            first = cfg.retries if k < furthest else 0
            if self.proposal is not None:
                mean = self._propose(states[k], ref, k, last, cfg.warm)
            for attempt in range(first, cfg.retries + 1):
                harder = cfg.harder(attempt)
                found = self._search(states[k], nominal, goal, k, w, mean, last, harder, rng, record)
                # A fall late in a long lookahead is the next windows' business; a window that keeps its
                # feet but leaves the motion (a kick given up for balance) is retried as a fall is.
                found.failed = (found.fell_at is not None and found.fell_at < w + harder.horizon // 2) or \
                    float(found.body_error[:w].mean()) > cfg.retry_error
                if best is None or found.rank(w) < best.rank(w):
                    best, best_attempt = found, attempt
                if not found.failed:
                    break
            level[k : k + w] = best_attempt
            if best.fell_at is not None and best.fell_at < w and rolled_back < cfg.rollback and k > 0:
                # Roll back: search the window before again, hardest, from its own start.
                back = max(0, k - cfg.window)
                rolled_back += 1
                mean = offsets[back].copy()
                last = offsets[back - 1].copy() if back > 0 else np.zeros(model.nu)
                k = back
                continue
            offsets[k : k + w] = best.applied[:w]
            last = best.applied[w - 1].copy()
            costs[k + 1 : k + w + 1] = best.step_cost[:w]
            states[k + 1 : k + w + 1] = best.states[:w]
            mean = cfg.warm * best.offset
            fell = next((j for j in range(1, w + 1) if goal.fallen(self._qpos(states[k + j]), k + j)), None)
            if fell is not None:
                at = k + fell
                failed_at = at if failed_at is None else failed_at
                if not reset_on_fail:
                    states[at + 1 :] = states[at]
                    break
                resets += 1
                reset_steps[at] = True
                reset_state(model, data, ref, at)
                states[at] = self._get(data)
                mean, last = np.zeros(model.nu), np.zeros(model.nu)
                level[at] = -1
                k = at
                continue
            k += w
            if k > furthest:
                furthest, rolled_back = k, 0
            if on_step is not None:
                on_step(k, n - 1)
        roll, record.observations = self._rollout(ref, states, failed_at, resets)
        roll.reset_steps = reset_steps
        record.qpos = states[:, self._qpos_at : self._qpos_at + model.nq].copy()
        record.qvel = states[:, self._qvel_at : self._qvel_at + model.nv].copy()
        return roll, record

    def window(self, ref: Reference, state: np.ndarray, k: int, mean: np.ndarray, seed: int,
               temperature: float | None = None) -> np.ndarray:  # fmt: skip
        """The offsets (63,) rad that one window's search (this controller's effort, no retries) commits
        from ``state`` (a full-physics state, ``mj_getState``) at control step ``k`` of ``ref``, its first
        round centred on ``mean`` (63,): the labels of a student's own states (DAgger). Deterministic in
        ``seed``. With ``temperature``, instead one round whose candidates are averaged with the weights
        exp(-(cost - least) / (temperature x (median - least))) (MPPI's path-integral weighting, scaled by the
        spread of the costs): with the same seed for every state (common random numbers) the label is a
        smooth function of the state, where the best candidate jumps between unlike offsets."""
        if self._planned is None or self._planned[0] is not ref:  # nominal controls and goal, once per reference
            nominal = np.stack([self.tracker.act(None, ref, j)[0] for j in range(len(ref.qpos))])
            self._planned = (ref, nominal, SearchGoal(ref, self.config))
        _, nominal, goal = self._planned
        w = min(self.config.window, len(ref.qpos) - 1 - k)
        if w < 1:
            return np.zeros(self.model.nu)
        cfg, rng = self.config, np.random.default_rng(seed)
        mean = np.asarray(mean, dtype=float)
        record = SearchRecord(np.zeros(0), np.zeros(0), np.zeros(0))
        if temperature is None:
            return self._search(state, nominal, goal, k, w, mean, mean, cfg, rng, record).offset
        cand = mean + cfg.sigma * self._spread * rng.standard_normal((cfg.candidates, len(mean)))
        cand[0] = mean
        _, _, step_cost, _, _ = self._candidates(state, nominal, goal, k, w, cand, mean, cfg, record)
        total = step_cost.sum(axis=1)
        spread = max(float(np.median(total) - total.min()), 1e-9)
        weights = np.exp(-(total - total.min()) / (temperature * spread))
        return (weights / weights.sum()) @ cand

    def _propose(self, state: np.ndarray, ref: Reference, k: int, last: np.ndarray, warm: float) -> np.ndarray:
        """The proposal's offsets (63,) rad at the committed state ``state`` of control step ``k``; a
        non-finite proposal falls back to ``warm`` x the last committed offset."""
        import mujoco

        from physmotion.physics.policy import observe

        mujoco.mj_setState(self.model, self._fk, state, self._spec)
        mujoco.mj_forward(self.model, self._fk)
        out = np.asarray(self.proposal(observe(self.model, self._fk, ref, k, 0.0)), dtype=float)
        return out if np.all(np.isfinite(out)) else warm * last

    # --- the search of one window ------------------------------------------------------------------------
    def _search(self, state, nominal, goal, k, w, mean, last, cfg: SearchConfig, rng, record) -> _Candidate:
        mu, sigma = mean.copy(), cfg.sigma * self._spread
        best = None
        for _ in range(cfg.rounds):
            cand = mu + sigma * rng.standard_normal((cfg.candidates, len(mu)))
            cand[0] = mu
            if best is None:
                # the bare tracker; with a proposal, the last committed plan carried on instead
                cand[1] = 0.0 if self.proposal is None else cfg.warm * last
            else:
                cand[1] = best.offset  # keep the best so far
            applied, at_ctrl, step_cost, fell, body_error = self._candidates(state, nominal, goal, k, w, cand, last,
                                                                             cfg, record)  # fmt: skip
            total = step_cost.sum(axis=1)
            order = np.argsort(total, kind="stable")
            i = int(order[0])
            if best is None or total[i] < best.total:
                fell_at = int(np.argmax(fell[i])) if fell[i].any() else None
                best = _Candidate(cand[i].copy(), applied[i], float(total[i]), step_cost[i], at_ctrl[i], fell_at,
                                  body_error[i])  # fmt: skip
            elite = cand[order[: cfg.elites]]
            mu, sigma = elite.mean(axis=0), np.maximum(elite.std(axis=0), 0.1 * cfg.sigma * self._spread)
        return best

    def _candidates(self, state, nominal, goal, k, w, cand, last, cfg: SearchConfig, record) -> tuple:
        """Simulate candidate offsets cand (C, nu) from ``state`` over the window and its lookahead (one
        ``mujoco.rollout`` call): (applied (C, S, nu), states after each control step (C, S, nstate), step
        cost (C, S), fall flags (C, S), pelvis-relative body error (C, S))."""
        from mujoco import rollout

        n = len(nominal)
        h = min(cfg.horizon, n - 1 - k - w)
        steps = w + h
        scale = np.concatenate([np.ones(w), cfg.decay ** np.arange(1, h + 1)])  # (steps,)
        # Weight of the candidate against the last committed offset per step: 1 once blended in.
        blend = np.minimum(1.0, np.arange(1, steps + 1) / max(cfg.blend, 1))[:, None]  # (steps, 1)
        base = nominal[k : k + steps]  # nominal[j]: the tracker's targets over control step j -> j+1
        applied = (blend * cand[:, None, :] + (1 - blend) * last) * scale[None, :, None]  # (C, steps, nu)
        ctrl = np.repeat(base[None] + applied, self.substeps, axis=1)
        init = np.repeat(state[None], len(cand), axis=0)
        out, _ = rollout.rollout(self.model, self._datas, init, ctrl)
        record.rollouts += len(cand)
        record.sim_steps += len(cand) * steps * self.substeps
        at_ctrl = out[:, self.substeps - 1 :: self.substeps]  # (C, steps, nstate): after each control step
        step_cost, fell, body_error = self._cost(at_ctrl, goal, k)
        return applied, at_ctrl, step_cost, fell, body_error

    def _cost(self, states: np.ndarray, goal: SearchGoal, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-step cost (C, S), fall flags (C, S) and mean pelvis-relative body error (C, S), metres, of
        candidate states (C, S, nstate) after control steps k+1..k+S."""
        c = self.config.cost
        cands, steps = states.shape[:2]
        qpos = states[..., self._qpos_at : self._qpos_at + self.model.nq]
        qvel = states[..., self._qvel_at : self._qvel_at + self.model.nv]
        bodies = self._bodies(qpos.reshape(-1, self.model.nq)).reshape(cands, steps, -1, 3)
        idx = np.minimum(np.arange(k + 1, k + 1 + steps), goal.n - 1)
        ref_b = goal.joints[idx]  # (S, 22, 3)
        rel = (bodies - bodies[:, :, :1]) - (ref_b - ref_b[:, :1])[None]
        cost = c.body * np.mean(np.sum(rel**2, axis=-1), axis=-1)
        cost += c.world * np.mean(np.sum((bodies - ref_b[None]) ** 2, axis=-1), axis=-1)
        cost += c.joint * np.mean((qpos[..., 7:] - goal.qpos[idx, 7:][None]) ** 2, axis=-1)
        yaw, up = _yaw_up(qpos[..., 3:7])
        dyaw = np.angle(np.exp(1j * (yaw - goal.yaw[idx][None])))
        cost += c.heading * dyaw**2
        cost += c.height * (qpos[..., 2] - goal.qpos[idx, 2][None]) ** 2
        cost += c.velocity * np.sum((qvel[..., :3] - goal.qvel[idx, :3][None]) ** 2, axis=-1)
        if c.body_velocity:  # a step the reference does not take costs (issue 62's frame-to-frame jumps)
            prev = np.concatenate([bodies[:, :1], bodies[:, :-1]], axis=1)
            ref_prev = goal.joints[np.maximum(idx - 1, 0)]
            dv = ((bodies - prev) - (ref_b - ref_prev)[None]) / self.humanoid.control_dt
            dv[:, 0] = 0.0  # the first step's previous position is not known here
            cost += c.body_velocity * np.mean(np.sum(dv**2, axis=-1), axis=-1)
        if c.slip:
            feet = bodies[:, :, list(FOOT_JOINTS)]  # (C, S, 4, 3)
            prev = np.concatenate([feet[:, :1], feet[:, :-1]], axis=1)
            speed2 = np.sum((feet[..., :2] - prev[..., :2]) ** 2, axis=-1) / self.humanoid.control_dt**2
            low = feet[..., 2] < goal.stand_height[None, None]
            speed2[:, 0] = 0.0  # the first step's previous position is not known here
            cost += c.slip * np.sum(np.where(low, speed2, 0.0), axis=-1)
        fell = goal.fallen_many(qpos[..., 2], up, idx)
        fell = np.cumsum(fell, axis=1) > 0  # every step from the first fall on
        return cost + c.fall * fell, fell, np.mean(np.linalg.norm(rel, axis=-1), axis=-1)

    def _bodies(self, qpos: np.ndarray) -> np.ndarray:
        """World positions (M, 22, 3) of the skeleton's bodies at qpos (M, nq), MuJoCo frame."""
        import mujoco

        out = np.empty((len(qpos), len(self.layout.body_ids), 3))
        d, ids = self._fk, self.layout.body_ids
        for i, q in enumerate(qpos):
            d.qpos[:] = q
            mujoco.mj_kinematics(self.model, d)
            out[i] = d.xpos[ids]
        return out

    def _get(self, data) -> np.ndarray:
        import mujoco

        s = np.empty(self._nstate)
        mujoco.mj_getState(self.model, data, s, self._spec)
        return s

    def _qpos(self, state: np.ndarray) -> np.ndarray:
        return state[self._qpos_at : self._qpos_at + self.model.nq]

    def _rollout(self, ref: Reference, states: np.ndarray, failed_at: int | None,
                 resets: int) -> tuple[Rollout, np.ndarray]:  # fmt: skip
        """The committed states as the simulation core's :class:`Rollout` (no residual, no torque past a
        limit: the actuators' force range bounds every joint torque, and nothing else is applied), and a
        policy's observation (N, 599) of each."""
        import mujoco

        from physmotion.physics.policy import OBS_DIM, observe

        n = len(states)
        data = mujoco.MjData(self.model)
        qpos = np.zeros((n, self.model.nq))
        mpjpe = np.zeros(n)
        contacts = np.zeros((n, 4), dtype=bool)
        obs = np.zeros((n, OBS_DIM), dtype=np.float32)
        for k, s in enumerate(states):
            mujoco.mj_setState(self.model, data, s, self._spec)
            mujoco.mj_forward(self.model, data)
            obs[k] = observe(self.model, data, ref, k, 0.0)
            qpos[k] = data.qpos
            mpjpe[k] = mpjpe_of(data, self.layout, ref.joints_mj[k])
            contacts[k] = contacts_of(self.model, data, self._foot_bodies)
        zeros = np.zeros(n)
        over = np.zeros(n, dtype=bool)
        return Rollout(qpos, mpjpe, zeros, zeros.copy(), contacts, failed_at, resets, 0, over), obs


@dataclass
class _Candidate:
    offset: np.ndarray  # (nu,) the candidate drawn
    applied: np.ndarray  # (S, nu) the offset applied per control step (blended in, decaying in the lookahead)
    total: float
    step_cost: np.ndarray  # (S,)
    states: np.ndarray  # (S, nstate) after each control step
    fell_at: int | None  # index into the S steps of the first fallen one
    body_error: np.ndarray  # (S,) mean pelvis-relative body error, m
    failed: bool = False  # the window counts as failed (a fall in it or soon after, or off the motion)

    def rank(self, w: int) -> tuple[bool, float]:
        """Order between attempts at one window (lookaheads differ, so costs do not compare): one that does
        not fall within the window first, then the smaller body error over the window."""
        return (self.fell_at is not None and self.fell_at < w, float(self.body_error[:w].mean()))


class SearchGoal:
    """The reference as the cost reads it, precomputed once per episode."""

    def __init__(self, ref: Reference, config: SearchConfig) -> None:
        self.n = len(ref.qpos)
        self.fall_drop, self.cos_tilt = config.fall_drop, float(np.cos(config.fall_tilt))
        self.qpos, self.qvel, self.joints = ref.qpos, ref.qvel, ref.joints_mj
        self.yaw, self.up = _yaw_up(ref.qpos[:, 3:7])
        feet = ref.joints_mj[:, list(FOOT_JOINTS), 2]  # (N, 4) heights of the foot bodies
        self.stand_height = feet.min(axis=0) + 0.03  # a foot body this low can stand (m)

    def fallen_many(self, height: np.ndarray, up: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Fall flags (..., S) for pelvis heights (..., S) and up axes (..., S, 3) at reference steps idx."""
        drop = self.qpos[idx, 2] - height > self.fall_drop
        cos = np.sum(up * self.up[idx], axis=-1)
        return drop | (cos < self.cos_tilt)

    def fallen(self, qpos: np.ndarray, k: int) -> bool:
        _, up = _yaw_up(qpos[3:7][None])
        return bool(self.fallen_many(np.array([qpos[2]]), up, np.array([min(k, self.n - 1)]))[0])


def _yaw_up(quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Heading (...,) of the local x axis about world z, and the local z axis (..., 3) in world, of unit
    quaternions (..., 4) wxyz."""
    w, x, y, z = (quat[..., i] for i in range(4))
    fx, fy = 1 - 2 * (y * y + z * z), 2 * (x * y + w * z)  # first column of the rotation matrix
    up = np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=-1)
    return np.arctan2(fy, fx), up


def save_teacher(path, result, motion) -> None:
    """Write a searched motion's teacher records to ``path`` (.npz, atomically): ``observations`` (N, 599)
    and ``offsets`` (N, 63) per control step (:class:`SearchRecord`), the control rate ``control_fps``, and
    the source motion's ``text`` and ``licence_tag`` (its tag travels with every derived artefact).

    result: a single motion's :class:`~physmotion.physics.projection.ProjectedMotion` under the search;
    motion: the :class:`~physmotion.motion.Motion` it was made from."""
    from physmotion.motion import write_atomic

    if result.teacher_obs is None:
        raise ShapeError("no teacher records: the motion was not projected by the search controller")
    arrays = {"observations": result.teacher_obs, "offsets": result.teacher_offsets,
              "control_fps": np.array(1.0 / HumanoidConfig().control_dt),
              "text": np.array("\n".join(motion.texts)), "licence_tag": np.array(motion.licence_tag)}  # fmt: skip
    write_atomic(path, lambda f: np.savez_compressed(f, **arrays))
