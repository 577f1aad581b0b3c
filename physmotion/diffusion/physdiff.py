"""PhysDiff: physics projection inside the sampler (Algorithm 2), its schedules, and the post-processing baseline.

At the scheduled steps the denoised motion x~ is replaced by P(x~) before the DDIM update, where P is
:func:`physmotion.physics.projection.project`. In feature space this means: de-normalise, recover joints
(``recover_from_ric``), simulate, re-extract HumanML3D features from the simulated joints in the model's
floor convention (the dataset's puts the floor back under the lowest joint; a model fine-tuned on
physical motion keeps the simulated soles on the floor) and normalise again.

Schedules name the projection steps by t, the number of sampling steps still to come (t = 0 is the last
step), as PhysDiff's Sec. 4.4 does:
- ``uniform:N``: N steps spread evenly, ``t = round(linspace(0, 0.9 * steps, N))`` ({0, 15, 30, 45} for
  50 steps and N = 4, the paper's example);
- ``start:M,end:N``: the first M and the last N steps;
- ``end:N,space:S``: t = 0, S, 2S, ... (N of them), e.g. ``end:4,space:1`` = the last four steps.

Any schedule may add ``fly:last``: a motion whose denoised x0 flies at a projection step before the last
(both feet at least :data:`~physmotion.metrics.dynamics.MIN_FLIGHT` up at once) is not projected there,
only at the last one. P keeps less of a flight than the motion had (the tracker holds the body near the
floor), and the denoiser follows the lowered motion, so the loss compounds over the projections
(docs/decisions/sampling.md: "PhysDiff with one P at the end for a motion that flies").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from physmotion.conventions import FLOOR_JOINTS, FLOOR_SURFACE, FPS, check_floor
from physmotion.diffusion.model import MotionDiffusion
from physmotion.errors import PhysmotionError
from physmotion.features.biomech import FEATURE_DIM_BIOMECH, extract_features_329
from physmotion.features.humanml3d import FEATURE_DIM, extract_features, recover_from_ric
from physmotion.metrics.dynamics import largest_step
from physmotion.physics.projection import ProjectionConfig, SimRecord, project


def projection_settings(config: ProjectionConfig) -> dict[str, bool | float]:
    """How P treats a fall, the step it simulates at (``--fine-step`` halves it) and whether the search
    is the tracker's fallback, carries falls or re-does short take-offs, as recorded with generated files
    and evaluation tables."""
    return {"reset_on_fail": config.reset_on_fail, "tau": config.tau, "sim_dt": config.humanoid.sim_dt,
            "search_fallback": config.fallback, "search_recover": config.recover,
            "flight_rescue": config.rescue_flight}


FLY_LAST = "fly:last"
"""The schedule modifier that projects a flying motion at the last scheduled step only (module docstring)."""


def _fields(spec: str) -> dict[str, str]:
    try:
        return dict(part.split(":") for part in spec.replace(" ", "").split(","))
    except ValueError:
        raise PhysmotionError(f"bad schedule {spec!r}: use uniform:N, start:M,end:N or end:N,space:S") from None


def flies_last(spec: str) -> bool:
    """Whether schedule ``spec`` carries ``fly:last``."""
    fly = _fields(spec).get("fly")
    if fly not in (None, "last"):
        raise PhysmotionError(f"bad schedule {spec!r}: the only fly option is {FLY_LAST}")
    return fly == "last"


def parse_schedule(spec: str, steps: int) -> list[int]:
    """Loop indices (0 = first sampling step) at which to project, ascending, for a schedule string."""
    flies_last(spec)  # checks the modifier
    fields = {k: v for k, v in _fields(spec).items() if k != "fly"}
    try:
        values = {k: int(v) for k, v in fields.items()}
    except ValueError:
        raise PhysmotionError(f"bad schedule {spec!r}: use uniform:N, start:M,end:N or end:N,space:S") from None
    if any(v < 0 for v in values.values()):
        raise PhysmotionError(f"bad schedule {spec!r}: numbers must not be negative")
    keys = set(values)
    if keys == {"uniform"}:
        ts = {round(x) for x in np.linspace(0, 0.9 * steps, values["uniform"])} if values["uniform"] else set()
    elif keys == {"start", "end"}:
        ts = {steps - 1 - k for k in range(values["start"])} | set(range(values["end"]))
    elif keys == {"end", "space"}:
        if values["space"] < 1:
            raise PhysmotionError(f"bad schedule {spec!r}: space must be at least 1")
        ts = {k * values["space"] for k in range(values["end"])}
    else:
        raise PhysmotionError(f"bad schedule {spec!r}: use uniform:N, start:M,end:N or end:N,space:S")
    if any(t >= steps for t in ts):
        raise PhysmotionError(f"schedule {spec!r} needs more than the {steps} sampling steps")
    return sorted(steps - 1 - t for t in ts)


@dataclass
class Projected:
    """What one application of P did to a list of motions, in the order given."""

    joints: list[np.ndarray]  # (T_i, 22, 3) P's output, physical coordinates (soles on the floor)
    bodies: list[np.ndarray]  # (22, 3) the humanoid body each was simulated with
    records: list[SimRecord]  # resets, residual, help, reset frames of each simulation
    selected: list[bool]  # the simulation was returned (not the input)
    tracked: list[bool]  # ... and the humanoid never fell (no reset)
    mpjpe_mm: list[float]  # mean distance to the input
    residual_force: list[float]  # mean root residual force, body weights
    # the input's largest frame-to-frame joint move, m (metrics.dynamics.largest_step): what an output's
    # own largest move is measured against to tell P's jumps from the denoiser's (issue 62)
    input_steps: list[float] = field(default_factory=list)
    # the largest move of the reference P tracked (ProjectedMotion.reference_step): a jump it already makes
    # is P's retargeting or shaping, not its simulation
    reference_steps: list[float] = field(default_factory=list)
    # each motion's place in the run's batch where a call projects only some (``fly:last``); None: all
    indices: list[int] | None = None

    @property
    def resets(self) -> list[int]:
        """Times the humanoid was put back onto each motion (cross-faded in the output)."""
        return [r.resets for r in self.records]


@dataclass
class ProjectionLog:
    """What the projections of a run did: one entry per projected motion, over all of P's calls."""

    calls: int = 0
    selected: list[bool] = field(default_factory=list)  # the simulation was returned
    tracked: list[bool] = field(default_factory=list)  # ... and the humanoid never fell (no reset)
    mpjpe_mm: list[float] = field(default_factory=list)
    residual: list[float] = field(default_factory=list)
    resets: list[int] = field(default_factory=list)  # times the humanoid was put back (a jump in the output)
    input_steps: list[float] = field(default_factory=list)  # largest frame step of each input, m
    reference_steps: list[float] = field(default_factory=list)  # ... and of the reference P tracked for it
    motions: list[int] = field(default_factory=list)  # each projection's motion: its place in the run's batch

    def add(self, done: Projected) -> Projected:
        """Count one call of P; returns ``done``."""
        self.calls += 1
        self.motions += done.indices if done.indices is not None else list(range(len(done.joints)))
        self.selected += done.selected
        self.tracked += done.tracked
        self.mpjpe_mm += done.mpjpe_mm
        self.residual += done.residual_force
        self.resets += done.resets
        self.input_steps += done.input_steps
        self.reference_steps += done.reference_steps
        return done

    def last_input_steps(self, n: int) -> list[float]:
        """Per motion of a run whose last call projected its ``n`` motions in order, the largest frame step
        of what that call was given (its output is the run's); empty without a call."""
        return self.input_steps[-n:] if self.calls else []

    def last_reference_steps(self, n: int) -> list[float]:
        """As :meth:`last_input_steps`, the largest frame step of the reference that call tracked."""
        return self.reference_steps[-n:] if self.calls else []

    def resets_per_motion(self, n: int) -> list[int]:
        """Per motion of a run of ``n`` motions (PhysDiff, post, Morph), its resets over all calls; zeros
        without a call."""
        if self.motions and max(self.motions) >= n:
            raise ValueError(f"the log's projections are not of a run of {n} motions")
        out = [0] * n
        for i, r in zip(self.motions, self.resets):
            out[i] += int(r)
        return out


class FeatureProjector:
    """P on normalised HumanML3D features: (B, T, 263) normalised + lengths -> same, physically projected.

    Stateless: every call returns what P did (:class:`Projected`); a caller that keeps a run's account
    adds it to a :class:`ProjectionLog`."""

    def __init__(self, model: MotionDiffusion, config: ProjectionConfig | None = None, fps: float = FPS) -> None:
        self.model, self.config, self.fps = model, config or ProjectionConfig.sampling(), fps

    def data_floor(self, joints: list[np.ndarray]) -> list[np.ndarray]:
        """Joints recovered from the model's samples, put in the data convention P takes: a FLOOR_SURFACE
        model's motions go onto their lowest joint (P raises the soles back onto the floor itself)."""
        return [on_data_floor(j) for j in joints] if self.model.floor == FLOOR_SURFACE else list(joints)

    def project_joints(self, joints: list[np.ndarray]) -> Projected:
        """Project a list of joint arrays (T_i, 22, 3) in the data convention; motions of equal length go
        through in one batch."""
        n = len(joints)
        done = Projected(joints=[np.empty(0)] * n, bodies=[np.empty(0)] * n, records=[None] * n,
                         selected=[False] * n, tracked=[False] * n, mpjpe_mm=[0.0] * n,
                         residual_force=[0.0] * n, input_steps=[largest_step(j) for j in joints],
                         reference_steps=[0.0] * n)  # fmt: skip
        by_len: dict[int, list[int]] = {}
        for i, j in enumerate(joints):
            by_len.setdefault(len(j), []).append(i)
        for idx in by_len.values():
            res = project(np.stack([joints[i] for i in idx]), self.fps, self.config)
            for k, i in enumerate(idx):
                done.joints[i], done.bodies[i], done.records[i] = res.joints[k], res.body[k], res.record(k)
                done.selected[i], done.tracked[i] = bool(res.selected[k]), bool(res.success[k])
                done.mpjpe_mm[i] = float(1000 * res.mpjpe[k].mean())
                done.residual_force[i] = float(res.residual_force[k].mean())
                done.reference_steps[i] = float(res.reference_step[k])
        return done

    def joints(self, x0: torch.Tensor, lengths: list[int]) -> list[np.ndarray]:
        """The joints (T_i, 22, 3) of a denoised x0 (B, T, D) normalised, in the data convention P takes."""
        feats = self.model.normalizer.denormalize(x0.detach().float().cpu().numpy())
        joints = [recover_from_ric(feats[i, :n].astype(np.float64)) for i, n in enumerate(lengths)]
        return self.data_floor(joints)

    def project_features(self, x0: torch.Tensor, lengths: list[int],
                         only: list[int] | None = None) -> tuple[torch.Tensor, Projected]:  # fmt: skip
        """P on a denoised x0 (B, T, D) normalised, as PhysDiff's Algorithm 2 applies it inside sampling:
        returns the projected x0 (same shape; frames past each length as given) and what P did. ``only``:
        the motions to project (the others pass through as given, and ``Projected`` lists the ones done)."""
        norm = self.model.normalizer
        joints = self.joints(x0, lengths)
        chosen = list(range(len(lengths))) if only is None else list(only)
        done = self.project_joints([joints[i] for i in chosen])
        done.indices = None if only is None else chosen
        out = x0.detach().clone()
        dim = x0.shape[-1]  # 263, or BioMoDiffuse's 329: the features are re-extracted in the model's own
        for i, j in zip(chosen, done.joints):
            n = lengths[i]
            out[i, :n] = torch.from_numpy(norm.normalize(joints_to_features(j, dim, self.model.floor))).to(out)
        return out, done


def on_data_floor(joints: np.ndarray) -> np.ndarray:
    """Joints (T, 22, 3) shifted so that the clip's lowest joint is at y = 0: the dataset's convention and
    the input P expects (P returns physical coordinates, with the humanoid's soles on the floor)."""
    return joints - np.array([0.0, joints[..., 1].min(), 0.0])


def joints_to_features(joints: np.ndarray, dim: int = FEATURE_DIM, floor: str = FLOOR_JOINTS) -> np.ndarray:
    """HumanML3D features with one row per frame: (T, 22, 3) -> (T, dim), dim 263 or 329 (BioMoDiffuse).

    HumanML3D's features of T frames describe T-1 transitions; a last frame extrapolated at constant
    velocity keeps the length, so a projected x0 replaces the denoised one frame for frame.
    floor: FLOOR_JOINTS re-floors the motion on its lowest joint (the dataset's convention); FLOOR_SURFACE
    keeps its heights (a simulated motion's soles on the floor: the convention of a model fine-tuned so).
    """
    ext = np.concatenate([joints, 2 * joints[-1:] - joints[-2:-1]], axis=0)
    on_joints = check_floor(floor) == FLOOR_JOINTS
    if dim == FEATURE_DIM_BIOMECH:
        return extract_features_329(ext, floor=on_joints)[0]
    if dim != FEATURE_DIM:
        raise PhysmotionError(f"features must be {FEATURE_DIM}- or {FEATURE_DIM_BIOMECH}-dimensional, got {dim}")
    return extract_features(ext, floor=on_joints)[0]
