"""Where an imported motion meets the floor: its stance soles on y = 0, over the whole clip.

The physical metrics put the floor where the body *surface* stands (:data:`~physmotion.conventions.
FLOOR_SURFACE`, :mod:`physmotion.metrics.physical`), measured on the humanoid's collision geometry posed
on the joints (:class:`~physmotion.physics.surface.HumanoidSurface`, what ``physmotion metrics`` uses).
The importer grounds a motion in that same convention, by one constant vertical shift:

1. stance frames: frames where some foot joint (ankle or toe) is slower than :data:`STANCE_SPEED` and
   within :data:`STANCE_BAND` of the frame's lowest foot joint (a planted foot, not a foot held still in
   the air);
2. floor: the median, over the stance frames, of the body's lowest surface point, so the stance soles
   stand on y = 0 (a median, because box feet dip a corner under the flat stance at heel strike and
   toe-off, and capture has outliers); a clip with no stance frame (a hop cut from take-off to landing)
   puts its lowest point over the clip on the floor;
3. cap: where that leaves the metrics' Penetrate above :data:`PENETRATE_CAP` (uneven ground in the
   capture, a body lying lower than its feet stood, the humanoid's capsules thicker than the actor),
   the motion is raised just enough to bring it down to the cap.

Every step moves with the motion (percentiles of heights, speeds), so grounding a grounded motion
changes nothing: an export -> import round trip returns the motion where it was (docs/decisions/data.md
"import floor").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physmotion.conventions import FPS, UP_AXIS
from physmotion.errors import ShapeError
from physmotion.skeleton import FOOT_JOINTS, NUM_JOINTS

STANCE_SPEED: float = 0.15
"""m/s: a foot joint slower than this (to both neighbouring frames) may be planted."""
STANCE_BAND: float = 0.03
"""m: ... if it is within this of the frame's lowest foot joint (the other foot may be lifted)."""
PENETRATE_CAP: float = 1.5
"""mm: most Penetrate (the metrics' measure, 5 mm tolerance) an imported motion keeps."""
_TOLERANCE = 0.005  # m: the metrics' Penetrate tolerance (MetricParams.tolerance)

STANCE: str = "stance"
"""The import floor: the stance soles over the whole clip on y = 0 (this module)."""
FRAME0: str = "frame0"
"""The earlier import floor (docs/decisions/data.md: "import floor"): frame 0's lowest foot joint on
y = 0. Close to the data convention that the physics projection P takes as input
(:mod:`physmotion.physics.projection`), and what P's benches and tests were measured on, bit for bit."""
IMPORT_FLOORS: tuple[str, ...] = (STANCE, FRAME0)


@dataclass(frozen=True)
class Grounding:
    """What grounding did: ``lift`` metres added to y (the stance rule, then the cap), the stance
    rule's floor ``stance_floor`` (m, before the shift), the share of stance frames, and whether the
    Penetrate cap raised the motion (``capped``)."""

    lift: float
    stance_floor: float
    stance_share: float
    capped: bool


def stance_frames(joints: np.ndarray, fps: float = FPS) -> np.ndarray:
    """(T,) bool: frames where some foot joint is planted (see the module docstring)."""
    feet = np.asarray(joints, dtype=np.float64)[:, list(FOOT_JOINTS)]  # (T, 4, 3)
    speed = np.linalg.norm(np.diff(feet, axis=0), axis=-1) * fps  # (T-1, 4)
    slow = np.ones(feet.shape[:2], dtype=bool)
    slow[:-1] &= speed < STANCE_SPEED
    slow[1:] &= speed < STANCE_SPEED
    height = feet[..., UP_AXIS]
    low = height <= height.min(axis=-1, keepdims=True) + STANCE_BAND
    return (slow & low).any(axis=-1)


def ground(joints: np.ndarray, fps: float = FPS) -> tuple[np.ndarray, Grounding]:
    """``joints`` (T, 22, 3) metres, Y up, shifted vertically onto the floor; and what was done."""
    from physmotion.physics.surface import HumanoidSurface  # MuJoCo: only when a motion is imported

    x = np.asarray(joints, dtype=np.float64)
    if x.ndim != 3 or x.shape[1:] != (NUM_JOINTS, 3) or len(x) == 0:
        raise ShapeError(f"joints must be (T, 22, 3), got {x.shape}")
    lowest = HumanoidSurface().lowest_height(x)  # (T,) the body's lowest surface point
    stance = stance_frames(x, fps)
    floor = float(np.median(lowest[stance]) if stance.any() else lowest.min())  # no stance: all in motion
    capped_floor = _highest_floor(lowest, PENETRATE_CAP / 1000.0)
    capped = capped_floor < floor
    lift = -min(floor, capped_floor)
    out = x.copy()
    out[..., UP_AXIS] += lift
    return out, Grounding(lift, floor, float(stance.mean()), bool(capped))


def _highest_floor(lowest: np.ndarray, cap: float) -> float:
    """The highest floor f with mean(max(0, f - tol - lowest)) <= cap (the metrics' Penetrate), exactly.

    The mean is piecewise linear and increasing in f: with the heights sorted, on the piece where the
    k lowest frames are under f - tol it is (k (f - tol) - sum of those k) / T.
    """
    a = np.sort(np.asarray(lowest, dtype=np.float64))
    n = len(a)
    g = (cap * n + np.cumsum(a)) / np.arange(1, n + 1)  # f - tol where the mean over the k lowest is the cap
    fits = np.append(g[:-1] <= a[1:], True)  # ... on its own piece (the first such k is the answer)
    return float(g[np.argmax(fits)] + _TOLERANCE)

