"""A light-weight body surface posed from joint positions alone: the ground metrics' stand-in for a mesh.

PhysDiff measures Penetrate and Float with the lowest vertex of the SMPL body mesh. We have no SMPL
mesh, so this module **replaces the mesh vertices with the collision geometry of our physics humanoid**
(:mod:`physmotion.physics.humanoid`, itself PHC's ``smpl_humanoid.xml`` geoms), rebuilt from the 22
joints (T, 22, 3) with numpy only and the same sizing rules:

- bones: capsules around the segment joint -> child from ``start`` to ``end`` of it (0.2..0.8 for limbs,
  as in PHC), with the humanoid's radius per bone;
- pelvis and head: spheres on the joint;
- hands: the humanoid's flat box along the forearm direction, 0.02..0.19 m past the wrist, 1.6 cm half
  thick (5.4 cm half wide);
- feet: the ankle box, with a heel 6.1 cm behind the ankle and its front 1 cm short of the foot joint, and
  the toe box on the foot joint; both soles lie 14.5 mm below the foot joint at rest.

Every size scales with the body, as the humanoid's do: by the ratio of the frame's summed bone lengths to
the default body's (1 for :func:`physmotion.skeleton.rest_joints`), and the ankle box's length and depth
follow the frame's own ankle -> foot segment.

Joint positions do not fix a foot's roll, a hand's roll or the toe joint's bend, so (written here because
they decide the numbers): the ankle box pitches with the ankle -> foot segment and never rolls (the sole
stays level side to side); the toe box stays level (toes flexed flat, as whenever they bear weight); the
hand box lies palm-down (its thin side toward the floor, as when a hand bears weight). Yaw never changes a
height.

Heights only: every function returns the lowest point of each part, which is all the ground metrics need.
To use other geometry (the MuJoCo model's own geoms, a real mesh), pass any object with the two methods
of :class:`BodySurface` where a ``body`` is accepted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from physmotion.skeleton import FOOT_JOINTS, JOINT_INDEX, REST_OFFSETS, bone_lengths

_J = JOINT_INDEX
_REST_SIZE = float(np.linalg.norm(REST_OFFSETS, axis=-1).sum())  # summed bone lengths of the default body


@runtime_checkable
class BodySurface(Protocol):
    """What the ground metrics need from a body model; swap in the MuJoCo geometry by implementing it."""

    def lowest_height(self, joints: np.ndarray) -> np.ndarray:
        """Height (y, metres) of the lowest surface point per frame. joints: (..., T, 22, 3) -> (..., T)."""
        ...

    def foot_heights(self, joints: np.ndarray) -> np.ndarray:
        """Height of each foot joint's contact patch (heel for an ankle, toes for a foot joint).

        joints: (..., T, 22, 3) -> (..., T, 4) in FOOT_JOINTS order: left heel, left toes, right heel,
        right toes. Skate counts a foot joint as in contact when its patch is within 5 mm of the floor.
        """
        ...


@dataclass(frozen=True)
class Capsule:
    """A capsule around the bone ``joint`` -> ``child``, from fraction ``start`` to ``end`` of it."""

    joint: int
    child: int
    start: float
    end: float
    radius: float  # metres, default body


def _limbs(joint: str, child: str, radius: float) -> tuple[Capsule, Capsule]:
    return tuple(  # type: ignore[return-value]
        Capsule(_J[f"{side}_{joint}"], _J[f"{side}_{child}"], 0.2, 0.8, radius) for side in ("left", "right")
    )


@dataclass(frozen=True)
class BodyGeometry:
    """Sizes of the default body's surface (metres, scaled per frame with the body), and its posing.

    Values are those of :mod:`physmotion.physics.humanoid` (from PHC's smpl_humanoid.xml). Implements
    :class:`BodySurface`. Foot boxes are given in the left foot's rest frame (x outward, y up, z forward).
    """

    capsules: tuple[Capsule, ...] = (
        *_limbs("hip", "knee", 0.061), *_limbs("knee", "ankle", 0.0541),
        *_limbs("collar", "shoulder", 0.0516), *_limbs("shoulder", "elbow", 0.0524),
        *_limbs("elbow", "wrist", 0.0407),
        Capsule(_J["spine1"], _J["spine2"], 0.45, 0.55, 0.0769),
        Capsule(_J["spine2"], _J["spine3"], 0.45, 0.55, 0.0755),
        Capsule(_J["spine3"], _J["neck"], 0.32, 0.39, 0.1002),
        Capsule(_J["neck"], _J["head"], 0.2, 0.8, 0.0436),
    )  # fmt: skip
    spheres: tuple[tuple[int, float], ...] = ((_J["pelvis"], 0.0942), (_J["head"], 0.1011))
    hand_start: float = 0.02  # hand box along the forearm direction, from the wrist
    hand_end: float = 0.19
    hand_half_thickness: float = 0.016
    sole_below_toe: float = 0.0145  # both soles, below the foot joint at rest
    heel_length: float = 0.061  # ankle box back, behind the ankle
    heel_front_gap: float = 0.010  # ankle box front, short of the foot joint
    heel_top: float = 0.0225  # ankle box top, above the ankle
    heel_half_width: float = 0.0483
    heel_lateral: float = 0.9  # ankle box centre, sideways, as a fraction of the foot joint's
    scale_with_body: bool = True

    def part_heights(self, joints: np.ndarray) -> np.ndarray:
        """Lowest point of every part. joints: (..., T, 22, 3) -> (..., T, P).

        Parts, in order: capsules, spheres, 2 hands (left, right), then the whole foot boxes in FOOT_JOINTS
        order (left ankle box, left toe box, right ankle box, right toe box).
        """
        j = np.asarray(joints, dtype=np.float64)
        s = self._scale(j)
        caps = self.capsules
        a, b = j[..., [c.joint for c in caps], 1], j[..., [c.child for c in caps], 1]
        start, end = np.array([c.start for c in caps]), np.array([c.end for c in caps])
        capsules = np.minimum(a + start * (b - a), a + end * (b - a)) - s * np.array([c.radius for c in caps])
        spheres = j[..., [i for i, _ in self.spheres], 1] - s * np.array([r for _, r in self.spheres])
        feet = self._foot_heights(j, s, patch=False)
        return np.concatenate([capsules, spheres, self._hand_heights(j, s), feet], axis=-1)

    def lowest_height(self, joints: np.ndarray) -> np.ndarray:
        """Height of the lowest surface point per frame: (..., T, 22, 3) -> (..., T)."""
        return self.part_heights(joints).min(axis=-1)

    def foot_heights(self, joints: np.ndarray) -> np.ndarray:
        """Contact patches of the foot joints: (..., T, 22, 3) -> (..., T, 4) in FOOT_JOINTS order.

        An ankle's patch is its heel, the ankle box's sole behind the ankle (the box's front is the ball of
        the foot, which rolls on the floor at toe-off while the ankle moves on: no contact of the ankle);
        a foot joint's patch is the toe box.
        """
        j = np.asarray(joints, dtype=np.float64)
        return self._foot_heights(j, self._scale(j))

    def _scale(self, j: np.ndarray) -> np.ndarray:
        """(..., T, 1) body size relative to the default body (the humanoid's ``body_scale``)."""
        if not self.scale_with_body:
            return np.ones(j.shape[:-2] + (1,))
        return bone_lengths(j).sum(axis=-1, keepdims=True) / _REST_SIZE

    def _hand_heights(self, j: np.ndarray, s: np.ndarray) -> np.ndarray:
        elbow = j[..., [_J["left_elbow"], _J["right_elbow"]], :]
        wrist = j[..., [_J["left_wrist"], _J["right_wrist"]], :]
        d = wrist - elbow
        u_y = d[..., 1] / np.maximum(np.linalg.norm(d, axis=-1), 1e-9)
        across = np.sqrt(np.maximum(1.0 - u_y**2, 0.0))  # palm-down: the thin half-size faces the floor
        ends = np.minimum(self.hand_start * u_y, self.hand_end * u_y)
        return wrist[..., 1] + s * (ends - self.hand_half_thickness * across)

    def _foot_heights(self, j: np.ndarray, s: np.ndarray, patch: bool = True) -> np.ndarray:
        """(..., T, 4) ankle and toe boxes: their heel/toe contact patches, or (patch=False) whole boxes."""
        la, lf, ra, rf = FOOT_JOINTS
        toe_sole = s[..., 0] * self.sole_below_toe  # the toe box stays level
        k = 1 if patch else 0
        left = self._ankle_box(j[..., la, :], j[..., lf, :], s[..., 0])[k]
        right = self._ankle_box(j[..., ra, :], j[..., rf, :], s[..., 0])[k]
        return np.stack([left, j[..., lf, 1] - toe_sole, right, j[..., rf, 1] - toe_sole], axis=-1)

    def _ankle_box(self, ankle: np.ndarray, foot: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lowest point of the ankle box, and of its heel (the sole behind the ankle): two (...,) arrays.

        The box is built at rest for this foot's length (the humanoid keeps the default directions for a
        motion's body: the foot joint at ``length * rest_dir`` from the ankle), then rotated by
        Ry(yaw) Rx(pitch - rest_pitch) Ry(-rest_yaw). Only the rotation's y row matters for a height and
        Ry(yaw) leaves that row alone, so the heading never enters (nor its degenerate case, a foot
        pointing straight down). Left and right feet, mirror images, give the same formula.
        """
        rest = REST_OFFSETS[_J["left_foot"]] / np.linalg.norm(REST_OFFSETS[_J["left_foot"]])
        rest_yaw, rest_pitch = np.arctan2(rest[0], rest[2]), np.arctan2(-rest[1], np.hypot(rest[0], rest[2]))
        d = foot - ankle
        toe = np.linalg.norm(d, axis=-1)[..., None] * rest  # foot joint at rest, relative to the ankle
        sole, top = toe[..., 1] - s * self.sole_below_toe, s * self.heel_top
        back, front = -s * self.heel_length, toe[..., 2] - s * self.heel_front_gap
        lateral = self.heel_lateral * toe[..., 0]
        center = np.stack([lateral, 0.5 * (sole + top), 0.5 * (back + front)], axis=-1)
        half = np.stack([s * self.heel_half_width, 0.5 * (top - sole), 0.5 * (front - back)], axis=-1)
        alpha = np.arctan2(-d[..., 1], np.hypot(d[..., 0], d[..., 2])) - rest_pitch  # nose-down positive
        sa, ca = np.sin(alpha), np.cos(alpha)
        row = np.stack([-sa * np.sin(rest_yaw), ca, -sa * np.cos(rest_yaw)], axis=-1)  # y row of Rx @ Ry
        box = ankle[..., 1] + (row * center).sum(axis=-1) - (np.abs(row) * half).sum(axis=-1)
        # The heel: the sole's corners at the back and under the ankle (a face's lowest point is a corner).
        heel = np.full(box.shape, np.inf)
        for x in (center[..., 0] - half[..., 0], center[..., 0] + half[..., 0]):
            for z in (back, np.zeros_like(back)):
                heel = np.minimum(heel, row[..., 0] * x + row[..., 1] * sole + row[..., 2] * z)
        return box, ankle[..., 1] + heel


DEFAULT_BODY = BodyGeometry()


def lowest_surface_height(joints: np.ndarray, body: BodySurface = DEFAULT_BODY) -> np.ndarray:
    """Height of the body's lowest surface point per frame, metres: (..., T, 22, 3) -> (..., T).

    The stand-in for PhysDiff's "lowest body mesh vertex"; ``body`` is pluggable (see BodySurface).
    """
    return body.lowest_height(joints)
