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

import multiprocessing
import os
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import lru_cache, partial

import numpy as np

from physmotion.conventions import FPS
from physmotion.errors import ShapeError
from physmotion.features.biomech import FEATURE_DIM_BIOMECH, to_263
from physmotion.features.humanml3d import FEATURE_DIM, recover_from_ric
from physmotion.physics.humanoid import HumanoidConfig, body_from_joints, build_model, foot_lift, layout
from physmotion.physics.retarget import joints_to_qpos, qpos_at, qpos_to_joints, reach_arm_ends
from physmotion.physics.search import SearchConfig, SearchController, search_humanoid
from physmotion.physics.shaping import ShapingConfig, flights, shape_reference
from physmotion.physics.surface import body_lowest, pose_frames
from physmotion.physics.sim import FlightCheck, Recover, Recovery, Rollout, simulate
from physmotion.physics.tracking import ModelBasedTracker, TrackingConfig, prepare_reference
from physmotion.physics.workers import map_in_workers, worker_count
from physmotion.skeleton import NUM_JOINTS


@dataclass
class ProjectionConfig:
    """Everything P depends on."""

    humanoid: HumanoidConfig = field(default_factory=HumanoidConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
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
    # With reset_on_fail and follow_drift: where the body is lower than the motion and its pose is within
    # tau once the whole offset is taken out, it fell short of a flight (a jump's push comes up short):
    # let it land instead of resetting it into the air (docs/decisions/sampling.md: "let a short jump land").
    let_land: bool = True
    # What the tracker is asked to follow: the reference out of the floor, swing feet a little higher
    # (physics/shaping.py has the measurements).
    shaping: ShapingConfig = field(default_factory=ShapingConfig)
    # A motion whose lowest point stays more than ``support_height`` above the floor for longer than
    # ``unsupported_seconds`` is not grounded: something we do not simulate holds it up (a chair, a bar,
    # a ladder), as Morph's hand-flagged non-grounded motions. Imitation selection rejects it, rather
    # than keep the humanoid's imitation of it on the floor. A jump's flight lasts well under a second.
    support_height: float = 0.10  # m
    unsupported_seconds: float = 1.0
    # Iterative learning control, for offline projection (``project --ilc``): after each simulation the
    # root's position error (reference - simulated) times ``ilc_gain`` is added to the reference and the
    # motion is simulated again, ``ilc_passes`` times; the pass closest to the input (mean MPJPE, a
    # success before a failure) is kept. Costs passes + 1 simulations. Root only: with the hinges and the
    # orientation fed forward too, runs tracked worse or fell (docs/decisions/projection.md: "iterative
    # learning control for offline projection").
    ilc_passes: int = 0
    ilc_gain: float = 0.5
    # Who drives the humanoid: the model-based tracker, or the learned imitation policy over it
    # (physics/policy.py), loaded from ``policy`` (a folder; None: the shipped one). The policy brings its
    # own tracker settings and residual cap; ``tracking`` applies to the tracker only.
    # "search": no outside hand at all, the body's own joint targets searched (physics/search.py), at the
    # effort of ``search``; slow (seconds per second of motion), for offline projection and Morph's data.
    # With ``policy`` set, the search is amortized: that policy proposes each window's first mean.
    controller: str = "tracker"
    policy: str | None = None
    search: SearchConfig = field(default_factory=SearchConfig)
    # With reset_on_fail: seconds before each reset over which the output is cross-faded from the falling
    # simulation onto the motion it is put back on, so no frame jumps (docs/decisions/projection.md: "resets
    # as frames, cross-faded"). Those frames are not simulated: ``ProjectedMotion.reset_frames`` marks them.
    crossfade: float = 0.25
    # The search as the tracker's fallback: a motion the tracker (or the policy) had to reset, failed, or
    # whose flight it kept less than ``fallback_flight`` of (flight as ``metrics.actions.flight_height``)
    # is projected again by the search at the effort of ``search``, with no outside hand, and the search's
    # output is kept unless it was reset more often. Motions the tracker follows cost what they did; the
    # ones it flattens or teleports cost the search's seconds per second of motion
    # (docs/decisions/projection.md: "the search as the tracker's fallback").
    fallback: bool = False
    fallback_flight: float = 0.8
    # With reset_on_fail: where the tracker (or the policy) would reset the body, the search first tries to
    # carry it with no outside hand from ``recover_back`` seconds before that step to ``recover_ahead``
    # seconds after it, starting from the simulation's own state there; only where the search falls too is
    # the body reset. Costs the search's seconds per second of motion for those stretches alone
    # (docs/decisions/projection.md: "the search in place of a reset"). Where the search falls, it tries
    # once more from ``recover_retry_back`` seconds before the step (0: no second try), before the reset.
    recover: bool = False
    recover_back: float = 0.5
    recover_ahead: float = 0.5
    recover_retry_back: float = 1.0
    # With recover: where the body has cleared the floor by less than ``rescue_flight`` x the shaped
    # reference's clearance just past a flight's highest (a flight of at least
    # ``metrics.dynamics.MIN_FLIGHT``), the search re-does that take-off the same way (no outside hand),
    # kept where the body flies higher in it.
    # The tracker's take-off speed turns on small details of the body and its contacts (docs/limitations.md);
    # 0: off (docs/decisions/projection.md: "the search where a take-off falls short").
    rescue_flight: float = 0.0
    # A first frame off the path of the next ones (its fastest joint moves into frame 1 more than
    # ``first_frame_margin`` beyond the fastest move of frame 1 -> 2: a denoiser's boundary artefact) is
    # replaced by the pose extrapolated back from frames 1 and 2 before P starts the body there; else the
    # output carries the jump (docs/decisions/sampling.md: "P starts from the motion's own path").
    mend_first_frame: bool = False
    first_frame_margin: float = 0.02  # m
    # Fit each arm to the body's bone lengths with its wrist kept (``retarget.reach_arm_ends``) before the
    # bone directions are copied: a generated arm whose bones change length otherwise swings its wrist
    # faster than the motion does. Captured clips' rigid bones pass through unchanged
    # (docs/decisions/projection.md: "arms fitted to the body's bones, the default").
    reach_arms: bool = True
    # Record the largest frame step of the reference P tracked (``ProjectedMotion.reference_step``, NaN when
    # off), which tells P's retargeting and shaping from its simulation (experiments/step_jumps). One more
    # forward kinematics of the whole motion, about 2 % of a P, so off unless asked for.
    record_reference_step: bool = False

    def __post_init__(self) -> None:
        if not 0.0 <= self.crossfade <= 2.0:
            raise ShapeError(f"crossfade must be in 0..2 seconds, got {self.crossfade}")
        if not (isinstance(self.ilc_passes, int) and 0 <= self.ilc_passes <= 20):
            raise ShapeError(f"ilc_passes must be an integer in 0..20, got {self.ilc_passes}")
        if not 0.0 < self.ilc_gain <= 1.0:
            raise ShapeError(f"ilc_gain must be in (0, 1], got {self.ilc_gain}")
        if self.controller not in CONTROLLERS:
            raise ShapeError(f"controller must be one of {', '.join(CONTROLLERS)}, got {self.controller!r}")
        if self.ilc_passes and self.reset_on_fail:  # a reset or a moved reference is no error to learn from
            raise ShapeError("ilc_passes needs a projection that does not reset the body where it falls "
                             "(the plain preset)")
        if self.ilc_passes and self.controller == "search":  # the search corrects the body itself, per window
            raise ShapeError("ilc_passes is for the tracker and the policy, not the search controller")
        if self.fallback and self.controller == "search":
            raise ShapeError("the search fallback is for the tracker and the policy; the search has none")
        if not self.first_frame_margin >= 0.0:
            raise ShapeError(f"first_frame_margin must be >= 0 metres, got {self.first_frame_margin}")
        if self.recover and (self.controller == "search" or not self.reset_on_fail):
            raise ShapeError("recover replaces the tracker's or the policy's resets: it needs reset_on_fail and "
                             "another controller than the search")
        spans = (self.recover_back, self.recover_ahead, self.recover_retry_back)
        if not all(0.0 <= s <= 5.0 for s in spans):
            raise ShapeError("recover_back, recover_ahead and recover_retry_back must be in 0..5 seconds, got "
                             + ", ".join(f"{s:g}" for s in spans))
        if not 0.0 <= self.rescue_flight <= 1.0:
            raise ShapeError(f"rescue_flight must be in 0..1, got {self.rescue_flight}")
        if self.rescue_flight and not self.recover:
            raise ShapeError("rescue_flight hands short take-offs to the search of recover: it needs recover")
        if not 0.0 <= self.fallback_flight <= 1.0:
            raise ShapeError(f"fallback_flight must be in 0..1, got {self.fallback_flight}")

    def with_controller(self, controller: str, policy: str | None = None,
                        search: SearchConfig | None = None) -> ProjectionConfig:  # fmt: skip
        """This P driven by ``controller`` ("tracker", "policy" loaded from ``policy``, or "search" at the
        effort ``search``, the default one if None). The search runs on :func:`search_humanoid`'s body (the
        elliptic friction cone, a hand that ends at the knuckles); the tracker's keeps MuJoCo's default cone
        and PHC's hand, as its figures were measured."""
        humanoid = self.humanoid
        if controller == "search":
            humanoid = search_humanoid(humanoid)
        return replace(self, controller=controller, policy=policy, search=search or self.search, humanoid=humanoid,
                       fallback=self.fallback and controller != "search",  # the search has no fallback
                       recover=self.recover and controller != "search",  # nor anyone to recover it
                       rescue_flight=0.0 if controller == "search" else self.rescue_flight)

    def residual_bound(self) -> float:
        """The cap on the root residual's force (x body weight) of whoever drives the humanoid: the
        tracker's ``tracking.residual_force``, the policy's own tracker settings at its cap, or 0 for the
        search (no outside hand)."""
        if self.controller == "search":
            return 0.0
        if self.controller == "tracker":
            return self.tracking.residual_force
        from physmotion.physics.policy import capped_tracking, load_policy

        settings = load_policy(self.policy).settings
        return capped_tracking(settings.tracking, settings.cap).residual_force

    @classmethod
    def sampling(cls, **overrides) -> ProjectionConfig:
        """The preset generation uses (physdiff and post): a fall (error past tau = 0.15 m) puts the
        humanoid back on the motion, or moves the motion to it where it only drifted or lets it land where
        it only fell short of a flight, so P always returns a simulated motion; each reset is counted
        (``ProjectedMotion.resets``). tau 0.15 m beat 0.2-0.5 m on PhysDiff's Phys-Err
        (docs/decisions/sampling.md: "sampling projection: reset at 0.15 m").

        The root wrench is not carried by the feet here (``TrackingConfig.feet_balance`` off): on the
        denoiser's intermediate motions it doubled the share of outputs with a reset
        (docs/decisions/projection.md: "balance through the feet"). The residual keeps its 0.3 W bound, its
        90 Hz hold and no ballistic flight phases: every generation figure was measured so, and the plain
        projection's changes of "residual within 0.1 W on walks and runs" were measured on captured motion
        only.

        A generated frame often hovers a centimetre or two over the floor, so the swing feet are lifted
        against the frame's lowest point (``ShapingConfig.hover_support``; docs/decisions/sampling.md:
        "support judged against a hovering frame in the sampling preset"); the plain projection keeps the
        floor rule, which captured runs read better.

        A generated jump often leaves the floor too slowly for the flight it then has; the rise into it is
        played faster (``ShapingConfig.push_off``; docs/decisions/projection.md: "a push-off fast enough for
        the flight"). The plain projection, run on captured motion, keeps it off.

        Where the tracker falls, the search first carries the body with no outside hand (``recover``), so
        that an output is simulated throughout rather than put back on the motion; it costs the search's
        seconds for those stretches alone (docs/decisions/projection.md: "the search in place of a reset")."""
        defaults = {
            "reset_on_fail": True,
            "tau": 0.15,
            "tracking": TrackingConfig(feet_balance=False, residual_force=0.3),
            "humanoid": HumanoidConfig(residual_every=4),
            "shaping": ShapingConfig(ballistic_flight=False, hover_support=0.05, push_off=True),
            "mend_first_frame": True,
            "recover": True,
        }
        return cls(**{**defaults, **overrides})

    def at_fine_step(self) -> ProjectionConfig:
        """This P simulated at half the step (1/720 s for the default 1/360 s): twice the simulation steps
        (1.2x the wall time of the plain P over the 369 captured clips); the root residual is held over
        twice as many steps, so it still changes at the same rate. On captured runs the contacts resolve
        better: Float 15.0 -> 9.7 mm, MPJPE 50.2 -> 40.6 mm. An option (``physmotion project
        --fine-step``, ``generate --fine-step``), not the default: 2 of the 123 captured walks fail under
        the plain P at this step, and PhysDiff costs more than the issue allows (docs/decisions/projection.md:
        "the finer step as an option for the plain P")."""
        h = self.humanoid
        return replace(self, humanoid=replace(h, sim_dt=h.sim_dt / 2, residual_every=2 * h.residual_every))


CONTROLLERS = ("tracker", "policy", "search")


@dataclass
class ProjectedMotion:
    """The result of :func:`project` for a batch of B motions of T frames at the input fps.

    joints: (B, T, 22, 3) float32, the simulated motion where ``selected``, else the input.
    simulated: (B, T, 22, 3) float32, the simulated motion whatever happened.
    mpjpe: (B, T) metres, per-frame mean joint error of the simulation to the (raised) input.
    residual_force, residual_torque: (B, T) root residual used, fractions of W and W x 1 m: the mean over
    the frame's control steps (the residual updates within them).
    residual_force_peak, residual_torque_peak: (B, T) the largest residual of any update within them.
    at_cap: (B, T) bool, frames in which some residual update was held at a cap (force, lift or torque).
    reset_frames: (B, T) bool, frames that are not the simulation where it is returned: each reset's frame
    and the ``ProjectionConfig.crossfade`` seconds before it, cross-faded onto the motion it is put back on.
    contacts: (B, T, 4) bool, left ankle, left foot, right ankle, right foot on the floor.
    success: (B,) the episode ran to the end without MPJPE passing the failure threshold.
    resets: (B,) int, how often the humanoid was put back on the reference (``reset_on_fail``): each is a
    jump (teleport) in ``simulated``, cross-faded in ``joints``.
    With ``follow_drift`` a body that only drifted (or, with ``let_land``, fell short of a flight) counts as
    a success; its ``mpjpe`` to the input grows.
    selected: (B,) the simulation was kept (MPJPE below ``tau`` throughout, and the motion grounded).
    ilc_pass: (B,) int, which simulation was kept with ``ProjectionConfig.ilc_passes`` (0: the first).
    grounded: (B,) the input never stays off the floor for long (``ProjectionConfig.support_height``,
    ``unsupported_seconds``); a motion that does is rejected by imitation selection whatever its MPJPE.
    body: (B, 22, 3) float64 rest offsets of the humanoid each motion was simulated with (bone lengths,
    fitted feet): the surface to measure the simulated motion on (``HumanoidSurface(body)``).
    over_limit: (B, T) bool, frames in which a hinge's total torque (actuator plus the joint torques the
    tracker's feet-balance path applies directly) passed the actuator's force limit: the actuators alone
    are bounded, that path is not (:func:`~physmotion.physics.sim.control_step`).
    searched: (B,) bool, the search made the motion (``controller`` "search", or as the tracker's
    ``fallback``): no outside hand on it.
    recovered: (B,) int, stretches the search carried in place of a reset (``ProjectionConfig.recover``) or
    re-did where a take-off fell short (``rescue_flight``);
    recovered_frames: (B, T) bool, frames all of whose control steps the search simulated: no outside hand.
    reference_step: (B,) metres, the largest frame-to-frame joint move of the reference P tracked (the input
    retargeted onto the humanoid and shaped, at the input rate): a jump in the output that the reference
    already makes is P's retargeting or shaping, not its simulation. NaN unless
    ``ProjectionConfig.record_reference_step``.
    teacher_obs, teacher_offsets: with the search controller only, per control step of the simulation
    (B, N, 599) float32 the observation a policy would see (:func:`physmotion.physics.policy.observe`, cap
    0) and (B, N, 63) the joint-target offsets the search committed (rad): a policy's teacher labels.
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
    resets: np.ndarray
    grounded: np.ndarray
    ilc_pass: np.ndarray
    over_limit: np.ndarray
    residual_force_peak: np.ndarray
    residual_torque_peak: np.ndarray
    at_cap: np.ndarray
    reset_frames: np.ndarray
    searched: np.ndarray
    recovered: np.ndarray
    recovered_frames: np.ndarray
    reference_step: np.ndarray
    teacher_obs: np.ndarray | None = None
    teacher_offsets: np.ndarray | None = None

    @property
    def residual(self) -> np.ndarray:
        """(..., T, 2) float32: residual force and torque per frame, as :attr:`Motion.residual` stores it."""
        return np.stack([self.residual_force, self.residual_torque], axis=-1).astype(np.float32)

    @property
    def residual_peak(self) -> np.ndarray:
        """(..., T, 2) float32: the per-frame peaks, as :attr:`Motion.residual_peak` stores them."""
        return np.stack([self.residual_force_peak, self.residual_torque_peak], axis=-1).astype(np.float32)

    def record(self, k: int | None = None) -> SimRecord:
        """The simulation record of motion ``k`` of a batch (None: of an unbatched result)."""
        at = (lambda a: a) if k is None else (lambda a: a[k])
        return SimRecord(int(at(self.resets)), at(self.residual), at(self.residual_peak),
                         at(self.at_cap).astype(bool), at(self.over_limit).astype(bool),
                         at(self.reset_frames).astype(bool), bool(at(self.searched)),
                         int(at(self.recovered)))  # fmt: skip


@dataclass
class SimRecord:
    """What P recorded of one motion's simulation, as :class:`~physmotion.motion.Motion` stores it.

    resets: times the humanoid was put back on the motion; residual, residual_peak: (T, 2) float32 root
    residual per frame, mean and peak (force x W, torque x W x 1 m); at_cap: (T,) bool, a residual update
    held at a cap; over_limit: (T,) bool, a joint's torque past its actuator's limit; reset_frames: (T,)
    bool, frames not simulated (a reset and the cross-fade before it); searched: the search made it
    (``ProjectionConfig.controller`` or ``fallback``); recovered: stretches the search carried, with no
    outside hand, where the humanoid would have been reset (``ProjectionConfig.recover``) or a take-off fell
    short (``rescue_flight``)."""

    resets: int
    residual: np.ndarray
    residual_peak: np.ndarray
    at_cap: np.ndarray
    over_limit: np.ndarray
    reset_frames: np.ndarray
    searched: bool = False
    recovered: int = 0

    def after(self, earlier: SimRecord | None) -> SimRecord:
        """This record of P's output following ``earlier`` P calls on the same motion (PhysDiff's calls in
        sampling, post's passes): the resets of every call counted, their frames marked, a search in any
        call noted."""
        if earlier is None:
            return self
        return replace(self, resets=self.resets + earlier.resets, searched=self.searched or earlier.searched,
                       reset_frames=self.reset_frames | earlier.reset_frames,
                       recovered=self.recovered + earlier.recovered)  # fmt: skip

    def motion_fields(self, cap: float) -> dict:
        """Keyword arguments of :class:`~physmotion.motion.Motion` for this record under a P whose force
        cap is ``cap`` (x W)."""
        return dict(resets=int(self.resets), residual=self.residual, residual_cap=cap, over_limit=self.over_limit,
                    residual_peak=self.residual_peak, residual_at_cap=self.at_cap,
                    reset_frames=self.reset_frames, searched=self.searched, recovered=int(self.recovered))  # fmt: skip


def as_joints(motion: np.ndarray) -> tuple[np.ndarray, bool]:
    """Joints (B, T, 22, 3) float64 from joints or HumanML3D features (263 or 329, not normalised).

    Returns (joints, batched). Raises ShapeError for other shapes, NaN/inf, fewer than 2 frames.
    """
    x = np.asarray(motion)
    if x.ndim in (2, 3) and x.shape[-1] in (FEATURE_DIM, FEATURE_DIM_BIOMECH):
        batched = x.ndim == 3
        feats = x if x.shape[-1] == FEATURE_DIM else to_263(x)
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
    last = (len(qpos) - 1) / fps_in
    n = count if count is not None else int(np.floor(last * fps_out + 1e-9)) + 1
    return qpos_at(qpos, np.minimum(np.arange(n) / fps_out, last), fps_in)


def project(
    motion: np.ndarray,
    fps: float = FPS,
    config: ProjectionConfig | None = None,
    on_step: Callable[[int, int], None] | None = None,
) -> ProjectedMotion:
    """PhysDiff's projection P of a motion or a batch (joints or un-normalised features).

    motion: (T, 22, 3) / (B, T, 22, 3) joints, metres, Y up, floor at the lowest joint, or HumanML3D
    features (T, 263|329) / (B, T, 263|329). fps: its frame rate. Deterministic: the same input gives
    the same output, and a batch gives what its motions give one by one.
    on_step(done, total): progress over control steps, for the search controller on a single motion (the
    slow case; a batch's motions run in worker processes, which report nothing).
    """
    cfg = config or ProjectionConfig()
    joints, batched = as_joints(motion)
    if not fps > 0:
        raise ShapeError(f"fps must be positive, got {fps}")
    if (cfg.controller == "search" or cfg.fallback or cfg.recover) and not cfg.search.threads:  # the search's threads share the cores
        inside_worker = multiprocessing.current_process().daemon  # a caller's worker: its siblings use the rest
        per_worker = 1 if inside_worker else max(1, (os.cpu_count() or 1) // worker_count(cfg.workers, len(joints)))
        cfg = replace(cfg, search=replace(cfg.search, threads=per_worker))
    if len(joints) == 1 and on_step is not None:
        outs = [_project_one(joints[0], fps, cfg, on_step)]
    else:
        outs = map_in_workers(partial(_project_one, fps=fps, config=cfg), list(joints), cfg.workers)
    stacked = {k: np.stack([o[k] for o in outs]) for k in outs[0]}
    result = ProjectedMotion(**stacked)
    if not batched:
        result = ProjectedMotion(**{k: v[0] for k, v in stacked.items()})
    return result


@dataclass
class PreparedMotion:
    """One motion made ready to simulate: the humanoid with its body and the shaped reference.

    body: (22, 3) rest offsets; model: its ``mujoco.MjModel``; lift: metres its soles lie under the toe
    joints; target: (N, 70) shaped reference qpos at the control rate; grounded: see ``ProjectedMotion``.
    """

    body: np.ndarray
    model: object
    lift: float
    target: np.ndarray
    grounded: bool


def prepare_motion(x: np.ndarray, fps: float, config: ProjectionConfig) -> PreparedMotion:
    """The humanoid and the shaped control-rate reference for one motion x (T, 22, 3) float64 at ``fps``,
    as P simulates it (the learned imitator trains on exactly these)."""
    ctrl_fps = 1.0 / config.humanoid.control_dt  # the reference and the simulation run at the control rate
    body = body_from_joints(x, fps)
    model = build_model(body, config.humanoid)
    lift = foot_lift(body, config.humanoid)
    arms = reach_arm_ends(x, layout(model).offsets) if config.reach_arms else x
    qpos = resample_qpos(joints_to_qpos(arms, model, lift=lift, config=config.humanoid), fps, ctrl_fps)
    grounded = _grounded(model, qpos, ctrl_fps, config)
    target = shape_reference(model, qpos, config.humanoid.control_dt, config.shaping)
    return PreparedMotion(body, model, lift, target, grounded)


def _controller(model, config: ProjectionConfig):
    """The controller P runs on ``model``: the model-based tracker, or the learned policy over it."""
    if config.controller == "tracker":
        return ModelBasedTracker(model, config.tracking)
    return _policy(config.policy).controller(model)


@lru_cache(maxsize=4)
def _policy(path: str | None):
    """The policy in ``path`` (None: the shipped one), read once per process."""
    from physmotion.physics.policy import load_policy

    return load_policy(path)


def _project_one(x: np.ndarray, fps: float, config: ProjectionConfig,
                 on_step: Callable[[int, int], None] | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """P of one motion x (T, 22, 3) float64: the fields of :class:`ProjectedMotion` for it."""
    if config.mend_first_frame:
        x = mend_first_frame(x, config.first_frame_margin)
    ctrl_fps = 1.0 / config.humanoid.control_dt
    prep = prepare_motion(x, fps, config)
    body, model, lift, target, grounded = prep.body, prep.model, prep.lift, prep.target, prep.grounded
    step = _reference_step(prep, len(x), fps, ctrl_fps) if config.record_reference_step else np.array(np.nan)
    ref_field = {"reference_step": step}
    if config.controller == "search":
        return _search_one(prep, x, fps, config, on_step) | {"searched": np.array(True)} | ref_field
    tracker = _controller(model, config)  # holds no episode state: one serves every pass
    reference, best = target, None
    checks = _flight_checks(model, target, config)
    for ilc_pass in range(config.ilc_passes + 1):
        ref = prepare_reference(model, reference, config.humanoid.control_dt, config.tracking)
        roll = simulate(model, ref, tracker, config.humanoid, fail_mpjpe=config.tau,
                        reset_on_fail=config.reset_on_fail, follow_drift=config.follow_drift,
                        let_land=config.let_land, recover=_recovery(model, config) if config.recover else None,
                        flights=checks, flight_kept=config.rescue_flight)  # fmt: skip
        out = _back_to_input_rate(roll, model, lift, x, fps, ctrl_fps, config.tau, config.reset_on_fail,
                                  grounded, config.crossfade)  # fmt: skip
        score = (not bool(out["success"]), float(out["mpjpe"].mean()))
        if best is None or score < best[0]:
            best = (score, out | {"ilc_pass": np.array(ilc_pass)})
        if ilc_pass < config.ilc_passes:  # the next pass's reference: the root error fed forward
            reference = reference.copy()
            reference[:, :3] += config.ilc_gain * (target[:, :3] - roll.qpos[:, :3])
    tracked = best[1] | {"body": body, "grounded": np.array(grounded), "searched": np.array(False)}
    tracked |= ref_field
    if config.fallback and _falls_short(tracked, x, config.fallback_flight):
        return _fallback(tracked, x, fps, config, on_step) | ref_field
    return tracked


def _reference_step(prep: PreparedMotion, t: int, fps: float, ctrl_fps: float) -> np.ndarray:
    """() float64: the largest frame step of prep's shaped reference brought to the input's t frames at
    ``fps`` (``ProjectedMotion.reference_step``)."""
    from physmotion.metrics.dynamics import largest_step  # metrics import the physics package

    reference = qpos_to_joints(resample_qpos(prep.target, ctrl_fps, fps, count=t), prep.model)
    return np.array(largest_step(reference))


def mend_first_frame(x: np.ndarray, margin: float) -> np.ndarray:
    """x (T, 22, 3) with frame 0 replaced by 2 x[1] - x[2] where its fastest joint's move into frame 1
    passes the fastest move of frame 1 -> 2 by more than ``margin`` metres; x itself otherwise."""
    if len(x) < 3:
        return x
    first, second = (float(np.linalg.norm(x[i + 1] - x[i], axis=-1).max()) for i in (0, 1))
    if first <= second + margin:
        return x
    out = x.copy()
    out[0] = 2.0 * x[1] - x[2]
    return out


def _falls_short(out: dict[str, np.ndarray], x: np.ndarray, flight: float) -> bool:
    """Whether the tracker's output ``out`` of motion x (T, 22, 3) needs the search: it was reset, failed,
    or kept less than ``flight`` of x's flight (where x flies at all, ``metrics.dynamics.MIN_FLIGHT``)."""
    from physmotion.metrics.actions import flight_height
    from physmotion.metrics.dynamics import MIN_FLIGHT

    if int(out["resets"]) > 0 or not bool(out["success"]):
        return True
    wanted = flight_height(x)
    return wanted >= MIN_FLIGHT and flight_height(out["joints"].astype(np.float64)) < flight * wanted


def _fallback(tracked: dict[str, np.ndarray], x: np.ndarray, fps: float, config: ProjectionConfig,
              on_step: Callable[[int, int], None] | None) -> dict[str, np.ndarray]:  # fmt: skip
    """The search's projection of x in place of the tracker's output ``tracked``, on the search's body
    (:func:`search_humanoid`), unless the search did worse (reset more often, or failed where the tracker
    did not); a teacher's records are dropped, so a batch stacks alike."""
    searching = replace(config, ilc_passes=0).with_controller("search")
    out = _search_one(prepare_motion(x, fps, searching), x, fps, searching, on_step)

    def worse(o: dict) -> tuple[int, bool]:
        return int(o["resets"]), not bool(o["success"])

    if worse(out) > worse(tracked):
        return tracked
    return {k: v for k, v in out.items() if not k.startswith("teacher_")} | {"searched": np.array(True)}


def _recovery(model, config: ProjectionConfig) -> Recover:
    """``simulate``'s ``recover`` for P: the search (at ``config.search``'s effort, with no outside hand, on the
    tracker's own body) from ``recover_back`` seconds before a failing step to ``recover_ahead`` seconds after
    it; where it falls, once more from ``recover_retry_back`` seconds before (an earlier start leaves it more
    time to steer the body); None where the search falls every time."""
    rate = 1.0 / config.humanoid.control_dt
    backs = [config.recover_back] + ([config.recover_retry_back] if config.recover_retry_back else [])
    backs = [int(round(b * rate)) for b in backs]
    ahead = int(round(config.recover_ahead * rate))

    def recover(ref, states: np.ndarray, k: int, earliest: int,
                accept: Callable[[Recovery], bool] | None = None) -> Recovery | None:  # fmt: skip
        stop = min(len(ref.qpos), k + ahead + 1)
        starts: set[int] = set()
        for back in backs:
            start = max(earliest, k - back)
            if start in starts:  # the earlier try started there already: the same search again
                continue
            starts.add(start)
            search = SearchController(model, replace(config.search, seed=config.search.seed + k), config.humanoid,
                                      config.tracking)  # fmt: skip
            roll, record = search.run(ref.window(start, stop), start=states[start])
            if roll.failed_at is None:
                got = Recovery(start, roll.qpos, record.qvel, roll.mpjpe, roll.contacts)
                if accept is None or accept(got):
                    return got
        return None

    return recover


def _flight_checks(model, target: np.ndarray, config: ProjectionConfig) -> list[FlightCheck]:
    """The flights of the shaped reference target (N, 70) that ``simulate`` checks the body makes
    (``ProjectionConfig.rescue_flight``; none when it is 0): each flight of the body's lowest point at least
    ``metrics.dynamics.MIN_FLIGHT`` over the floor, judged one step past its highest."""
    from physmotion.metrics.dynamics import MIN_FLIGHT

    if not config.rescue_flight:
        return []
    sh = config.shaping
    found = flights(model, target, config.humanoid.control_dt, sh.support, sh.float_window)
    return [FlightCheck(a, top + 1, height) for a, top, height in found if height >= MIN_FLIGHT]


def _search_one(prep: PreparedMotion, x: np.ndarray, fps: float, config: ProjectionConfig,
                on_step: Callable[[int, int], None] | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """P of one motion under the search controller: no outside hand. Its failure is a fall, not a world
    error (the body may drift from the reference's path), so imitation selection keeps the simulation of a
    grounded motion that did not fall; ``mpjpe`` still reports the world error, drift included."""
    ref = prepare_reference(prep.model, prep.target, config.humanoid.control_dt, config.tracking)
    proposal = None
    if config.policy is not None:  # amortized search: the policy proposes each window's first mean
        policy = _policy(config.policy)
        scale = policy.settings.action_scale
        proposal = lambda obs: scale * np.clip(policy.network(obs), -1.0, 1.0)  # noqa: E731
    search = SearchController(prep.model, config.search, config.humanoid, config.tracking, proposal)
    roll, record = search.run(ref, reset_on_fail=config.reset_on_fail, on_step=on_step)
    out = _back_to_input_rate(roll, prep.model, prep.lift, x, fps, 1.0 / config.humanoid.control_dt, np.inf,
                              config.reset_on_fail, prep.grounded, config.crossfade)  # fmt: skip
    return out | {"ilc_pass": np.array(0), "body": prep.body, "grounded": np.array(prep.grounded),
                  "teacher_obs": record.observations, "teacher_offsets": record.offsets.astype(np.float32)}


def _grounded(model, qpos: np.ndarray, rate: float, config: ProjectionConfig) -> bool:
    """Whether the retargeted motion qpos (N, 70) at ``rate`` never keeps its lowest point above
    ``config.support_height`` for longer than ``config.unsupported_seconds``."""
    _, gpos, gmat = pose_frames(model, qpos)
    up = np.concatenate([[False], body_lowest(model, gpos, gmat) > config.support_height, [False]])
    edges = np.flatnonzero(np.diff(up.astype(np.int8)))  # starts and ends of each run off the floor
    longest = int((edges[1::2] - edges[::2]).max()) if len(edges) else 0
    return longest <= config.unsupported_seconds * rate


def _back_to_input_rate(
    roll: Rollout, model, lift: float, joints: np.ndarray, fps: float, ctrl_fps: float, tau: float,
    keep_simulated: bool = False, grounded: bool = True, crossfade: float = 0.0,
) -> dict[str, np.ndarray]:
    """One rollout (control rate) as arrays at the input rate, with imitation selection applied (unless
    ``keep_simulated``: then the simulation, reset where it failed and cross-faded over ``crossfade``
    seconds before each reset, is always returned). A frame's help is over the control steps nearest to
    it (:func:`_frame_of_steps`), so none is dropped where the control rate is the higher."""
    t, n = len(joints), len(roll.qpos)
    sim = qpos_to_joints(resample_qpos(roll.qpos, ctrl_fps, fps, count=t), model)
    raised = joints + np.array([0.0, lift, 0.0])
    owner = _frame_of_steps(n, ctrl_fps, fps, t)
    # A reset's frame is the first at or after it: an earlier one interpolates the fallen and the reset states.
    resets = np.zeros(t, dtype=bool)
    resets[np.minimum(np.ceil(np.flatnonzero(roll.reset_steps) * fps / ctrl_fps - 1e-9).astype(int), t - 1)] = True
    out_sim, faded = _crossfade(sim, raised, resets, int(round(crossfade * fps)))
    mpjpe = np.linalg.norm(out_sim - raised, axis=-1).mean(-1)
    success = roll.failed_at is None
    selected = keep_simulated or (success and grounded and float(mpjpe.max()) < tau)
    nearest = np.minimum(np.round(np.arange(t) * ctrl_fps / fps).astype(int), n - 1)
    return {
        "joints": (out_sim if selected else joints).astype(np.float32),
        "simulated": sim.astype(np.float32),
        "mpjpe": mpjpe,
        "residual_force": _per_frame(roll.residual_force, owner, nearest, "mean"),
        "residual_torque": _per_frame(roll.residual_torque, owner, nearest, "mean"),
        "residual_force_peak": _per_frame(roll.residual_force_peak, owner, nearest, "max"),
        "residual_torque_peak": _per_frame(roll.residual_torque_peak, owner, nearest, "max"),
        "at_cap": _per_frame(roll.at_cap, owner, nearest, "max") > 0,
        "contacts": roll.contacts[nearest],
        "success": np.array(success),
        "selected": np.array(selected),
        "resets": np.array(roll.resets),
        "recovered": np.array(roll.recovered),
        "recovered_frames": _per_frame(roll.recovered_steps, owner, nearest, "mean") > 1.0 - 1e-9,
        "reset_frames": faded if selected else np.zeros(t, dtype=bool),
        "over_limit": _per_frame(roll.over_limit, owner, nearest, "max") > 0,
    }


def _frame_of_steps(n: int, ctrl_fps: float, fps: float, t: int) -> np.ndarray:
    """(n,) int: the input frame (of t) nearest each control step, the frame whose help it counts in."""
    return np.minimum(np.round(np.arange(n) * fps / ctrl_fps).astype(int), t - 1)


def _per_frame(values: np.ndarray, owner: np.ndarray, nearest: np.ndarray, how: str) -> np.ndarray:
    """(t,) float64: ``values`` (n,) per control step reduced over each frame's steps (``owner`` (n,), the
    frame of each step) by ``how`` ("mean" or "max"); a frame that owns no step (an input faster than the
    control rate) takes the value of its ``nearest`` (t,) step."""
    v = np.asarray(values, dtype=np.float64)
    t = len(nearest)
    count = np.bincount(owner, minlength=t)
    if how == "mean":
        out = np.bincount(owner, weights=v, minlength=t) / np.maximum(count, 1)
    else:
        out = np.full(t, -np.inf)
        np.maximum.at(out, owner, v)
    empty = count == 0
    out[empty] = v[nearest[empty]]
    return out


def _crossfade(sim: np.ndarray, raised: np.ndarray, resets: np.ndarray,
               frames: int) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The simulation sim (T, 22, 3) with each reset hidden: over the ``frames`` frames before a reset
    frame (``resets`` (T,) bool) the falling body is blended (smoothstep) onto the motion it is put back
    on (``raised`` (T, 22, 3), moved to meet the simulation at the reset frame), so no frame jumps. Returns
    it and (T,) bool: the reset frames and the blended ones, which are not simulated."""
    out, marked = sim.copy(), resets.copy()
    prev = -1
    for f in np.flatnonzero(resets):
        start = max(f - frames, prev + 1)
        span = f - start + 1  # the weight reaches 1 at the reset frame itself
        if span > 1:
            u = (np.arange(start, f) - start + 1) / span
            w = (u * u * (3.0 - 2.0 * u))[:, None, None]
            target = raised[start:f] + (sim[f] - raised[f])
            out[start:f] = (1.0 - w) * sim[start:f] + w * target
            marked[start:f] = True
        prev = f
    return out, marked
