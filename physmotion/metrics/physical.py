"""Physical plausibility metrics of PhysDiff, EDGE/Morph and BioMoDiffuse, each computed as its source does.

Input everywhere: joints (T, 22, 3) or a batch (B, T, 22, 3), metres, Y up, floor y = 0 (see
:mod:`physmotion.conventions`), with ``lengths`` (B,) or a prefix ``mask`` (B, T) for padded batches.
Each metric is averaged per its source: PhysDiff's over all frames of the batch pooled (as CLoSD does),
the others per motion and then over motions (``MetricInfo.aggregate``). Where a paper leaves a detail
open, the choice is written in that metric's docstring and in :data:`METRICS`.

The floor: y = 0 is where the body *surface* stands (``surface``: the humanoid's collision geometry of
:mod:`physmotion.physics.surface` in the tables, or the capsules of :mod:`physmotion.metrics.geometry`),
not the lowest joint. Motions in the
data convention (lowest joint at 0) stand about a sole's thickness in the floor by this measure, so the
tables ground them first with :func:`physmotion.physics.surface.ground_on_surface`, by the constant
shift that leaves the least Phys-Err (a rigid box foot cannot both stand flat and roll over heel and
toe on the floor as a real foot does): the real row and the ``none+floor`` mode are grounded that way;
``none`` is measured as sampled, and P's output is already a simulated body on the simulator's floor
(docs/decisions/data.md, "floor convention").

Sources followed (code read, not copied):
- PhysDiff App. A, as implemented in GuyTevet/CLoSD
  ``closd/diffusion_planner/data_loaders/humanml/utils/metrics.py`` (``calculate_penetration``,
  ``calculate_floating``, ``calculate_foot_sliding``, "based on PhysDiff's implementation"), and UHC's
  ``uhc/smpllib/smpl_eval.py`` (``compute_penetration``, ``compute_skate``; ZhengyiLuo/UHC).
- EDGE's PFC: Stanford-TML/EDGE ``eval/eval_pfc.py`` (``calc_physical_score``), used by Morph.
- Foot-skating ratio: korrawe/guided-motion-diffusion ``data_loaders/humanml/utils/metrics.py``
  (``calculate_skating_ratio``), which BioMoDiffuse App. A cites.
- BioMoDiffuse Sec. 4.1 (VC, AC, eq. 13) and App. A (eqs. 14-19); Morph Sec. 3.2/4.1 (IFR).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Literal, Union

import numpy as np
from rich.table import Table
from scipy.ndimage import uniform_filter1d

from physmotion.conventions import FPS, UP_AXIS
from physmotion.errors import ShapeError
from physmotion.metrics.geometry import DEFAULT_BODY, BodySurface
from physmotion.skeleton import FOOT_JOINTS, JOINT_INDEX, NUM_JOINTS

METRIC_MIN_FRAMES = 4
"""Fewest frames a motion needs: Smoothness takes a third difference."""

_HORIZONTAL = [a for a in range(3) if a != UP_AXIS]
_TOES = [JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"]]  # GMD's and BioMoDiffuse's "feet": 10, 11


@dataclass(frozen=True)
class MetricParams:
    """Thresholds of every metric, with the value its source uses."""

    # PhysDiff App. A: 5 mm tolerance "to account for geometry approximation"; also Skate's contact height.
    tolerance: float = 0.005
    # Skate and PFC sum per-frame displacements, so they depend on the frame rate; they are expressed per
    # frame at this rate (displacement * fps / reference_fps): the published values are at 20 fps
    # (HumanML3D). EDGE's own AIST++ numbers are at 30 fps: pass reference_fps=30 to compare with them.
    reference_fps: float = float(FPS)
    pfc_scale: float = 1e4  # EDGE prints mean * 10000
    # Below this peak root acceleration (m/s^2) a motion counts as not accelerating: EDGE divides by the
    # motion's own maximum, which would blow rounding noise of a constant-velocity root up to O(1).
    pfc_min_acceleration: float = 1e-3
    # GMD skating ratio: toe joints below 5 cm in two adjacent frames, faster than 0.5 m/s both in that frame
    # and on average over a 5-frame window (0.25 s at GMD's 20 fps).
    skate_height: float = 0.05
    skate_speed: float = 0.5
    skate_window_s: float = 0.25
    # BioMoDiffuse / ReinDiffuse: h_ground = 5 cm for Float; Penetration below the floor (penetration_ratio).
    float_height: float = 0.05
    penetrate_height: float = 0.0
    clip_distance: float = 0.05
    # BioMoDiffuse VC/AC spectral bands (the paper gives no values: our choice, see velocity_consistency).
    band_low_hz: float = 1.0
    band_high_hz: float = 5.0
    # Morph: an imitation fails once the MPJPE between input and simulated pose exceeds 0.5 m.
    ifr_tau: float = 0.5


PARAMS = MetricParams()

Aggregate = Literal["frames", "motions", "sum"]
Lengths = Union[np.ndarray, Sequence[int], None]
"""(B,) valid frames per motion of a padded batch."""
Mask = Union[np.ndarray, Sequence[Sequence[bool]], None]
"""(B, T) bool, True on valid frames, which come first in each row."""


@dataclass(frozen=True)
class MetricInfo:
    """One row of :data:`METRICS`.

    aggregate: "frames" = mean over every valid term of the batch pooled (each motion weighted by its
    ``length - offset`` terms), "motions" = per-motion value averaged over motions, "sum" = the sum of
    other aggregated metrics. better: "lower", or "closer to real" where the paper says so.
    """

    name: str
    unit: str
    paper: str
    aggregate: Aggregate
    offset: int
    better: str
    description: str


METRICS: dict[str, MetricInfo] = {
    m.name: m
    for m in (
        MetricInfo("penetrate", "mm", "PhysDiff", "frames", 0, "lower",
                   "depth of the lowest body surface point below the floor, minus 5 mm"),
        MetricInfo("float", "mm", "PhysDiff", "frames", 0, "lower",
                   "height of the lowest body surface point above the floor, minus 5 mm"),
        MetricInfo("skate", "mm", "PhysDiff", "frames", 1, "lower",
                   "horizontal displacement of foot joints in contact in two adjacent frames"),
        MetricInfo("phys_err", "mm", "PhysDiff", "sum", 0, "lower", "Penetrate + Float + Skate"),
        MetricInfo("pfc", "score", "EDGE/Morph", "motions", 2, "lower",
                   "physical foot contact x 1e4: min foot step left x right x normalised root acceleration"),
        MetricInfo("skate_ratio", "ratio", "BioMoDiffuse (GMD)", "motions", 1, "closer to real",
                   "fraction of frame pairs where a toe near the floor slides faster than 0.5 m/s"),
        MetricInfo("float_ratio", "ratio", "BioMoDiffuse (ReinDiffuse)", "motions", 0, "closer to real",
                   "fraction of frames whose lowest joint is above 5 cm"),
        MetricInfo("penetrate_ratio", "ratio", "BioMoDiffuse (ReinDiffuse)", "motions", 0, "closer to real",
                   "fraction of frames whose lowest joint is below the floor"),
        MetricInfo("clip_ratio", "ratio", "BioMoDiffuse (ReinDiffuse)", "motions", 0, "closer to real",
                   "fraction of frames whose two toe joints are closer than 5 cm"),
        MetricInfo("speed", "m/s", "BioMoDiffuse (Fischer)", "motions", 1, "closer to real",
                   "mean joint speed"),
        MetricInfo("smoothness", "m/s^3", "BioMoDiffuse (Fischer)", "motions", 3, "closer to real",
                   "mean joint jerk magnitude"),
        MetricInfo("vc", "ratio", "BioMoDiffuse", "motions", 1, "closer to real",
                   "velocity spectrum: mid band over low + high bands"),
        MetricInfo("ac", "ratio", "BioMoDiffuse", "motions", 2, "closer to real",
                   "acceleration spectrum: mid band over low + high bands"),
        MetricInfo("ifr", "ratio", "Morph", "motions", 0, "lower",
                   "fraction of motions whose simulated MPJPE to the input exceeds 0.5 m at some frame"),
    )
}  # fmt: skip
"""Every metric :func:`physical_metrics` can return, in table order ("ifr" only with a reference)."""


# ------------------------------------------------------------------------------------------------
# Input


@dataclass
class _Batch:
    """Validated input. joints: (B, T, 22, 3) float64 where frames past a motion's length repeat its
    last valid frame, so padding never enters a difference; lengths: (B,)."""

    joints: np.ndarray
    lengths: np.ndarray
    fps: float
    body: BodySurface
    params: MetricParams

    def valid(self, offset: int) -> np.ndarray:
        """(B, T - offset) True where a term computed from ``offset + 1`` consecutive frames is inside."""
        n = self.joints.shape[1] - offset
        return np.arange(n)[None, :] < (self.lengths - offset)[:, None]

    def mean(self, values: np.ndarray, offset: int) -> np.ndarray:
        """Per-motion mean of per-term values (B, T - offset) over the valid terms: (B,)."""
        valid = self.valid(offset)
        return np.where(valid, values, 0.0).sum(axis=1) / valid.sum(axis=1)

    @cached_property
    def lowest(self) -> np.ndarray:
        """(B, T) height of the lowest body surface point."""
        return np.asarray(self.body.lowest_height(self.joints), dtype=np.float64)

    @cached_property
    def feet(self) -> np.ndarray:
        """(B, T, 4) height of each foot joint's contact patch (heel, toes), FOOT_JOINTS order."""
        return np.asarray(self.body.foot_heights(self.joints), dtype=np.float64)

    def per_frame_rate(self) -> float:
        """Factor turning a displacement per frame at ``fps`` into one per frame at the reference rate."""
        return self.fps / self.params.reference_fps


def _lengths(shape: tuple[int, int], lengths: Lengths, mask: Mask) -> np.ndarray:
    b, t = shape
    if lengths is not None and mask is not None:
        raise ShapeError("give lengths or mask, not both")
    if mask is not None:
        m = np.asarray(mask)
        if m.ndim == 1 and b == 1:
            m = m[None]
        if m.shape != (b, t):
            raise ShapeError(f"mask must have shape ({b}, {t}), got {m.shape}")
        m = m.astype(bool)
        out = m.sum(axis=1)
        if np.any(m != (np.arange(t)[None, :] < out[:, None])):
            raise ShapeError("mask must mark a prefix of each motion (valid frames first, then padding)")
        return out.astype(np.int64)
    if lengths is None:
        return np.full(b, t, dtype=np.int64)
    out = np.atleast_1d(np.asarray(lengths))
    if out.shape != (b,) or not np.issubdtype(out.dtype, np.integer):
        raise ShapeError(f"lengths must be {b} integers, got {out.tolist()!r}")
    if np.any(out > t):
        raise ShapeError(f"lengths must not exceed the {t} frames given, got max {int(out.max())}")
    return out.astype(np.int64)


def _prepare(
    joints: np.ndarray, fps: float, lengths: Lengths, mask: Mask, body: BodySurface | None,
    params: MetricParams, name: str = "joints",
) -> _Batch:  # fmt: skip
    try:
        arr = np.asarray(joints, dtype=np.float64)
    except (TypeError, ValueError):
        raise ShapeError(f"{name} must be a numeric array of shape (T, {NUM_JOINTS}, 3)") from None
    shape = arr.shape
    if arr.ndim == 3:
        arr = arr[None]
    if arr.ndim != 4 or arr.shape[2:] != (NUM_JOINTS, 3) or arr.shape[0] == 0:
        raise ShapeError(f"{name} must have shape (T, 22, 3) or (B, T, 22, 3), got {shape}")
    if not (np.isfinite(fps) and fps > 0):
        raise ShapeError(f"fps must be a positive number, got {fps}")
    lens = _lengths(arr.shape[:2], lengths, mask)
    if lens.min() < METRIC_MIN_FRAMES:
        raise ShapeError(
            f"{name}: each motion needs at least {METRIC_MIN_FRAMES} frames, got {int(lens.min())}"
        )
    b, t = arr.shape[:2]
    last = np.minimum(np.arange(t)[None, :], lens[:, None] - 1)
    arr = arr[np.arange(b)[:, None], last]  # padding repeats the last valid frame
    if not np.all(np.isfinite(arr)):
        raise ShapeError(f"{name} contains NaN or infinite values")
    return _Batch(arr, lens, float(fps), DEFAULT_BODY if body is None else body, params)


def foot_contacts(
    joints: np.ndarray, body: BodySurface | None = None, params: MetricParams = PARAMS
) -> np.ndarray:
    """Which foot joints touch the floor, by the rule Skate uses: (..., T, 22, 3) -> (..., T, 4) bool.

    FOOT_JOINTS order (left ankle, left foot, right ankle, right foot): a joint is in contact when its
    contact patch (heel, toes) on ``body`` (default: the joint-only surface model) is within
    ``params.tolerance`` of the floor. Previews and the viewer mark the same contacts the metrics count.
    """
    body = DEFAULT_BODY if body is None else body
    return _in_contact(np.asarray(body.foot_heights(np.asarray(joints, dtype=np.float64))), params)


def _in_contact(feet: np.ndarray, params: MetricParams) -> np.ndarray:
    """feet: (..., 4) contact patch heights, metres -> (..., 4) bool."""
    return feet <= params.tolerance


# ------------------------------------------------------------------------------------------------
# Per-motion values, one function per metric: (batch) -> (B,)


def _penetrate(b: _Batch) -> np.ndarray:
    depth = np.maximum(-b.lowest - b.params.tolerance, 0.0) * 1000.0
    return b.mean(depth, 0)


def _float(b: _Batch) -> np.ndarray:
    height = np.maximum(b.lowest - b.params.tolerance, 0.0) * 1000.0
    return b.mean(height, 0)


def _skate_pairs(b: _Batch) -> tuple[np.ndarray, np.ndarray]:
    """Per adjacent frame pair (B, T-1): Skate's term (mm, 0 where no foot joint touches in both frames)
    and whether some foot joint does."""
    contact = _in_contact(b.feet, b.params)  # (B, T, 4)
    both = contact[:, :-1] & contact[:, 1:]
    feet = b.joints[:, :, list(FOOT_JOINTS)][..., _HORIZONTAL]
    disp = np.linalg.norm(np.diff(feet, axis=1), axis=-1) * 1000.0 * b.per_frame_rate()  # (B, T-1, 4)
    n = both.sum(axis=-1)
    return np.where(n > 0, (disp * both).sum(axis=-1) / np.maximum(n, 1), 0.0), n > 0


def _skate(b: _Batch) -> np.ndarray:
    return b.mean(_skate_pairs(b)[0], 1)


def skate_factors(joints: np.ndarray, fps: float = FPS, *, body: BodySurface | None = None,
                  params: MetricParams = PARAMS) -> tuple[float, float]:  # fmt: skip
    """Skate of one motion (T, 22, 3) split in two factors: (share of adjacent frame pairs in which some
    foot joint is in contact in both frames, mean Skate over those pairs in mm per reference frame), so
    that Skate = share x slide. Skate counts 0 where no foot touches: feet hovering over the tolerance
    score little however they move, feet standing on the floor pay for every millimetre."""
    b = _prepare(joints, fps, None, None, body, params)
    if b.joints.shape[0] != 1:
        raise ShapeError(f"skate_factors takes one motion (T, 22, 3), got {np.shape(joints)}")
    per_pair, touching = _skate_pairs(b)
    if not touching.any():
        return 0.0, 0.0
    return float(touching.mean()), float(per_pair[touching].mean())


def _pfc(b: _Batch) -> np.ndarray:
    root = b.joints[:, :, 0]
    acc = np.diff(root, n=2, axis=1) * b.fps**2  # (B, T-2, 3)
    acc[..., UP_AXIS] = np.maximum(acc[..., UP_AXIS], 0.0)  # only upward acceleration needs a foot
    acc = np.where(b.valid(2), np.linalg.norm(acc, axis=-1), 0.0)
    scale = acc.max(axis=1, keepdims=True)
    moving = scale > b.params.pfc_min_acceleration
    acc = np.where(moving, acc / np.where(moving, scale, 1.0), 0.0)  # EDGE: divided by the motion's maximum
    feet = b.joints[:, :, list(FOOT_JOINTS)][..., _HORIZONTAL]
    # EDGE pairs the acceleration centred on frame k+1 with the step from frame k+1 to k+2.
    speed = np.linalg.norm(feet[:, 2:] - feet[:, 1:-1], axis=-1) * b.per_frame_rate()  # (B, T-2, 4)
    left, right = speed[..., :2].min(axis=-1), speed[..., 2:].min(axis=-1)
    return b.mean(left * right * acc, 2) * b.params.pfc_scale


def _skate_ratio(b: _Batch) -> np.ndarray:
    p = b.params
    toes = b.joints[:, :, _TOES]  # (B, T, 2, 3)
    speed = np.linalg.norm(np.diff(toes[..., _HORIZONTAL], axis=1), axis=-1) * b.fps  # (B, T-1, 2)
    speed = np.where(b.valid(1)[..., None], speed, 0.0)  # zeros past the end = GMD's mode="constant"
    window = max(1, round(p.skate_window_s * b.fps))
    mean_speed = uniform_filter1d(speed, size=window, axis=1, mode="constant", origin=0)
    low = toes[..., UP_AXIS] < p.skate_height
    skating = (low[:, :-1] & low[:, 1:]) & (speed > p.skate_speed) & (mean_speed > p.skate_speed)
    return b.mean(skating.any(axis=-1).astype(np.float64), 1)


def _lowest_joint(b: _Batch) -> np.ndarray:
    return b.joints[..., UP_AXIS].min(axis=-1)


def _float_ratio(b: _Batch) -> np.ndarray:
    return b.mean((_lowest_joint(b) > b.params.float_height).astype(np.float64), 0)


def _penetrate_ratio(b: _Batch) -> np.ndarray:
    return b.mean((_lowest_joint(b) < b.params.penetrate_height).astype(np.float64), 0)


def _clip_ratio(b: _Batch) -> np.ndarray:
    gap = np.linalg.norm(b.joints[:, :, _TOES[0]] - b.joints[:, :, _TOES[1]], axis=-1)
    return b.mean((gap < b.params.clip_distance).astype(np.float64), 0)


def _speed(b: _Batch) -> np.ndarray:
    v = np.linalg.norm(np.diff(b.joints, axis=1), axis=-1) * b.fps  # (B, T-1, 22)
    return b.mean(v.mean(axis=-1), 1)


def _smoothness(b: _Batch) -> np.ndarray:
    jerk = np.linalg.norm(np.diff(b.joints, n=3, axis=1), axis=-1) * b.fps**3  # (B, T-3, 22)
    return b.mean(jerk.mean(axis=-1), 3)


def _spectral_ratio(b: _Batch, order: int) -> np.ndarray:
    """BioMoDiffuse eq. 13 on the ``order``-th time derivative; motions grouped by length for the FFT."""
    out = np.empty(len(b.lengths))
    for n in np.unique(b.lengths):
        sel = b.lengths == n
        x = b.joints[sel, :n].reshape(int(sel.sum()), n, -1)  # (k, n, 66): Phi in R^{T x 3d}
        deriv = np.diff(x, n=order, axis=1)
        spectrum = np.abs(np.fft.rfft(deriv, axis=1)).sum(axis=-1)  # (k, n_freq), summed over channels
        freq = np.fft.rfftfreq(n - order, d=1.0 / b.fps)
        with np.errstate(invalid="ignore", divide="ignore"):
            share = spectrum / spectrum.sum(axis=-1, keepdims=True)
            low = share[:, freq < b.params.band_low_hz].sum(axis=-1)
            high = share[:, freq >= b.params.band_high_hz].sum(axis=-1)
            out[sel] = (1.0 - low - high) / (low + high)
    return out


_PER_MOTION: dict[str, Callable[[_Batch], np.ndarray]] = {
    "penetrate": _penetrate,
    "float": _float,
    "skate": _skate,
    "pfc": _pfc,
    "skate_ratio": _skate_ratio,
    "float_ratio": _float_ratio,
    "penetrate_ratio": _penetrate_ratio,
    "clip_ratio": _clip_ratio,
    "speed": _speed,
    "smoothness": _smoothness,
    "vc": lambda b: _spectral_ratio(b, 1),
    "ac": lambda b: _spectral_ratio(b, 2),
}

RECORDED: dict[str, MetricInfo] = {
    m.name: m
    for m in (
        # Recorded by P in its output (Motion.residual), not measured from the joints: how much of the
        # motion the non-physical root wrench carried (PhysDiff's residual force control).
        MetricInfo("residual_force", "x W", "PhysDiff (RFC)", "frames", 0, "lower",
                   "mean root residual force the projection applied, in body weights"),
        MetricInfo("residual_force_p95", "x W", "PhysDiff (RFC)", "frames", 0, "lower",
                   "95th percentile over frames of the root residual force"),
        MetricInfo("residual_torque", "x W m", "PhysDiff (RFC)", "frames", 0, "lower",
                   "mean root residual torque the projection applied, in body weight x 1 m"),
        MetricInfo("residual_torque_p95", "x W m", "PhysDiff (RFC)", "frames", 0, "lower",
                   "95th percentile over frames of the root residual torque"),
        MetricInfo("residual_force_peak_p95", "x W", "PhysDiff (RFC)", "frames", 0, "lower",
                   "95th percentile over frames of the largest root residual force within the frame"),
        MetricInfo("residual_torque_peak_p95", "x W m", "PhysDiff (RFC)", "frames", 0, "lower",
                   "95th percentile over frames of the largest root residual torque within the frame"),
        MetricInfo("residual_at_cap", "share", "PhysDiff (RFC)", "frames", 0, "lower",
                   "share of frames in which the root residual was held at one of P's caps (force, lift "
                   "or torque; files that predate that record: the mean force at the force's cap)"),
        MetricInfo("over_limit", "share", "-", "frames", 0, "lower",
                   "share of frames in which a joint's torque passed its actuator's limit"),
    )
}
"""Values a projected motion file records (``Motion.residual``, ``residual_cap``, ``over_limit``) rather
than metrics of its joints; the metrics tables show them after :data:`METRICS`."""


def _aggregate(name: str, values: np.ndarray, lengths: np.ndarray) -> float:
    info = METRICS[name]
    if info.aggregate == "frames":
        weights = lengths - info.offset
        return float(np.sum(values * weights) / np.sum(weights))
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else float("nan")


def _one(name: str, joints: np.ndarray, fps: float, lengths: Lengths, mask: Mask,
         body: BodySurface | None, params: MetricParams) -> float:  # fmt: skip
    batch = _prepare(joints, fps, lengths, mask, body, params)
    return _aggregate(name, _PER_MOTION[name](batch), batch.lengths)


# ------------------------------------------------------------------------------------------------
# Public API: one function per metric, and physical_metrics() for all of them at once.
# Every function takes joints (T, 22, 3) or (B, T, 22, 3) and returns the batch's aggregated value.

def penetrate(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
              body: BodySurface | None = None, params: MetricParams = PARAMS) -> float:  # fmt: skip
    """PhysDiff Penetrate, mm: mean over frames of max(0, -h - 5 mm) * 1000.

    h is the height of the lowest body surface point (PhysDiff: lowest SMPL mesh vertex; here the
    humanoid's collision geometry, :mod:`physmotion.metrics.geometry`, or ``body``). The 5 mm tolerance is
    subtracted, not a cut-off: 23 mm deep counts 18 mm, as in CLoSD's ``calculate_penetration``.
    Frames of all motions are pooled (CLoSD concatenates them before the mean).
    """
    return _one("penetrate", joints, fps, lengths, mask, body, params)


def float_(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
           body: BodySurface | None = None, params: MetricParams = PARAMS) -> float:  # fmt: skip
    """PhysDiff Float, mm: mean over frames of max(0, h - 5 mm) * 1000, h as in :func:`penetrate`.

    A frame counts as floating only when its lowest surface point is above the floor (PhysDiff: "the
    lowest body mesh vertex above the ground"); 37 mm up counts 32 mm. Frames pooled as in CLoSD.
    """
    return _one("float", joints, fps, lengths, mask, body, params)


def skate(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
          body: BodySurface | None = None, params: MetricParams = PARAMS) -> float:  # fmt: skip
    """PhysDiff Skate, mm per frame: mean over adjacent frame pairs of the average horizontal
    displacement of the foot joints in contact in both frames (0 for a pair with none).

    Foot joints: ankles and feet (FOOT_JOINTS). PhysDiff leaves "contact" open; here a foot joint is in
    contact when its contact patch is within the 5 mm tolerance of the floor: the toe box for a foot
    joint; for an ankle the ankle box (heel to the ball of the foot) on the humanoid's geometry, its
    heel alone on the joint-only surface model (0.2 mm of Skate apart on generated motions). CLoSD uses
    the same 5 mm margin on the lowest joint, UHC the mesh vertices at or below the floor. The
    displacement is expressed per frame at ``params.reference_fps`` (20 fps, HumanML3D), so a foot
    sliding at 0.3 m/s scores 15 mm at any input rate. Frame pairs of all motions pooled.

    This follows PhysDiff's text (App. A: "foot joints that contact the ground ... their average
    horizontal displacement"), not CLoSD's code, which counts per frame pair only the joint lowest by
    its joint height (floor at the motion's lowest joint), finds contact in few frames and so reads far
    lower (docs/decisions/metrics.md: "PhysDiff Skate as its text says, not as CLoSD's code").
    """
    return _one("skate", joints, fps, lengths, mask, body, params)


def phys_err(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
             body: BodySurface | None = None, params: MetricParams = PARAMS) -> float:  # fmt: skip
    """PhysDiff Phys-Err, mm: Penetrate + Float + Skate."""
    batch = _prepare(joints, fps, lengths, mask, body, params)
    return sum(_aggregate(n, _PER_MOTION[n](batch), batch.lengths) for n in ("penetrate", "float", "skate"))


def pfc(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
        params: MetricParams = PARAMS) -> float:  # fmt: skip
    """EDGE's Physical Foot Contact score (used by Morph), x 1e4, lower is better.

    Per motion (EDGE ``calc_physical_score``): root acceleration a_k = second difference of the pelvis,
    its upward component clamped at >= 0 (downward acceleration needs no foot), |a_k| divided by the
    motion's maximum; foot speed = horizontal displacement of each FOOT_JOINT from frame k+1 to k+2 (per
    frame, not divided by dt: expressed at ``params.reference_fps``); per side the smaller of ankle and
    foot; score = mean_k(min_left * min_right * |a_k| / max|a|). Batch: mean over motions x 10000.
    A motion whose root never accelerates (peak below ``params.pfc_min_acceleration``) scores 0; EDGE
    would divide by zero, or blow rounding noise up to a full score.
    """
    return _one("pfc", joints, fps, lengths, mask, None, params)


def skating_ratio(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
                  params: MetricParams = PARAMS) -> float:  # fmt: skip
    """BioMoDiffuse foot-skating ratio (eq. 14), computed as the GMD code it cites.

    For each frame pair and toe joint (left_foot, right_foot): skating when the joint is below 5 cm in
    both frames, its horizontal speed exceeds 0.5 m/s, and its speed averaged over a 5-frame window
    (zero beyond the motion's ends, as ``uniform_filter1d(mode="constant")``) also exceeds 0.5 m/s. A
    pair skates when either foot does; ratio = skating pairs / (T - 1), then mean over motions. The paper's
    printed exp(-||...||) form cannot give its own table (real data 0.057; exp is 1 on every clean frame),
    so the frame fraction of the cited code is used.
    """
    return _one("skate_ratio", joints, fps, lengths, mask, None, params)


def float_ratio(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
                params: MetricParams = PARAMS) -> float:  # fmt: skip
    """BioMoDiffuse Floating (eq. 15): fraction of frames whose lowest joint is above h_ground = 5 cm.

    The flag f_F of eq. 15, averaged over frames, then over motions. Joints, not the body surface, as the
    paper says ("the lowest joint"). The exp(-||...||) wrapper is dropped: it equals 1 on every frame
    without the flag, so it cannot give the paper's real-data values (0.205 here, 0.000 for Clip).
    """
    return _one("float_ratio", joints, fps, lengths, mask, None, params)


def penetration_ratio(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
                      params: MetricParams = PARAMS) -> float:  # fmt: skip
    """BioMoDiffuse Ground Penetration (eq. 16): fraction of frames whose lowest joint is below the floor.

    The paper reuses h_ground = 5 cm, which would flag every grounded frame and contradicts its own
    real-data value (0.000 on HumanML3D, whose lowest joint never goes below y = 0); the threshold is the
    floor itself (``params.penetrate_height`` = 0). Frame fraction, then mean over motions.
    """
    return _one("penetrate_ratio", joints, fps, lengths, mask, None, params)


def clip_ratio(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
               params: MetricParams = PARAMS) -> float:  # fmt: skip
    """BioMoDiffuse Foot Clipping (eq. 17): fraction of frames whose toe joints are closer than 5 cm.

    The paper's flag says "exceeds" a 5 cm distance but its text describes feet "too close together";
    the text is followed (real data scores 0.000 in its table). Feet = left_foot/right_foot joints, 3-D
    distance. Frame fraction, then mean over motions.
    """
    return _one("clip_ratio", joints, fps, lengths, mask, None, params)


def speed(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
          params: MetricParams = PARAMS) -> float:  # fmt: skip
    """BioMoDiffuse Speed (eq. 18), m/s: mean over frames and joints of |p_j^i - p_j^(i-1)| / dt.

    Eq. 18 prints ||Theta^i|| / dt; a speed needs the frame-to-frame change, so the per-joint
    displacement is used (dt = 1/fps: 0.05 s for HumanML3D as in the paper). Mean over motions.
    """
    return _one("speed", joints, fps, lengths, mask, None, params)


def smoothness(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
               params: MetricParams = PARAMS) -> float:  # fmt: skip
    """BioMoDiffuse Smoothness (eq. 19), m/s^3: mean over frames and joints of |a^i - a^(i-1)| / dt.

    a = second difference / dt^2 per joint, |.| the Euclidean norm per joint (the paper does not say
    which norm or representation; its scale, 2.60 for real HumanML3D, is not reproducible from the text).
    Mean over motions.
    """
    return _one("smoothness", joints, fps, lengths, mask, None, params)


def velocity_consistency(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
                         params: MetricParams = PARAMS) -> float:  # fmt: skip
    """BioMoDiffuse VC (eq. 13): (1 - L - H) / (L + H) on the velocity spectrum.

    Phi is the motion as (T, 66); its time derivative is transformed along time (real FFT), the magnitude
    summed over the 66 channels and normalised to sum 1, so L (share below ``band_low_hz``, DC included)
    + mid + H (share at or above ``band_high_hz``) = 1 and VC = mid / (L + H). The paper gives no
    thresholds: we use 1 Hz and 5 Hz (Nyquist is 10 Hz at 20 fps). NaN for a motion with no movement.
    Mean over motions.
    """
    return _one("vc", joints, fps, lengths, mask, None, params)


def acceleration_consistency(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None,
                             mask: Mask = None, params: MetricParams = PARAMS) -> float:  # fmt: skip
    """BioMoDiffuse AC (eq. 13): :func:`velocity_consistency` on the second time derivative."""
    return _one("ac", joints, fps, lengths, mask, None, params)


def mpjpe(pred: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Per-frame global MPJPE in metres (not root-aligned): (..., T, 22, 3) x2 -> (..., T)."""
    pred, ref = np.asarray(pred, dtype=np.float64), np.asarray(ref, dtype=np.float64)
    if pred.shape != ref.shape or pred.shape[-2:] != (NUM_JOINTS, 3):
        raise ShapeError(f"pred and ref must share a shape (..., T, 22, 3), got {pred.shape} and {ref.shape}")
    return np.linalg.norm(pred - ref, axis=-1).mean(axis=-1)


def imitation_failure_rate(
    mpjpe: np.ndarray, tau: float = PARAMS.ifr_tau, *, lengths: Lengths = None
) -> float:
    """Morph's imitation failure rate (IFR): the fraction of motions whose imitation fails.

    mpjpe: per-motion values (B,) in metres, failing when > tau; or per-frame values (B, T), failing when
    any valid frame is > tau - Morph's early termination ("MPJPE between input and simulated pose exceeds
    0.5 m"), the default reading. ``lengths`` (B,) marks valid frames of a padded (B, T) array.
    """
    err = np.asarray(mpjpe, dtype=np.float64)
    if err.ndim == 1:
        if lengths is not None:
            raise ShapeError("lengths only applies to per-frame MPJPE of shape (B, T)")
        fails = err > tau
        valid_values = err
    elif err.ndim == 2:
        lens = _lengths(err.shape, lengths, None)
        valid = np.arange(err.shape[1])[None, :] < lens[:, None]
        fails = np.any((err > tau) & valid, axis=1)
        valid_values = err[valid]
    else:
        raise ShapeError(f"mpjpe must have shape (B,) or (B, T), got {err.shape}")
    if err.shape[0] == 0:
        raise ShapeError("mpjpe is empty")
    if not np.all(np.isfinite(valid_values)):
        raise ShapeError("mpjpe contains NaN or infinite values")
    return float(fails.mean())


def per_motion_metrics(
    joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
    body: BodySurface | None = None, params: MetricParams = PARAMS,
) -> dict[str, np.ndarray]:  # fmt: skip
    """Every metric of :data:`METRICS` but "ifr" for each motion: name -> (B,) values.

    Frame-pooled metrics give each motion's own frame mean; :func:`physical_metrics` weighs them by
    ``length - METRICS[name].offset``.
    """
    batch = _prepare(joints, fps, lengths, mask, body, params)
    out = {name: fn(batch) for name, fn in _PER_MOTION.items()}
    out["phys_err"] = out["penetrate"] + out["float"] + out["skate"]
    return {name: out[name] for name in METRICS if name in out}


def physical_metrics(joints: np.ndarray, fps: float = FPS, *, lengths: Lengths = None, mask: Mask = None,
                     body: BodySurface | None = None, params: MetricParams = PARAMS,
                     reference: np.ndarray | None = None) -> dict[str, float]:  # fmt: skip
    """All physical metrics of a motion (T, 22, 3) or a padded batch (B, T, 22, 3): name -> value.

    lengths (B,) or a prefix mask (B, T) mark valid frames; body swaps the surface geometry used by
    Penetrate/Float/Skate (see :class:`~physmotion.metrics.geometry.BodySurface`). With ``reference``
    (the input motion, same shape, when ``joints`` is its simulation) the result adds Morph's "ifr".
    Units and sources: :data:`METRICS`. Raises ShapeError on a wrong shape, NaN/inf or < 4 frames.
    """
    batch = _prepare(joints, fps, lengths, mask, body, params)
    values = {name: _aggregate(name, fn(batch), batch.lengths) for name, fn in _PER_MOTION.items()}
    values["phys_err"] = values["penetrate"] + values["float"] + values["skate"]
    if reference is not None:
        ref = _prepare(reference, fps, batch.lengths, None, body, params, name="reference")
        if ref.joints.shape != batch.joints.shape:
            raise ShapeError(f"reference must have the shape of joints, got {ref.joints.shape}")
        err = mpjpe(batch.joints, ref.joints)
        values["ifr"] = imitation_failure_rate(err, params.ifr_tau, lengths=batch.lengths)
    return {name: values[name] for name in METRICS if name in values}


def ragged_physical_metrics(joints: Sequence[np.ndarray], fps: float = FPS, *,
                            body: BodySurface | None = None) -> dict[str, float]:  # fmt: skip
    """:func:`physical_metrics` of motions of different lengths, each (T_i, 22, 3): padded with its last
    frame and masked by its length."""
    lengths = [len(j) for j in joints]
    padded = np.zeros((len(joints), max(lengths), *np.shape(joints[0])[1:]))
    for i, j in enumerate(joints):
        padded[i, : len(j)] = j
        padded[i, len(j) :] = j[-1]
    return physical_metrics(padded, fps, lengths=lengths, body=body)


def format_table(results: Mapping[str, Mapping[str, float]], title: str | None = None) -> Table:
    """A rich table of metric results: one row per metric (with unit and paper), one column per result.

    results: column name (a file, a method) -> metric name -> value, e.g. ``{"motion.npz":
    physical_metrics(joints)}``. Metrics missing from a column show as "-".
    """
    table = Table(title=title)
    for col, justify in (("metric", "left"), ("unit", "left"), ("paper", "left")):
        table.add_column(col, justify=justify)  # type: ignore[arg-type]
    for name in results:
        table.add_column(str(name), justify="right")
    known = METRICS | RECORDED
    present = [m for m in known if any(m in r for r in results.values())]
    present += sorted({k for r in results.values() for k in r} - set(known))
    for name in present:
        info = known.get(name)
        cells = [f"{r[name]:.3f}" if name in r else "-" for r in results.values()]
        table.add_row(name, info.unit if info else "", info.paper if info else "", *cells)
    return table
