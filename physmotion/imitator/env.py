"""One imitation episode: the humanoid on a clip from a chosen frame, driven by the tracker plus the policy.

What P simulates (``projection.prepare_motion`` with the plain preset's shaping and humanoid) is what the
policy trains on, and the controller is the same :class:`~physmotion.physics.policy.PolicyController`
arithmetic: the tracker's PD targets plus ``action_scale`` x the action, the root residual capped at
``cap`` x the tracker's bounds. DeepMimic-style: reference state initialisation (a random start frame),
early termination when the body leaves the reference, an imitation reward.

A clip may carry a tracked trajectory (:class:`~physmotion.imitator.clips.TrackedTrajectory`: the search's,
from a teacher record): the observation's reference stays the kinematic one, what P gives the policy at
deployment, but the reward, the early termination and the start states follow the tracked trajectory,
which the body can follow with no outside hand (the kinematic reference it may not be able to).

Reward per control step, against step k+1 of the reference (or of the tracked trajectory), with the weights
of :class:`RewardConfig`:
``w_pos exp(-k_pos mean|dx|^2) + w_rot exp(-k_rot mean dq^2) + w_vel exp(-k_vel |dv_root|^2)
+ w_height exp(-k_height dz_root^2) + alive - w_residual (force/W + 0.2 torque/(W m)) - w_action mean a^2``,
with dx the 22 bodies' position errors, dq the 63 hinge errors, dv the root velocity error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.imitator.clips import TrackedTrajectory
from physmotion.physics.humanoid import HumanoidConfig, layout
from physmotion.physics.policy import NUM_ACTIONS, PolicySettings, capped_tracking, observe
from physmotion.physics.sim import control_step, mpjpe_of, reset_state
from physmotion.physics.tracking import STANDARD_GRAVITY, ModelBasedTracker, Reference, prepare_reference
from physmotion.physics.projection import PreparedMotion


@dataclass(frozen=True)
class RewardConfig:
    """Weights and sharpness of the imitation reward (the module docstring has the formula)."""

    w_pos: float = 0.45
    k_pos: float = 100.0
    w_rot: float = 0.2
    k_rot: float = 20.0
    w_vel: float = 0.1
    k_vel: float = 2.0
    w_height: float = 0.1
    k_height: float = 100.0
    alive: float = 0.15
    w_residual: float = 0.5
    w_action: float = 0.01
    terminate_mpjpe: float = 0.3  # m: the episode ends when the bodies are this far from the goal


@dataclass(frozen=True)
class EnvConfig:
    """One episode's rules."""

    settings: PolicySettings = field(default_factory=PolicySettings)
    reward: RewardConfig = field(default_factory=RewardConfig)
    humanoid: HumanoidConfig = field(default_factory=HumanoidConfig)
    max_steps: int = 150  # control steps (5 s at 30 Hz): long clips are learnt from random starts


class Clip:
    """A prepared motion with its tracker reference (computed once, reused by every episode on it).

    ref: what the tracker and the observation follow, the kinematic reference (N steps). goal: what the
    reward, the early termination and the start states follow: ``ref`` itself, or with ``tracked`` a
    :class:`Reference` of its qpos (M, nq), qvel (M, nv) and bodies by forward kinematics (M, 22, 3), M <= N
    (its ``tau_ff`` is unused, zeros).
    """

    def __init__(self, prepared: PreparedMotion, config: EnvConfig,
                 tracked: TrackedTrajectory | None = None) -> None:  # fmt: skip
        self.model = prepared.model
        self.ref = prepare_reference(self.model, prepared.target, config.humanoid.control_dt,
                                     config.settings.tracking)  # fmt: skip
        self.weight = float(self.model.body_subtreemass[0]) * STANDARD_GRAVITY
        self.layout = layout(self.model)
        self.tracked = tracked
        self.goal = self.ref if tracked is None else self._goal(tracked)

    def _goal(self, tracked: TrackedTrajectory) -> Reference:
        import mujoco

        m, n = len(tracked.qpos), len(self.ref.qpos)
        nq, nv = self.model.nq, self.model.nv
        if tracked.qpos.shape != (m, nq) or tracked.qvel.shape != (m, nv) or not 2 <= m <= n:
            raise PhysmotionError(f"a tracked trajectory of qpos {tracked.qpos.shape} and qvel "
                                  f"{tracked.qvel.shape} does not fit this humanoid (nq {nq}, nv {nv}) and "
                                  f"its {n}-step reference")  # fmt: skip
        data = mujoco.MjData(self.model)
        bodies = np.zeros((m, len(self.layout.body_ids), 3))
        for k, q in enumerate(tracked.qpos):
            data.qpos[:] = q
            mujoco.mj_kinematics(self.model, data)
            bodies[k] = data.xpos[self.layout.body_ids]
        return Reference(tracked.qpos, tracked.qvel, bodies, np.zeros_like(tracked.qvel))

    @property
    def steps(self) -> int:
        """Control steps an episode can run over: the goal's."""
        return len(self.goal.qpos)


class ImitationEnv:
    """A single episode at a time on one of many clips; numpy in, numpy out."""

    def __init__(self, config: EnvConfig) -> None:
        self.config = config
        self.clip: Clip | None = None
        self.k = 0
        self.start = 0
        self.cap = 0.0
        self._tracker: ModelBasedTracker | None = None
        self.data = None  # mujoco.MjData of the current clip's model

    def reset(self, clip: Clip, frame: int, cap: float) -> np.ndarray:
        """Put the humanoid on ``clip``'s goal at control step ``frame`` with the residual cap ``cap``; the
        observation (599,) against the kinematic reference."""
        import mujoco

        if self.clip is not clip:  # each environment simulates in its own MjData
            self.data = mujoco.MjData(clip.model)
        self.clip, self.k, self.start, self.cap = clip, frame, frame, float(cap)
        self._tracker = ModelBasedTracker(clip.model, capped_tracking(self.config.settings.tracking, cap))
        if clip.tracked is None:
            reset_state(clip.model, self.data, clip.ref, frame)
        else:  # a simulated state: exactly as it was, not lifted out of the floor as a kinematic frame is
            mujoco.mj_resetData(clip.model, self.data)
            self.data.qpos[:], self.data.qvel[:] = clip.goal.qpos[frame], clip.goal.qvel[frame]
            mujoco.mj_forward(clip.model, self.data)
        return observe(clip.model, self.data, clip.ref, frame, self.cap)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, float]]:
        """Apply ``action`` (63,) over one control step: (observation, reward, terminated, truncated, info)."""
        clip, cfg, rw = self.clip, self.config, self.config.reward
        a = np.clip(action, -1.0, 1.0)
        controller = _Offset(self._tracker, cfg.settings.action_scale * a)
        help_ = control_step(clip.model, self.data, clip.ref, controller, self.k, cfg.humanoid, clip.weight)
        force, torque = help_.force, help_.torque
        self.k += 1
        k, data, ref, goal = self.k, self.data, clip.ref, clip.goal
        bodies = data.xpos[clip.layout.body_ids]
        dx2 = float(np.mean(np.sum((bodies - goal.joints_mj[k]) ** 2, axis=-1)))
        mpjpe = mpjpe_of(data, clip.layout, goal.joints_mj[k])
        dq2 = float(np.mean((data.qpos[7:] - goal.qpos[k, 7:]) ** 2))
        dv2 = float(np.sum((data.qvel[:3] - goal.qvel[k, :3]) ** 2))
        dz2 = float((data.qpos[2] - goal.qpos[k, 2]) ** 2)
        reward = (rw.w_pos * math.exp(-rw.k_pos * dx2) + rw.w_rot * math.exp(-rw.k_rot * dq2)
                  + rw.w_vel * math.exp(-rw.k_vel * dv2) + rw.w_height * math.exp(-rw.k_height * dz2)
                  + rw.alive - rw.w_residual * (force + 0.2 * torque)
                  - rw.w_action * float(np.mean(a * a)))  # fmt: skip
        terminated = bool(mpjpe > rw.terminate_mpjpe or not np.all(np.isfinite(data.qpos)))
        truncated = not terminated and (k >= clip.steps - 1 or k - self.start >= cfg.max_steps)
        obs = observe(clip.model, data, ref, min(k, clip.steps - 1), self.cap)
        if not np.all(np.isfinite(obs)):
            obs = np.nan_to_num(obs, nan=0.0, posinf=0.0, neginf=0.0)
            terminated = True
        info = {"mpjpe": mpjpe, "force": force, "torque": torque}
        return obs, float(reward), terminated, truncated, info


class _Offset:
    """The tracker with fixed offsets added to its PD targets over one control step."""

    def __init__(self, tracker: ModelBasedTracker, offset: np.ndarray) -> None:
        self.tracker, self.offset = tracker, offset

    def act(self, data, ref, k):
        ctrl, qfrc = self.tracker.act(data, ref, k)
        return ctrl + self.offset, qfrc

    def residual(self, data, ref, step, substeps):
        return self.tracker.residual(data, ref, step, substeps)

    def caps(self):
        return self.tracker.caps()


__all__ = ["NUM_ACTIONS", "Clip", "EnvConfig", "ImitationEnv", "RewardConfig"]
