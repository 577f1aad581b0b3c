"""The physics projection P of PhysDiff: imitate a motion with the simulated humanoid, return the result.

``project(motion)`` builds a humanoid with the motion's own body (bone lengths, feet fitted to its
standing pose), retargets the joints to qpos, resamples them to the control rate, shapes that
reference (out of the floor, swing feet a little higher: :mod:`physmotion.physics.shaping`), runs the
tracking controller and resamples the simulated motion back to the input's frame rate. Morph's imitation
selection then keeps the simulated motion where its MPJPE stayed below ``tau`` and the input
otherwise, flagged.

Coordinates: input joints follow the data convention (floor at the lowest joint, as HumanML3D); the
humanoid's soles lie ``foot_lift`` (~1.5 cm) under its toe joints, so the reference is raised by that
much and the simulated joints come back in physical coordinates (soles on y = 0). MPJPE is measured
against that raised reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from physmotion.conventions import FPS
from physmotion.errors import ShapeError
from physmotion.physics.humanoid import (
    HumanoidConfig,
    PDGain,
    body_from_joints,
    build_model,
    default_gains,
    foot_lift,
)
from physmotion.physics.retarget import joints_to_qpos, qpos_to_joints
from physmotion.physics.shaping import ShapingConfig, shape_reference
from physmotion.physics.sim import Rollout, simulate
from physmotion.physics.tracking import ModelBasedTracker, TrackingConfig, prepare_reference
from physmotion.physics.workers import map_in_workers
from physmotion.skeleton import NUM_JOINTS


def _default_humanoid() -> HumanoidConfig:
    """The projection's humanoid: 360 Hz, ankles kp 1500, contacts 2.5 times as stiff as MuJoCo's default.

    Ankle gains, re-measured with everything else as below (2026-11-24). kp 5000 / 3000 / 2000 / 1500 /
    1200 / 1000 (kv = kp / 10): 96 generated motions projected once, Phys-Err 13.95 / 12.82 / 11.19 /
    10.43 / 10.33 / 10.33 mm (Skate 7.7 -> 6.1 mm at 1500, and the runs' Float 23.5 -> 19.2 mm), MPJPE
    72 / 80 / 83 / 82 / 84 / 84 mm. The 203 captured walks/runs (bench/projection_quality.py): kp 5000
    / 2000 / 1500 / 1000 tracked 99.5 / 99 / 97 / 95 % at 48.6 / 36.1 / 33.7 / 30.4 mm, Phys-Err 16.5
    / 11.0 / 10.1 / 8.5 mm. kp 1500 keeps a margin on the 95 %; kv 300 with it did worse (98 %, 45 mm,
    13.4 mm). The earlier choice of 5000 (below) predates reference shaping and the root residual's
    bounds. 240 Hz with kp 1500 still fails (17.2 mm on the 96 motions).

    Measured over all 203 walking/running clips of the bundled mocap (bench/projection_quality.py, with a
    grounded reference, before swing clearance): at 240 Hz with ankle kp 2000, 85 % tracked at 67 mm;
    360 Hz alone made it 96 %, and stiffer ankles then cut the error (kp 3000 / 4000 / 5000:
    99.5 / 98 / 98.5 % at 61 / 54 / 54 mm); 480 Hz was no better (93 %). The stiff ankle needs the
    small step: at 240 Hz kp 4000 tracked 74 %. A shorter contact time constant cuts the loaded soles'
    sinking (Penetrate ~2 mm at MuJoCo's 20 ms): 10 / 8 ms gave 1.03 / 0.87 mm at 99 / 97.5 % and
    56 / 58 mm (12 ms with ankle kp 4000: 1.11 mm; 8 ms is above MuJoCo's floor of two steps, 5.6 ms).
    With reference shaping and the 0.3 W residual bound: 98 % at 46 mm, Penetrate 0.72 mm (residual at
    every step; at every 4th, below: 99.5 % at 48 mm, Penetrate 0.75 mm).

    The root residual is updated at 90 Hz (every 4th step) and held between: per step 98 / 99 / 98.5 /
    99.5 % at 45.7 / 47.4 / 46.5 / 48.4 mm (every 1 / 2 / 3 / 4 steps), Phys-Err 16.8 / 17.2 / 16.3 /
    16.6 mm; every 6 / 12 steps the error grows (60 / 105 mm). On generated motions (model at step 3229)
    PhysDiff's Phys-Err was 15.5 / 15.3 / 15.3 mm (every 1 / 3 / 4). Fewer Python calls make P 1.18x
    faster (bench/physics.py).

    Hip and knee gains, tried on 32 generated motions projected once (14.2 mm with kp 1000, kv 100): kv
    200, 18.1 mm with 16 falls; kp 1500 / 700 (kv = kp / 10), 14.3 / 13.8 mm. The runs' Float stayed at
    19-22 mm in each.

    Also tried on 96 generated motions projected once (13.95 mm with ankle kp 5000; 2026-11-24):
    MuJoCo's noslip pass (4 iterations), 13.86 mm; floor friction 1.5 / 2.0, 14.46 / 16.48 mm (the feet
    catch, MPJPE 72 -> 87 / 107 mm, Skate up); 240 Hz with the residual every 2 / 4 steps, 16.95 /
    20.33 mm; the PGS / CG solvers, 14.00 / 13.63 mm, neither faster (CG 1.4x slower). With kp 1500 and the
    reset at 0.15 m (10.05 mm; runs 28.7 mm, Float 17.6 mm; 2026-11-24): contacts over-damped, damping
    ratio 1.5 / 2 / 3, 10.38 / 10.32 / 11.21 mm: the runs' Float drops to 15-16.5 mm, but the softer
    contact sinks (Penetrate 0.43 -> 0.74 / 1.08 / 1.74 mm) and Skate and MPJPE grow.
    """
    gains = default_gains()
    gains["ankle"] = PDGain(1500.0, 150.0, gains["ankle"].torque_limit)
    return HumanoidConfig(sim_dt=1.0 / 360.0, gains=gains, contact_solref=(0.008, 1.0), residual_every=4)


def _default_tracking() -> TrackingConfig:
    # Force bound 0.3 W, measured over all 203 walk/run clips with reference shaping: 0.5 / 0.3 / 0.2 /
    # 0.15 / 0.1 W tracked 100 / 98 / 97.5 / 94 / 88 % at 39.5 / 45.7 / 55.9 / 68.2 / 91.2 mm. 0.2 W
    # meets the targets (95 %, 60 mm) with little margin (26 of the clips: 77 mm with one
    # failure), 0.3 W with room; on generated motions PhysDiff's Phys-Err is 15.5 mm at 0.3 W and 14.7
    # at 0.2 W (32 prompts). Before reference shaping 0.5 W was needed. Upward force is capped at 0.1 W
    # so the residual cannot hold a floating body up (at 1 W the simulated walks floated more than their
    # input). Torque 1 W x 1 m: at 0.5 the backward and tired walks tipped over once the torque
    # saturated (5 of 6 such failures tracked at 1.0).
    # Not kept (96 generated motions projected once: 13.95 mm with these, ankle kp 5000): the downward
    # residual capped at 0.1 / 0 W, 14.20 / 14.58 mm (runners float more without the pull); a vertical
    # centre-of-mass PD through the stance legs' Jacobians (virtual model control, 400 / s^2, 40 / s, at the
    # control rate; at 90 Hz on 32 motions the runs' Float stayed at 19-21 mm), 13.75 mm with MPJPE 72 -> 67
    # mm; PD targets one control step further ahead (against the tracker's lag), 14.12 mm; on 32 of them (14.2
    # mm with these), upward residual 0.2 / 0.3 W, 13.9 / 13.5 mm, root kd 3000, 13.2 mm, elliptic friction
    # cones with impratio 10, 13.6 mm, and planting a foot that touches the floor while its reference moves
    # slower than 0.5 / 0.8 m/s (leg IK at the control rate), 14.5 / 14.8 mm: none lowered Phys-Err beyond the
    # noise. Re-measured on the 96 (2026-11-24): force bound 0.5 / 0.2 W, 14.24 / 14.19 mm (MPJPE 48 / 108
    # mm). The feed-forward's contact split solved at run time over the foot corners near the floor in the
    # simulation (or in either), so stance torques follow the body's own contacts rather than the reference's
    # timing: 14.67 / 14.35 mm (the runs' Float unchanged).
    return TrackingConfig(residual_force=0.3, residual_torque=1.0, residual_lift=0.1,
                          root_kp=10000.0, root_kd=1000.0, root_rot_kp=3000.0, root_rot_kd=30.0)


@dataclass
class ProjectionConfig:
    """Everything P depends on."""

    humanoid: HumanoidConfig = field(default_factory=_default_humanoid)
    tracking: TrackingConfig = field(default_factory=_default_tracking)
    tau: float = 0.5  # m: Morph's imitation selection keeps the simulation while MPJPE < tau
    # Processes for a batch, 0: one per core. Each motion is projected whole in one worker process
    # (physics/workers.py): the tracker is Python and holds the GIL, so threads gained little.
    workers: int = 0
    # False: Morph's imitation selection (a failed episode returns the input, flagged). True: put the
    # humanoid back on the reference where it fails and go on, so the output is always simulated; PhysDiff
    # sampling uses this, because a kept kinematic input would carry its artefacts to the next step.
    reset_on_fail: bool = False
    # With reset_on_fail: where the body has only drifted from the reference (its pose, horizontal offset
    # taken out, is within tau), move the rest of the reference to it instead of resetting it.
    follow_drift: bool = True
    # What the tracker is asked to follow: the reference out of the floor, swing feet a little higher
    # (physics/shaping.py has the measurements).
    shaping: ShapingConfig = field(default_factory=ShapingConfig)


@dataclass
class ProjectedMotion:
    """The result of :func:`project` for a batch of B motions of T frames at the input fps.

    joints: (B, T, 22, 3) float32, the simulated motion where ``selected``, else the input.
    simulated: (B, T, 22, 3) float32, the simulated motion whatever happened.
    mpjpe: (B, T) metres, per-frame mean joint error of the simulation to the (raised) input.
    residual_force, residual_torque: (B, T) root residual used, fractions of W and W x 1 m.
    contacts: (B, T, 4) bool, left ankle, left foot, right ankle, right foot on the floor.
    success: (B,) the episode ran to the end without MPJPE passing the failure threshold.
    With ``follow_drift`` a body that only drifted counts as a success; its ``mpjpe`` to the input grows.
    selected: (B,) the simulation was kept (MPJPE below ``tau`` throughout).
    body: (B, 22, 3) float64 rest offsets of the humanoid each motion was simulated with (bone lengths,
    fitted feet): the surface to measure the simulated motion on (``HumanoidSurface(body)``).
    """

    joints: np.ndarray
    simulated: np.ndarray
    mpjpe: np.ndarray
    residual_force: np.ndarray
    residual_torque: np.ndarray
    contacts: np.ndarray
    success: np.ndarray
    selected: np.ndarray
    body: np.ndarray


def as_joints(motion: np.ndarray) -> tuple[np.ndarray, bool]:
    """Joints (B, T, 22, 3) float64 from joints or HumanML3D features (263 or 329, not normalised).

    Returns (joints, batched). Raises ShapeError for other shapes, NaN/inf, fewer than 2 frames.
    """
    x = np.asarray(motion)
    if x.ndim in (2, 3) and x.shape[-1] in (263, 329):
        from physmotion.features.biomech import to_263
        from physmotion.features.humanml3d import recover_from_ric

        batched = x.ndim == 3
        feats = x if x.shape[-1] == 263 else to_263(x)
        if not np.all(np.isfinite(feats)):
            raise ShapeError("features contain NaN or infinite values")
        x = recover_from_ric(np.asarray(feats, dtype=np.float64))
        x = x if batched else x[None]
    elif x.ndim in (3, 4) and x.shape[-2:] == (NUM_JOINTS, 3):
        batched = x.ndim == 4
        x = x if batched else x[None]
    else:
        raise ShapeError(
            f"motion must be joints (T, 22, 3) / (B, T, 22, 3) or features (.., T, 263|329), got {x.shape}"
        )
    if not np.all(np.isfinite(x)):
        raise ShapeError("motion contains NaN or infinite values")
    if x.shape[1] < 2:
        raise ShapeError(f"motion needs at least 2 frames, got {x.shape[1]}")
    return x.astype(np.float64), batched


def resample_qpos(qpos: np.ndarray, fps_in: float, fps_out: float, count: int | None = None) -> np.ndarray:
    """qpos (T, 70) at fps_in -> (N, 70) at fps_out over the same span (or ``count`` frames, the
    last ones held): hinges and root position linearly, the root quaternion by slerp."""
    t_in = np.arange(len(qpos)) / fps_in
    n = count if count is not None else int(np.floor(t_in[-1] * fps_out + 1e-9)) + 1
    t_out = np.minimum(np.arange(n) / fps_out, t_in[-1])
    out = np.empty((n, qpos.shape[1]))
    for i in [0, 1, 2, *range(7, qpos.shape[1])]:
        out[:, i] = np.interp(t_out, t_in, qpos[:, i])
    rots = Rotation.from_quat(qpos[:, 3:7], scalar_first=True)
    out[:, 3:7] = Slerp(t_in, rots)(t_out).as_quat(scalar_first=True)
    return out


def project(
    motion: np.ndarray,
    fps: float = FPS,
    config: ProjectionConfig | None = None,
) -> ProjectedMotion:
    """PhysDiff's projection P of a motion or a batch (joints or un-normalised features).

    motion: (T, 22, 3) / (B, T, 22, 3) joints, metres, Y up, floor at the lowest joint, or HumanML3D
    features (T, 263|329) / (B, T, 263|329). fps: its frame rate. Deterministic: the same input gives
    the same output, and a batch gives what its motions give one by one.
    """
    cfg = config or ProjectionConfig()
    joints, batched = as_joints(motion)
    if not fps > 0:
        raise ShapeError(f"fps must be positive, got {fps}")
    outs = map_in_workers(partial(_project_one, fps=fps, config=cfg), list(joints), cfg.workers)
    stacked = {k: np.stack([o[k] for o in outs]) for k in outs[0]}
    result = ProjectedMotion(**stacked)
    if not batched:
        result = ProjectedMotion(**{k: v[0] for k, v in stacked.items()})
    return result


def _project_one(x: np.ndarray, fps: float, config: ProjectionConfig) -> dict[str, np.ndarray]:
    """P of one motion x (T, 22, 3) float64: the fields of :class:`ProjectedMotion` for it."""
    ctrl_fps = 1.0 / config.humanoid.control_dt  # the reference and the simulation run at the control rate
    body = body_from_joints(x, fps)
    model = build_model(body, config.humanoid)
    lift = foot_lift(body, config.humanoid)
    qpos = resample_qpos(joints_to_qpos(x, model, lift=lift, config=config.humanoid), fps, ctrl_fps)
    qpos = shape_reference(model, qpos, config.humanoid.control_dt, config.shaping)
    ref = prepare_reference(model, qpos, config.humanoid.control_dt, config.tracking)
    tracker = ModelBasedTracker(model, config.tracking)
    roll = simulate(model, ref, tracker, config.humanoid, fail_mpjpe=config.tau,
                    reset_on_fail=config.reset_on_fail, follow_drift=config.follow_drift)
    out = _back_to_input_rate(roll, model, lift, x, fps, ctrl_fps, config.tau, config.reset_on_fail)
    return out | {"body": body}


def _back_to_input_rate(
    roll: Rollout, model, lift: float, joints: np.ndarray, fps: float, ctrl_fps: float, tau: float,
    keep_simulated: bool = False,
) -> dict[str, np.ndarray]:
    """One rollout (control rate) as arrays at the input rate, with imitation selection applied (unless
    ``keep_simulated``: then the simulation, reset where it failed, is always returned)."""
    t = len(joints)
    sim = qpos_to_joints(resample_qpos(roll.qpos, ctrl_fps, fps, count=t), model)
    raised = joints + np.array([0.0, lift, 0.0])
    mpjpe = np.linalg.norm(sim - raised, axis=-1).mean(-1)
    nearest = np.minimum(np.round(np.arange(t) * ctrl_fps / fps).astype(int), len(roll.qpos) - 1)
    success = roll.failed_at is None
    selected = keep_simulated or (success and float(mpjpe.max()) < tau)
    return {
        "joints": (sim if selected else joints).astype(np.float32),
        "simulated": sim.astype(np.float32),
        "mpjpe": mpjpe,
        "residual_force": roll.residual_force[nearest],
        "residual_torque": roll.residual_torque[nearest],
        "contacts": roll.contacts[nearest],
        "success": np.array(success),
        "selected": np.array(selected),
    }
