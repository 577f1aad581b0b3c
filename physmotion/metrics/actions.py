"""Did a motion do what its verb says? Checks on generated joints for the actions HDM05 brought in.

All take joints (T, 22, 3) in metres, Y up, on the floor of the dataset's convention (the clip's lowest
joint at y = 0, as plain sampling gives them), and return the measured figure; the thresholds a test or a
table applies are :data:`ACTION_CHECKS` (issue 50's acceptance).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from physmotion.skeleton import JOINT_INDEX

_PELVIS = JOINT_INDEX["pelvis"]
_KNEES = [JOINT_INDEX["left_knee"], JOINT_INDEX["right_knee"]]
_FEET = {"left": [JOINT_INDEX["left_ankle"], JOINT_INDEX["left_foot"]],
         "right": [JOINT_INDEX["right_ankle"], JOINT_INDEX["right_foot"]]}  # fmt: skip


def squat_depth(joints: np.ndarray) -> tuple[float, float]:
    """(how far the pelvis goes down from its first-frame height, how far it comes back up from its lowest
    point by the last frame), metres."""
    y = joints[:, _PELVIS, 1]
    low = int(np.argmin(y))
    return float(y[0] - y[low]), float(y[low:].max() - y[low])


def kick_height(joints: np.ndarray) -> float:
    """The highest a foot (its ankle and toe joints) gets over the median height of the knees, metres:
    positive where one foot rises above knee height."""
    feet = joints[:, _FEET["left"] + _FEET["right"], 1].max()
    return float(feet - np.median(joints[:, _KNEES, 1]))


def final_pelvis_height(joints: np.ndarray) -> float:
    """Pelvis height over the floor at the last frame, metres (lying down ends low)."""
    return float(joints[-1, _PELVIS, 1] - joints[..., 1].min())


def flight_height(joints: np.ndarray) -> float:
    """The most both feet are off the floor at once: over frames, the lower of the two feet's lowest joint,
    measured from each foot's own lowest height in the clip (its stance level), metres."""
    lows = [joints[:, idx, 1].min(axis=1) for idx in _FEET.values()]  # (T,) per foot
    clear = np.minimum(*(low - low.min() for low in lows))
    return float(clear.max())


@dataclass(frozen=True)
class ActionCheck:
    """A verb's check: the figure measured and the least (or most) it must be."""

    verb: str
    what: str
    measure: Callable[[np.ndarray], float]
    threshold: float
    above: bool = True  # the figure must be at least the threshold (else at most)

    def passes(self, joints: np.ndarray) -> bool:
        return self.accepts(self.measure(joints))

    def accepts(self, value: float) -> bool:
        """Whether a measured figure passes the threshold."""
        return value >= self.threshold if self.above else value <= self.threshold


def _down_and_up(joints: np.ndarray) -> float:
    """The smaller of the squat's way down and its way back up: both must pass the threshold."""
    return min(squat_depth(joints))


ACTION_CHECKS: dict[str, ActionCheck] = {
    "squat": ActionCheck("squat", "pelvis down and back up, m (the smaller of the two)", _down_and_up, 0.25),
    "kick": ActionCheck("kick", "highest foot over knee height, m", kick_height, 0.0),
    "lie down": ActionCheck(
        "lie down", "pelvis height at the end, m", final_pelvis_height, 0.35, above=False
    ),
    "hop": ActionCheck("hop", "both feet off the floor at once, m", flight_height, 0.03),
}
