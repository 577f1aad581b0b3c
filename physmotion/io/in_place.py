"""Motions for game loops: in place (no horizontal root travel) and trimmed to a loop.

``generate --in-place`` / ``export --in-place`` and ``export --loop`` (docs/cli.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from physmotion.conventions import UP_AXIS
from physmotion.errors import PhysmotionError
from physmotion.motion import Motion
from physmotion.skeleton import facing_direction

_HORIZONTAL = [a for a in range(3) if a != UP_AXIS]
LOOP_SEARCH_SHARE = 0.3
"""A loop starts in the first and ends in the last this share of the frames."""


def in_place(motion: Motion) -> Motion:
    """``motion`` with the root's horizontal travel removed: every frame shifted horizontally so the root
    stays over the origin. Heading (the rotations) and vertical motion are kept; joints (T, 22, 3)."""
    joints = np.asarray(motion.joints, dtype=np.float64).copy()
    shift = joints[:, :1, _HORIZONTAL].copy()  # (T, 1, 2)
    joints[:, :, _HORIZONTAL] -= shift
    return replace(motion, joints=joints.astype(np.float32))


@dataclass(frozen=True)
class Loop:
    """The best loop of a motion: frames ``start`` to ``end`` (exclusive; frame ``end`` is the pose that
    follows the loop's last frame, close to frame ``start``), and ``distance``, the mean joint distance (m)
    between the poses at ``start`` and ``end`` with the root's horizontal offset and heading removed."""

    start: int
    end: int
    distance: float


def best_loop(joints: np.ndarray, share: float = LOOP_SEARCH_SHARE) -> Loop:
    """The start (first ``share`` of the frames) and end (last ``share``) whose poses are closest.

    joints: (T, 22, 3), T >= 4. Each pose is taken relative to its root, horizontally, and turned to face +Z,
    so a walk cycle matches wherever and whichever way it goes.
    """
    x = np.asarray(joints, dtype=np.float64)
    n = len(x)
    if n < 4:
        raise PhysmotionError(f"a loop needs at least 4 frames, the motion has {n}")
    local = x.copy()
    local[:, :, _HORIZONTAL] -= x[:, :1, _HORIZONTAL]
    forward = facing_direction(x)  # (T, 3)
    yaw = np.arctan2(forward[:, 0], forward[:, 2])
    c, s = np.cos(-yaw), np.sin(-yaw)
    turn = np.zeros((n, 3, 3))
    turn[:, 0, 0], turn[:, 0, 2], turn[:, 1, 1], turn[:, 2, 0], turn[:, 2, 2] = c, s, 1.0, -s, c
    local = np.einsum("tij,tkj->tki", turn, local)
    span = max(1, int(round(share * n)))
    starts = np.arange(0, span)
    ends = np.arange(n - span, n)
    dist = np.linalg.norm(local[starts][:, None] - local[ends][None], axis=-1).mean(axis=-1)  # (S, E)
    dist[ends[None, :] - starts[:, None] < 2] = np.inf
    i, k = np.unravel_index(np.argmin(dist), dist.shape)
    return Loop(int(starts[i]), int(ends[k]), float(dist[i, k]))


def trim_to_loop(motion: Motion, loop: Loop) -> Motion:
    """Frames ``loop.start`` .. ``loop.end - 1`` of ``motion`` (every per-frame array cut alike)."""
    cut = slice(loop.start, loop.end)
    changes: dict[str, object] = {"joints": motion.joints[cut]}
    for name in ("rotations", "residual", "over_limit", "residual_peak", "residual_at_cap", "reset_frames"):
        value = getattr(motion, name)
        if value is not None:
            changes[name] = value[cut]
    return replace(motion, **changes)


def horizontal_travel(joints: np.ndarray) -> float:
    """The largest horizontal distance (m) of the root from its frame-0 position; joints (T, 22, 3)."""
    root = np.asarray(joints, dtype=np.float64)[:, 0, _HORIZONTAL]
    return float(np.linalg.norm(root - root[0], axis=-1).max())
