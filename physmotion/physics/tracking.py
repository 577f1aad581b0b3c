"""Tracking controllers: what drives the humanoid along a reference motion.

The model-based tracker needs no training. At each control step (30 Hz by default) it sends

- PD targets: the reference hinge angles of the next control step (position actuators in the MJCF),
  plus ``kv * qvel_ref`` so the actuators' damping acts on the velocity *error*;
- feed-forward joint torques from the reference's inverse dynamics (``mj_inverse`` with contacts and
  limits disabled), after the part of the root wrench that the feet can carry has been given to
  them: min-norm foot forces in a friction pyramid (NNLS) at the foot-box corners that touch the
  floor in the reference. ``mj_inverse`` with contacts on is useless here: the soft contact model
  turns small reference penetrations into huge forces, and a feed-forward built on them pushes the
  body up (docs/decisions/projection.md: "inverse dynamics without contacts, foot forces split out");
- a root wrench: what the feet could not explain in the reference, plus a PD pull of the pelvis toward
  the reference. With ``feet_balance`` the feet that touch the floor in the simulation carry what they
  can of it (contact forces in the friction pyramid, made by the legs' joint torques); the rest is the
  residual (RFC, PhysDiff's action space), clipped to ``residual_force`` x body weight and
  ``residual_torque`` x body weight x 1 m. Kept small so that the body cannot float or sink.

All reference terms depend only on the reference, so :func:`prepare_reference` computes them once for
the whole motion; the closed loop adds only the root PD. A learned policy implements
:class:`Controller` the same way and can replace or correct this one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.optimize import nnls
from scipy.spatial.transform import Rotation, Slerp

from physmotion.physics.humanoid import layout
from physmotion.physics.retarget import qvel_from_qpos
from physmotion.skeleton import JOINT_NAMES

STANDARD_GRAVITY = 9.81  # m/s^2: residual bounds are fractions of body weight on Earth


@dataclass(frozen=True)
class TrackingConfig:
    """Gains and bounds of the model-based tracker (SI units; fractions of body weight W = m g)."""

    # Root residual bounds (docs/decisions/projection.md: "tracker residual bounds", "residual within 0.1 W on
    # walks and runs"): 0.2 W with the feet carrying the force first; upward force capped at 0.1 W so the
    # residual cannot hold a body up.
    residual_force: float = 0.2  # max |F| on the root as a fraction of W
    residual_torque: float = 1.0  # max |tau| on the root as a fraction of W x 1 m
    residual_lift: float = 0.1  # max upward force on the root as a fraction of W (below 1: cannot float)
    root_kp: float = 10000.0  # N/m, pelvis position PD (before clipping)
    root_kd: float = 1000.0  # N s/m
    root_rot_kp: float = 3000.0  # N m/rad
    root_rot_kd: float = 30.0  # N m s/rad
    contact_height: float = 0.02  # m: a foot-box corner this close to the floor can push
    friction: float = 0.8  # friction pyramid slope for the contact split (below the geoms' 1.0)
    feedforward: bool = True
    # Route the root wrench (feed-forward leftover + root PD) through the feet that touch the floor in the
    # simulation first: foot forces in the friction pyramid (NNLS), made by the legs' joint torques; only
    # what the feet cannot carry is left to the residual (docs/decisions/projection.md: "balance through the
    # feet").
    feet_balance: bool = True
    # Weight of the torque rows against the force rows in that fit (at 1, 1 N m counts as much as 1 N):
    # below 1 the feet carry more of the force and leave more torque to the residual, whose bound
    # (``residual_torque``) is the looser one.
    feet_torque_weight: float = 0.3
    # Send those joint torques through the leg actuators' targets (torque / kp added to the target), so
    # each actuator's force range clips its total; off, they are applied beside the actuators and a hinge's
    # total can pass its limit (``over_limit``; docs/decisions/sampling.md: "the root wrench through the
    # feet in generation").
    feet_through_actuators: bool = False


@dataclass
class Reference:
    """A reference motion at the control rate, with everything the tracker precomputes.

    qpos: (N, 70) targets at control steps 0..N-1; qvel: (N, 69); joints_mj: (N, 22, 3) body positions
    in MuJoCo's frame (for MPJPE); tau_ff: (N, 69) feed-forward generalised forces (root rows hold the
    part of the root wrench the feet could not carry, in MuJoCo's free-joint convention: world force,
    local torque).
    """

    qpos: np.ndarray
    qvel: np.ndarray
    joints_mj: np.ndarray
    tau_ff: np.ndarray
    _root: dict[int, RootTargets] = field(default_factory=dict, repr=False)

    def root_targets(self, substeps: int) -> RootTargets:
        """The root's reference at every simulation step of ``substeps`` per control step (cached)."""
        if substeps not in self._root:
            self._root[substeps] = _root_targets(self, substeps)
        return self._root[substeps]

    def window(self, start: int, stop: int) -> Reference:
        """Control steps start..stop-1 of this reference, as a reference of their own."""
        return Reference(qpos=self.qpos[start:stop], qvel=self.qvel[start:stop],
                         joints_mj=self.joints_mj[start:stop], tau_ff=self.tau_ff[start:stop])  # fmt: skip

    def shifted(self, step: int, offset: np.ndarray, substeps: int) -> Reference:
        """A copy whose control steps from ``step`` on are moved horizontally by ``offset`` (2,), MuJoCo
        x/y; the root targets of ``substeps`` per control step move with them."""
        qpos, joints = self.qpos.copy(), self.joints_mj.copy()
        qpos[step:, :2] += offset
        joints[step:, :, :2] += offset
        tgt = self.root_targets(substeps)
        pos = tgt.pos.copy()
        pos[step * substeps :, :2] += offset
        root = {substeps: RootTargets(pos, tgt.vel, tgt.quat, tgt.omega, tgt.ff_force, tgt.ff_torque)}
        return Reference(qpos=qpos, qvel=self.qvel, joints_mj=joints, tau_ff=self.tau_ff, _root=root)


@dataclass(frozen=True)
class RootTargets:
    """The reference root at simulation steps i = 0..(N-1) * substeps, i.e. control time i / substeps,
    interpolated between control steps (positions and velocities linearly, the orientation by slerp).

    pos, vel: (M, 3) world; quat: (M, 4) wxyz; omega: (M, 3) angular velocity, world frame;
    ff_force: (M, 3) world and ff_torque: (M, 3) local, the feed-forward root wrench the feet could not
    carry, held over each control step.
    """

    pos: np.ndarray
    vel: np.ndarray
    quat: np.ndarray
    omega: np.ndarray
    ff_force: np.ndarray
    ff_torque: np.ndarray
    # Per step, the 15 floats pos, vel, ff_force, omega, ff_torque as a Python list: the residual runs at
    # the simulation rate, and indexing small numpy arrays there cost more than the arithmetic.
    rows: list[list[float]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        rows = np.concatenate([self.pos, self.vel, self.ff_force, self.omega, self.ff_torque], axis=1).tolist()
        object.__setattr__(self, "rows", rows)


def _root_targets(ref: Reference, substeps: int) -> RootTargets:
    n = len(ref.qpos)
    t = np.arange((n - 1) * substeps + 1) / substeps
    k = np.minimum(np.floor(t).astype(int), max(n - 2, 0))
    a = (t - k)[:, None]
    k1 = np.minimum(k + 1, n - 1)
    rots = Rotation.from_quat(ref.qpos[:, 3:7], scalar_first=True)
    quat = Slerp(np.arange(n), rots)(t) if n > 1 else rots
    omega_local = (1 - a) * ref.qvel[k, 3:6] + a * ref.qvel[k1, 3:6]
    ff = ref.tau_ff[np.minimum(k, len(ref.tau_ff) - 1), :6]
    return RootTargets(
        pos=(1 - a) * ref.qpos[k, :3] + a * ref.qpos[k1, :3],
        vel=(1 - a) * ref.qvel[k, :3] + a * ref.qvel[k1, :3],
        quat=quat.as_quat(scalar_first=True),
        omega=quat.apply(omega_local),
        ff_force=ff[:, :3],
        ff_torque=ff[:, 3:],
    )


class Controller(Protocol):
    """What a tracker (model-based or learned) provides to the simulation loop. One that sets
    ``joints_through_actuators`` true has the joint torques :meth:`residual` returns put into the actuators'
    targets (torque / kp), where their force range clips the total, instead of beside them."""

    def act(self, data, ref: Reference, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Controls held over the control step k -> k+1: (ctrl (nu,), qfrc_applied (nv,))."""
        ...

    def residual(self, data, ref: Reference, step: int, substeps: int) -> np.ndarray:
        """Generalised force (nv,) held over the simulation steps that end at ``step`` (counted from the
        start, ``substeps`` per control step, so at control time step / substeps): the root residual
        wrench in rows 0..5, any joint torques the controller adds for it in the rest."""
        ...

    def caps(self) -> tuple[float, float, float]:
        """The bounds :meth:`residual` holds the root wrench to: force norm (N), upward force (N), torque
        norm (N m); a residual at one of them is the most outside help the controller allows."""
        ...


def _foot_box_corners(model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every box on the feet: geom ids (G,), body ids (G,) and local bottom-corner offsets (G, 4, 3)."""
    import mujoco

    body = mujoco.mjtObj.mjOBJ_BODY
    feet = {mujoco.mj_name2id(model, body, n) for n in JOINT_NAMES if "ankle" in n or "foot" in n}
    geoms = [g for g in range(model.ngeom)
             if model.geom_bodyid[g] in feet and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX]  # fmt: skip
    local = [[[x, y, -sz] for x in (-sx, sx) for y in (-sy, sy)] for sx, sy, sz in model.geom_size[geoms]]
    local = np.array(local, dtype=np.float64).reshape(-1, 4, 3)
    return np.array(geoms, dtype=int), model.geom_bodyid[geoms].astype(int), local


def _pyramid(mu: float) -> np.ndarray:
    """(4, 3) edges of a friction pyramid with the floor normal +z (MuJoCo frame)."""
    return np.array([[mu, 0, 1], [-mu, 0, 1], [0, mu, 1], [0, -mu, 1]], dtype=np.float64)


def prepare_reference(model, qpos: np.ndarray, dt: float, config: TrackingConfig | None = None) -> Reference:
    """Velocities, body positions and feed-forward torques of a reference qpos series (N, 70) at step dt."""
    import mujoco

    cfg = config or TrackingConfig()
    qpos = np.asarray(qpos, dtype=np.float64)
    qvel = qvel_from_qpos(qpos, dt)
    qacc = np.gradient(qvel, dt, axis=0) if len(qpos) > 2 else np.zeros_like(qvel)
    lay = layout(model)

    inv = model  # the same model with contacts and limits switched off for the inverse pass
    data = mujoco.MjData(inv)
    n = len(qpos)
    joints = np.zeros((n, len(JOINT_NAMES), 3))
    tau = np.zeros((n, model.nv))
    geoms, bodies, local = _foot_box_corners(model)  # local: (boxes, 4 corners, 3)
    pyr = _pyramid(cfg.friction)
    jac = np.zeros((local.shape[0] * local.shape[1], 3, model.nv))  # at most every corner touches
    reg = 1e-3  # prefer small forces among the many that explain the wrench
    regs = {m: reg * np.eye(m) for m in range(4, 4 * len(jac) + 1, 4)}
    saved_flags = inv.opt.disableflags
    try:
        off = mujoco.mjtDisableBit
        inv.opt.disableflags = saved_flags | off.mjDSBL_CONTACT | off.mjDSBL_LIMIT
        for k in range(n):
            data.qpos[:], data.qvel[:], data.qacc[:] = qpos[k], qvel[k], qacc[k]
            mujoco.mj_inverse(inv, data)
            joints[k] = data.xpos[lay.body_ids]
            if not cfg.feedforward:
                continue
            t = data.qfrc_inverse.copy()
            rot = data.geom_xmat[geoms].reshape(-1, 3, 3)
            pts = data.geom_xpos[geoms][:, None] + local @ rot.transpose(0, 2, 1)  # (4, 4, 3) world corners
            low = pts[..., 2] < cfg.contact_height  # (4, 4) corners that can push
            count = 0
            for box, corner in zip(*np.nonzero(low)):
                mujoco.mj_jac(inv, data, jac[count], None, pts[box, corner], int(bodies[box]))
                count += 1
            if count:
                # Columns: root rows of J^T d for each pyramid edge d of each contact point.
                gen = np.einsum("pcv,ec->pev", jac[:count], pyr).reshape(-1, model.nv)  # (P*4, nv)
                a = gen[:, :6].T  # (6, P*4)
                target = np.concatenate([t[:6], np.zeros(a.shape[1])])
                c, _ = nnls(np.vstack([a, regs[a.shape[1]]]), target)
                t = t - c @ gen
            tau[k] = t
    finally:
        inv.opt.disableflags = saved_flags
    # Joint feed-forward cannot exceed what the joint could deliver anyway.
    limits = np.abs(model.actuator_forcerange[:, 1])
    tau[:, 6:] = np.clip(tau[:, 6:], -limits, limits)
    return Reference(qpos=qpos, qvel=qvel, joints_mj=joints, tau_ff=tau)


class ModelBasedTracker:
    """PD + inverse-dynamics feed-forward + bounded residual root wrench (see the module docstring).

    Joint targets change at the control rate; the root residual is a PD recomputed at every
    simulation step toward the reference interpolated in time. It must not live in the model as
    implicit ``dof_damping``: that damps the *absolute* root velocity, and once the bound clipped the
    ``kd * v_ref`` meant to cancel it, a 1.2 m/s walk was braked by ~1000 N and fell behind
    (measured). Explicit, the rotational damping must stay small: the pelvis alone is light
    (stability needs kd * dt / I < 2).
    """

    def __init__(self, model, config: TrackingConfig | None = None) -> None:
        self.model = model
        self.config = config or TrackingConfig()
        self.weight = float(model.body_subtreemass[0]) * STANDARD_GRAVITY
        self.max_force = self.config.residual_force * self.weight
        self.max_torque = self.config.residual_torque * self.weight * 1.0
        self.max_lift = self.config.residual_lift * self.weight
        # Position actuators in qpos order: actuator i drives dof 6 + i (see humanoid.build_mjcf).
        self.kp = model.actuator_gainprm[:, 0]
        self.kv = -model.actuator_biasprm[:, 2]
        self._limits = np.abs(model.actuator_forcerange[:, 1])
        feet = [model.body(n).id for n in JOINT_NAMES if "ankle" in n or "foot" in n]
        self._is_foot = np.zeros(model.nbody, dtype=bool)
        self._is_foot[feet] = True
        self._pyr = _pyramid(self.config.friction)
        self._fit_rows = np.array([1.0, 1.0, 1.0] + [self.config.feet_torque_weight] * 3)  # force, torque
        self.joints_through_actuators = self.config.feet_balance and self.config.feet_through_actuators

    def caps(self) -> tuple[float, float, float]:
        """Force, lift (N) and torque (N m) bounds of the root residual."""
        return self.max_force, self.max_lift, self.max_torque

    def act(self, data, ref: Reference, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Actuator targets for the control step k -> k+1 (ctrl (nu,); qfrc (nv,) is zero here).

        Velocity and torque feed-forward go in through the targets, so the actuators' force range
        clips PD and feed-forward together: added outside as qfrc_applied, an ankle's kv * qvel_ref
        alone reached 1600 N m and spun the 1 kg foot once the PD part saturated (measured).
        """
        nxt = min(k + 1, len(ref.qpos) - 1)
        ctrl = ref.qpos[nxt, 7:] + (self.kv * ref.qvel[nxt, 6:] + ref.tau_ff[k, 6:]) / self.kp
        return ctrl, np.zeros(self.model.nv)

    def residual(self, data, ref: Reference, step: int, substeps: int) -> np.ndarray:
        """Generalised force (nv,) for simulation step ``step`` (ending at control time step / substeps):
        rows 0..5 the residual root wrench in MuJoCo's free-joint convention (world force, local torque),
        clipped to the configured bounds; with ``feet_balance`` the legs' joint torques in the rest.

        This runs at every simulation step, in Python, so the reference side is precomputed
        (:meth:`Reference.root_targets`) and the torque is worked out in the pelvis frame, where the
        free joint wants it (a norm bound does not depend on the frame).
        """
        import mujoco

        cfg = self.config
        tgt = ref.root_targets(substeps)
        i = min(step, len(tgt.pos) - 1)
        px, py, pz, vx, vy, vz, fx, fy, fz, ox, oy, oz, tx, ty, tz = tgt.rows[i]
        q, v, r = data.qpos[:3].tolist(), data.qvel[:6].tolist(), data.xmat[1].tolist()  # r: pelvis, row-major
        # Plain floats, each term in the order the numpy expression (ff + kp * dx) + kd * dv would take,
        # so the result is bit-identical to it at a fraction of the cost.
        kp, kd = cfg.root_kp, cfg.root_kd
        force = [fx + kp * (px - q[0]) + kd * (vx - v[0]),
                 fy + kp * (py - q[1]) + kd * (vy - v[1]),
                 fz + kp * (pz - q[2]) + kd * (vz - v[2])]  # fmt: skip
        err = np.zeros(3)
        mujoco.mju_subQuat(err, tgt.quat[i], data.qpos[3:7])  # pelvis -> target, as a local rotation vector
        e = err.tolist()
        # Local frame: R^T omega_ref - omega.
        w = [ox * r[j] + oy * r[3 + j] + oz * r[6 + j] - v[3 + j] for j in range(3)]
        rkp, rkd = cfg.root_rot_kp, cfg.root_rot_kd
        torque = [tx + rkp * e[0] + rkd * w[0], ty + rkp * e[1] + rkd * w[1], tz + rkp * e[2] + rkd * w[2]]
        out = np.zeros(self.model.nv)
        if cfg.feet_balance:
            wrench = np.array(force + torque)
            joint, carried = self._through_feet(data, wrench)
            out[6:] = joint
            rest = (wrench - carried).tolist()
            force, torque = rest[:3], rest[3:]
        force = _clip_norm(force, self.max_force)
        force[2] = min(force[2], self.max_lift)  # MuJoCo z is up
        out[:6] = force + _clip_norm(torque, self.max_torque)
        return out

    def _through_feet(self, data, wrench: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint torques (nv - 6,) that make the feet on the floor push the root with as much of ``wrench``
        (6,) as the friction pyramid allows, and the root wrench (6,) they carry."""
        import mujoco

        n = data.ncon
        if n == 0:
            return np.zeros(self.model.nv - 6), np.zeros(6)
        pairs = data.contact.geom[:n]
        bodies = self.model.geom_bodyid[pairs[:, 1]]
        use = np.nonzero((pairs[:, 0] == 0) & self._is_foot[bodies])[0]
        if len(use) == 0:
            return np.zeros(self.model.nv - 6), np.zeros(6)
        jac = np.empty((len(use), 3, self.model.nv))
        for i, c in enumerate(use):
            mujoco.mj_jac(self.model, data, jac[i], None, data.contact.pos[c], int(bodies[c]))
        gen = np.einsum("pcv,ec->pev", jac, self._pyr).reshape(-1, self.model.nv)
        rows = self._fit_rows
        a = gen[:, :6].T * rows[:, None]
        m = a.shape[1]
        coef, _ = nnls(np.vstack([a, 1e-3 * np.eye(m)]), np.concatenate([wrench * rows, np.zeros(m)]))
        total = coef @ gen
        return np.clip(-total[6:], -self._limits, self._limits), total[:6]


def _clip_norm(v: list[float], bound: float) -> list[float]:
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return v if n <= bound or n == 0.0 else [x * (bound / n) for x in v]
