"""Where an imported motion meets the floor: one constant vertical shift, chosen where the body stands.

The physical metrics put the floor where the body *surface* stands (:data:`~physmotion.conventions.
FLOOR_SURFACE`, :mod:`physmotion.metrics.physical`), measured on the humanoid's collision geometry posed
on the joints (:class:`~physmotion.physics.surface.HumanoidSurface`, what ``physmotion metrics`` uses,
with a flat hand). The importer grounds a motion in that same convention:

1. contact frames: frames where a foot stands (some foot joint, ankle or toe, slower than
   :data:`STANCE_SPEED` and within :data:`STANCE_BAND` of the frame's lowest foot joint: a planted
   foot, not a foot held still in the air), or a hand does (its wrist slower than
   :data:`STANCE_SPEED` and the hand within :data:`STANCE_BAND` of the body's lowest point);
2. floor: the height f that minimises Penetrate + Float as the metrics define them (5 mm tolerance),
   Penetrate over every frame and Float over the contact frames only: a frame in the air may float, no
   frame may be in the floor. The sum is convex and piecewise linear in f; f is the middle of its
   minimisers (:func:`best_floor`, exact). The toe boxes bend where the floor meets them
   (:class:`~physmotion.physics.surface.HumanoidSurface`), so the lowest point depends on f: f is
   chosen again on the toes it bends until it stays. A clip with no contact frame (a hop
   cut from take-off to landing) puts its lowest point over the clip on the floor.

A capture floor tilted against the file's up axis (CMU's subjects 2, 5, 6 and 7 stand on a plane rising
up to 2 cm a metre) is levelled first (:func:`floor_tilt`): a plane fitted to the standing feet over the
directions the clip travels far enough to measure, and the whole clip rotated, root included, so that
plane is level. A rigid rotation of the world: no pose changes (docs/decisions/data.md, "a tilted
capture floor levelled").

Ground that is not level (a walk over steps or rough ground) has no single floor: where the body's lowest
point over the contact frames spreads wider than :data:`UNEVEN_GROUND`, :class:`Grounding` says so
(``level`` False) and the importer warns (:class:`UnevenGroundWarning`).

Hands count only in the frames where they touch the floor; a low hand elsewhere weighs like any
frame's lowest point, in Penetrate only. Every step moves with the motion (speeds, heights relative to
the frame), so grounding a grounded motion changes nothing. History (the earlier cap on Penetrate,
which made clips with one low frame float): docs/decisions/data.md "import floor".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from physmotion.conventions import FPS, UP_AXIS
from physmotion.errors import PhysmotionWarning, ShapeError
from physmotion.skeleton import FOOT_JOINTS, NUM_JOINTS

STANCE_SPEED: float = 0.15
"""m/s: a foot joint slower than this (to both neighbouring frames) may be planted."""
STANCE_BAND: float = 0.03
"""m: ... if it is within this of the frame's lowest foot joint (the other foot may be lifted)."""
UNEVEN_GROUND: float = 0.15
"""m: contact frames whose lowest points spread (5th to 95th percentile) wider than this stand on ground that
is not level. CMU's "walk on uneven terrain" takes spread 0.24-0.34 m, every other clip of our data at most
0.12 m (a body lying down; docs/decisions/data.md, "ground that is not level")."""
TILT_MIN: float = 0.005
"""Rise per metre of the fitted floor plane below which a clip is left as captured (Bandai's own floors
fit at most 0.4 % on the median clip)."""
TILT_MAX: float = 0.05
"""... and above which the plane is not a tilted floor but a walk up or down something: left alone."""
TILT_SPAN: float = 0.5
"""m: standard deviation of the standing feet's horizontal positions along a direction below which that
direction's slope is not measured (about 2 m of travel: a clip that stays in place has no slope to fit,
and over shorter spans HDM05's hops and lying down fitted 1-8 % from landings and bodies on the floor)."""
_TOLERANCE = 0.005  # m: the metrics' Penetrate and Float tolerance (MetricParams.tolerance)
_FLOOR_ROUNDS = 40  # at most, of choosing the floor and bending the toes to it (see ground()) ...
_FLOOR_SETTLED = 1e-7  # m: ... until it moves less than this

STANCE: str = "stance"
"""The import floor: least Penetrate + Float over the contact frames (this module)."""
FRAME0: str = "frame0"
"""The earlier import floor (docs/decisions/data.md: "import floor"): frame 0's lowest foot joint on
y = 0. Close to the data convention that the physics projection P takes as input
(:mod:`physmotion.physics.projection`), and what P's benches and tests were measured on, bit for bit."""
IMPORT_FLOORS: tuple[str, ...] = (STANCE, FRAME0)


@dataclass(frozen=True)
class Grounding:
    """What grounding did: ``lift`` metres added to y; the floor ``stance_floor`` it chose (m, before the
    shift: ``-lift``); the share of contact frames, and of them those where only a hand touches; and
    ``stance_spread``, how far apart (m, 5th to 95th percentile) the body's lowest point lies over the
    contact frames."""

    lift: float
    stance_floor: float
    stance_share: float
    hand_share: float
    stance_spread: float = 0.0
    tilt: float = 0.0
    """Degrees the floor was levelled by (:func:`floor_tilt`); 0 where it was left as captured."""

    @property
    def level(self) -> bool:
        """Whether the contact frames stand on one level floor (:data:`UNEVEN_GROUND`)."""
        return self.stance_spread <= UNEVEN_GROUND


class UnevenGroundWarning(PhysmotionWarning):
    """An imported clip stands on ground that is not level: a level floor leaves some of its steps in the
    floor or above it (:data:`UNEVEN_GROUND`)."""


def stance_frames(joints: np.ndarray, fps: float = FPS) -> np.ndarray:
    """(T,) bool: frames where some foot joint is planted (see the module docstring)."""
    feet = np.asarray(joints, dtype=np.float64)[:, list(FOOT_JOINTS)]  # (T, 4, 3)
    height = feet[..., UP_AXIS]
    low = height <= height.min(axis=-1, keepdims=True) + STANCE_BAND
    return (_slow(feet, fps) & low).any(axis=-1)


def hand_frames(joints: np.ndarray, hands: np.ndarray, lowest: np.ndarray, fps: float = FPS) -> np.ndarray:
    """(T,) bool: frames where a hand rests on the floor: its wrist slower than :data:`STANCE_SPEED` and
    the hand (heights ``hands`` (T, 2)) within :data:`STANCE_BAND` of the body's lowest point ``lowest`` (T,)."""
    from physmotion.physics.surface import HAND_JOINTS

    wrists = np.asarray(joints, dtype=np.float64)[:, list(HAND_JOINTS)]  # (T, 2, 3)
    return (_slow(wrists, fps) & (hands <= lowest[:, None] + STANCE_BAND)).any(axis=-1)


def _slow(points: np.ndarray, fps: float) -> np.ndarray:
    """(T, K) bool: points (T, K, 3) slower than STANCE_SPEED to both neighbouring frames."""
    speed = np.linalg.norm(np.diff(points, axis=0), axis=-1) * fps  # (T-1, K)
    slow = np.ones(points.shape[:2], dtype=bool)
    slow[:-1] &= speed < STANCE_SPEED
    slow[1:] &= speed < STANCE_SPEED
    return slow


def best_floor(lowest: np.ndarray, contact: np.ndarray) -> float:
    """The floor f (m) with the least Penetrate (every frame) + Float (contact frames), exactly.

    lowest: (T,) the body's lowest surface point per frame; contact: (T,) bool, not all False.
    Penetrate grows by 1/T per frame with lowest < f - tol and Float falls by 1/T per contact frame with
    lowest > f + tol: the sum is convex, its slope steps at those breakpoints; the answer is the middle
    of the interval where the slope changes sign (so a constant shift of ``lowest`` shifts f alike).
    """
    low = np.asarray(lowest, dtype=np.float64)
    under = np.sort(low + _TOLERANCE)  # f beyond these: that frame penetrates
    over = np.sort(low[contact] - _TOLERANCE)  # f below these: that contact frame floats
    points = np.concatenate([under, over])
    right = np.searchsorted(under, points, "right") - (len(over) - np.searchsorted(over, points, "right"))
    left = np.searchsorted(under, points, "left") - (len(over) - np.searchsorted(over, points, "left"))
    lo = points[right >= 0].min()  # the lowest minimiser: the first breakpoint the slope leaves <= 0 at
    hi = points[left <= 0].max()  # the highest: the last the slope reaches >= 0 at
    return float(0.5 * (lo + hi))


def floor_tilt(joints: np.ndarray, fps: float = FPS) -> np.ndarray:
    """(3, 3) the rotation that levels the floor the standing feet of ``joints`` (T, 22, 3, metres, Y up)
    stand on; the identity where the clip's floor is level, unmeasurable or no floor at all.

    The body's lowest surface point over the stance frames is fitted, least squares, by a plane over the
    horizontal position of the lowest foot joint, along the principal directions of those positions
    whose spread reaches :data:`TILT_SPAN` (a slope across a straight walk cannot be seen, so it is taken
    as 0). A slope under :data:`TILT_MIN` or over :data:`TILT_MAX`, or standing points spread off the
    plane wider than :data:`UNEVEN_GROUND` (steps, not a tilt), is left alone; levelling a levelled clip
    finds no slope."""
    from physmotion.physics.surface import HumanoidSurface

    x = np.asarray(joints, dtype=np.float64)
    stance = stance_frames(x, fps)
    if stance.sum() < 3:
        return np.eye(3)
    lowest = HumanoidSurface().lowest_height(x, floor=np.inf)[stance]  # (S,) planted: toes pressed
    feet = x[stance][:, list(FOOT_JOINTS)]  # (S, 4, 3)
    foot = feet[np.arange(len(feet)), feet[..., UP_AXIS].argmin(axis=1)][:, [0, 2]]  # (S, 2) x, z
    centred = foot - foot.mean(axis=0)
    variance, directions = np.linalg.eigh(centred.T @ centred / len(centred))
    measured = directions[:, np.sqrt(np.maximum(variance, 0.0)) >= TILT_SPAN]  # (2, D)
    if measured.shape[1] == 0:
        return np.eye(3)
    design = np.column_stack([centred @ measured, np.ones(len(centred))])
    coef = np.linalg.lstsq(design, lowest, rcond=None)[0]
    slope = measured @ coef[:-1]  # (2,) rise per metre along x and z
    off_plane = np.subtract(*np.percentile(lowest - design @ coef, [95, 5]))
    if not TILT_MIN <= np.linalg.norm(slope) <= TILT_MAX or off_plane > UNEVEN_GROUND:
        return np.eye(3)
    normal = np.array([-slope[0], 1.0, -slope[1]])
    return Rotation.align_vectors([[0.0, 1.0, 0.0]], [normal])[0].as_matrix()  # the shortest turn onto +Y


def ground(joints: np.ndarray, fps: float = FPS) -> tuple[np.ndarray, Grounding]:
    """``joints`` (T, 22, 3) metres, Y up, shifted vertically onto the floor; and what was done."""
    from physmotion.physics.surface import HumanoidSurface  # MuJoCo: only when a motion is imported

    x = np.asarray(joints, dtype=np.float64)
    if x.ndim != 3 or x.shape[1:] != (NUM_JOINTS, 3) or len(x) == 0:
        raise ShapeError(f"joints must be (T, 22, 3), got {x.shape}")
    surface = HumanoidSurface()
    lowest = surface.lowest_height(x, floor=np.inf)  # (T,) the body's lowest surface point, toes pressed
    feet = stance_frames(x, fps)
    hands = hand_frames(x, surface.hand_heights(x), lowest, fps)
    contact = feet | hands
    floor = float(lowest.min())  # no contact: all in motion, the lowest point on the floor
    if contact.any():
        # The toes bend where the floor meets them, so the lowest point depends on the floor chosen:
        # iterate to the floor that is best for the toes it bends. Most clips settle in 1-2 rounds; where
        # the bent toes bound the best interval, its middle moves half the way each round (geometric).
        for _ in range(_FLOOR_ROUNDS):
            floor, before = best_floor(lowest, contact), floor
            if abs(floor - before) < _FLOOR_SETTLED:
                break
            lowest = surface.lowest_height(x, floor=floor)
    spread = float(np.subtract(*np.percentile(lowest[contact], [95, 5]))) if contact.any() else 0.0
    out = x.copy()
    out[..., UP_AXIS] -= floor
    return out, Grounding(-floor, floor, float(contact.mean()), float((hands & ~feet).mean()), spread)
