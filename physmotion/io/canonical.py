"""From a rig motion in its file's units, axes and rate to the project's conventions (HumanML3D's).

Steps, in order, and why in that order:

1. T-pose check on the first frames (at the file's rate, before resampling would smear the frame).
2. Resample the *rig* to 20 fps: slerp of every local rotation, linear root / animated translations,
   then one FK, so bone lengths stay exactly constant (resampling joint positions would not).
3. Map rig nodes to the 22 SMPL joints (:class:`~physmotion.io.rigs.RigTable`), scale to metres,
   rotate the up axis to +Y (a proper rotation: handedness is kept).
4. Fit the 22-joint body: offsets from :func:`skeleton.offsets_from_joints`, local rotations from
   :func:`skeleton.inverse_kinematics`, and joints := FK of those. Rig points that SMPL's tree
   holds rigid but the rig does not (CMU bends its spine at the pelvis; its clavicles start on the
   midline) cannot be reproduced exactly; replacing the joints by their FK keeps ``Motion.joints``,
   ``rotations`` and ``offsets`` consistent (as HumanML3D's uniform-skeleton step does). The pelvis
   frame is fixed by the hips first (:func:`_rigid_pelvis`), so legs and feet stay exact and the
   misfit sits at spine1 (measured: :attr:`Canonical.fit_mean`, ``fit_max``).
5. Place: the root's XZ at the origin at frame 0, the body facing +Z at frame 0
   (:func:`skeleton.facing_direction`; its left is then +X), a capture floor tilted against the up
   axis levelled (:func:`physmotion.io.floor.floor_tilt`), and the stance soles over the whole clip
   on y = 0, the physical metrics' floor (:func:`physmotion.io.floor.ground`; frame 0's lowest foot
   joint, the rule before, left captured clips 2-3 cm in the floor and moved exported motions).
   A rig whose files are already placed (:attr:`RigTable.placed`: our own BVH export) keeps the
   file's position and facing: re-estimating the facing turned a generated motion by 1-5 degrees and
   re-grounding moved it 3-15 mm (docs/decisions/data.md "import floor").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from physmotion.conventions import FPS
from physmotion.errors import MotionFormatError, PhysmotionError
from physmotion.io.floor import FRAME0, IMPORT_FLOORS, STANCE, Grounding, floor_tilt, ground
from physmotion.io.rigs import RigMotion, RigTable
from physmotion.skeleton import (
    FOOT_JOINTS,
    JOINT_INDEX,
    check_bone_lengths,
    facing_direction,
    forward_kinematics,
    inverse_kinematics,
    offsets_from_joints,
    unit_vectors,
)

# Z-up -> Y-up is a -90 degree turn about X: (x, y, z) -> (x, z, -y); X-up -> Y-up a +90 degree
# turn about Z: (x, y, z) -> (-y, x, z). Both are proper rotations, so no mirroring. Public: the export
# onto a user's rig (io/retarget_rig.py) turns our axes into the file's with the same table.
TO_Y_UP = {
    "Y": np.eye(3),
    "Z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
    "X": np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
}

# T-pose test thresholds (cosines) and the pose jump that marks frame 0 as not part of the motion.
_TPOSE_ARM_LEVEL = np.cos(
    np.radians(70.0)
)  # upper arm and forearm within 20 deg of perpendicular to the trunk
_TPOSE_ARM_OUT = np.cos(np.radians(30.0))  # ... and pointing out sideways
_TPOSE_STRAIGHT = np.cos(
    np.radians(30.0)
)  # thighs, shins within 30 deg of the trunk (CMU's rest legs splay 20)
MAX_FRAMES = 1_000_000
"""Most frames an import may produce: about 14 hours at 20 fps, far beyond any take."""
_TPOSE_JUMP_M = 0.05  # mean joint displacement frame 0 -> 1, root-relative, metres
_TPOSE_JUMP_RATIO = 5.0  # ... and that many times the displacement frame 1 -> 2


@dataclass
class Canonical:
    """A motion in the project's conventions.

    joints: (T, 22, 3) float64 metres, Y up, FPS, stance soles on y = 0 (:mod:`physmotion.io.floor`),
    root XZ at the origin and facing +Z at frame 0; equal to FK of (rotations, joints[:, 0], offsets).
    rotations: (T, 22, 3, 3) local rotations; offsets: (22, 3) rest offsets, metres.
    dropped_tpose: whether a T-pose frame 0 was detected and removed.
    fit_mean, fit_max: (22,) mean and largest distance (m) per joint between the mapped rig point
    and the fitted 22-joint body (0 where the rig has SMPL's rigid parts, e.g. Bandai).
    grounding: how the motion was put on the floor.
    """

    joints: np.ndarray
    rotations: np.ndarray
    offsets: np.ndarray
    dropped_tpose: bool
    fit_mean: np.ndarray
    fit_max: np.ndarray
    grounding: Grounding


def canonicalize(
    rig: RigMotion,
    table: RigTable,
    fps: float,
    *,
    units: float,
    up_axis: str = "Y",
    drop_tpose: bool = True,
    floor: str = STANCE,
) -> Canonical:
    """Bring a rig motion to the project's conventions (see the module docstring).

    rig: in file units and axes; fps: its true frame rate; units: metres per file unit;
    up_axis: the file's world up axis ("X", "Y" or "Z"); floor: :data:`~physmotion.io.floor.STANCE`
    (the stance soles on y = 0) or :data:`~physmotion.io.floor.FRAME0` (the rule before, for P's input);
    neither applies to a ``table.placed`` rig, whose files keep their placement.
    """
    if up_axis not in TO_Y_UP:
        raise PhysmotionError(f"up axis must be one of X, Y, Z, got {up_axis!r}")
    if floor not in IMPORT_FLOORS:
        raise PhysmotionError(f"floor must be one of {', '.join(IMPORT_FLOORS)}, got {floor!r}")
    if not (np.isfinite(fps) and fps > 0):
        raise PhysmotionError(f"frame rate must be positive, got {fps}")
    out_frames = (rig.num_frames - 1) * FPS / fps + 1
    if out_frames > MAX_FRAMES:  # e.g. a Frame Time of 1e308 s: the resampled motion would not fit in memory
        raise PhysmotionError(
            f"a frame rate of {fps:.3g} fps makes {out_frames:.3g} frames at {FPS} fps "
            f"(more than {MAX_FRAMES}): give the true rate with --fps"
        )
    rig = rig.subset(table.nodes())
    weights = table.weights(rig.names)
    to_world = TO_Y_UP[up_axis] * units

    def smpl_points(r: RigMotion) -> np.ndarray:
        return np.einsum("ij,tjk,lk->til", weights, r.forward_kinematics(), to_world)

    dropped = drop_tpose and rig.num_frames >= 3 and is_tpose_start(smpl_points(rig.frames(slice(0, 3))))
    if dropped:
        rig = rig.frames(slice(1, None))
    raw = smpl_points(resample(rig, fps, FPS))
    if not np.all(np.isfinite(raw)):
        raise MotionFormatError("the motion has NaN or infinite joint positions")
    rigid = _rigid_pelvis(raw)
    offsets = offsets_from_joints(rigid)
    check_bone_lengths(offsets, "its two joints sit on one rig point (check the rig table or mapping)")
    rotations, root = inverse_kinematics(rigid, offsets)
    joints = forward_kinematics(rotations, root, offsets)
    misfit = np.linalg.norm(joints - raw, axis=-1)
    if table.placed:  # our own export: already placed and on the floor; placing again would move it
        grounding = Grounding(0.0, 0.0, 0.0, 0.0)
    elif floor == FRAME0:
        joints, rotations = _place(joints, rotations, frame0_floor=True)
        grounding = Grounding(0.0, 0.0, 0.0, 0.0)
    else:
        joints, rotations = _place(joints, rotations)
        joints, rotations, tilt = _level(joints, rotations)
        joints, grounding = ground(joints, FPS)  # a vertical shift: rotations and offsets keep
        grounding = replace(grounding, tilt=tilt)
    return Canonical(
        joints, rotations, offsets, bool(dropped), misfit.mean(axis=0), misfit.max(axis=0), grounding
    )


def resample(rig: RigMotion, fps: float, target_fps: float = FPS) -> RigMotion:
    """The rig at ``target_fps``: local rotations by slerp, translations linearly.

    Frame k of the result is at time k / target_fps; it spans the input's duration (the last
    frame lies at or before the input's last frame). Slerp is written on numpy quaternions: scipy's
    ``Rotation.from_matrix`` and composition cost ~20 ms a clip here, more than the rest of an
    import; ``tests/io/test_canonical.py`` checks it against scipy's ``Slerp``.
    """
    n = rig.num_frames
    if n < 2 or abs(fps - target_fps) < 1e-9:
        return rig
    count = int(np.floor((n - 1) * target_fps / fps + 1e-9)) + 1
    t = np.arange(count) * (fps / target_fps)  # in input frames
    i0 = np.minimum(np.floor(t).astype(int), n - 2)
    frac = (t - i0)[:, None]  # (count, 1)
    quats = _quat_from_matrix(rig.rotations)
    rotations = _quat_to_matrix(_slerp(quats[i0], quats[i0 + 1], frac))
    translations = rig.translations[i0] * (1 - frac[..., None]) + rig.translations[i0 + 1] * frac[..., None]
    return RigMotion(rig.names, rig.parents, rotations, translations, target_fps, rig.units, rig.is_end)


def _quat_from_matrix(m: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) as (w, x, y, z) from rotation matrices (..., 3, 3).

    Each of the four standard formulas is exact where its denominator is largest; take that one.
    """
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    xy, yx, xz, zx, yz, zy = (
        m[..., 0, 1],
        m[..., 1, 0],
        m[..., 0, 2],
        m[..., 2, 0],
        m[..., 1, 2],
        m[..., 2, 1],
    )
    diag = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    cands = np.stack(
        [
            np.stack([diag[..., 0], zy - yz, xz - zx, yx - xy], -1),
            np.stack([zy - yz, diag[..., 1], xy + yx, xz + zx], -1),
            np.stack([xz - zx, xy + yx, diag[..., 2], yz + zy], -1),
            np.stack([yx - xy, xz + zx, yz + zy, diag[..., 3]], -1),
        ],
        -2,
    )  # (..., 4 candidates, 4)
    best = np.argmax(diag, -1)
    q = np.take_along_axis(cands, best[..., None, None], -2)[..., 0, :]
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from unit quaternions (..., 4) (w, x, y, z)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _slerp(q0: np.ndarray, q1: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Spherical interpolation along the shorter arc; q0, q1 (N, J, 4), frac (N, 1) in [0, 1]."""
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where(dot[..., None] < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-6  # nearly equal: linear interpolation is exact to rounding
    safe = np.where(small, 1.0, sin)
    w0 = np.where(small, 1 - frac, np.sin((1 - frac) * theta) / safe)
    w1 = np.where(small, frac, np.sin(frac * theta) / safe)
    q = w0[..., None] * q0 + w1[..., None] * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def is_tpose_start(joints: np.ndarray) -> bool:
    """Whether frame 0 is a T-pose that does not belong to the motion after it.

    joints: (T >= 3, 22, 3), any orientation (the test uses the body's own trunk axis). True when
    frame 0 has level, straight arms pointing sideways and straight legs along the trunk, and the
    pose jumps from frame 0 to 1 (a stored T-pose followed by the take), not when a take merely
    starts by holding a T-pose.
    """
    j = JOINT_INDEX
    p = joints[0]
    trunk = unit_vectors(p[j["neck"]] - p[j["pelvis"]])
    across = unit_vectors(p[j["left_shoulder"]] - p[j["right_shoulder"]])
    for side, out in (("left", across), ("right", -across)):
        upper = unit_vectors(p[j[f"{side}_elbow"]] - p[j[f"{side}_shoulder"]])
        fore = unit_vectors(p[j[f"{side}_wrist"]] - p[j[f"{side}_elbow"]])
        if abs(upper @ trunk) > _TPOSE_ARM_LEVEL or abs(fore @ trunk) > _TPOSE_ARM_LEVEL:
            return False
        if upper @ out < _TPOSE_ARM_OUT or fore @ out < _TPOSE_ARM_OUT:
            return False
        thigh = unit_vectors(p[j[f"{side}_knee"]] - p[j[f"{side}_hip"]])
        shin = unit_vectors(p[j[f"{side}_ankle"]] - p[j[f"{side}_knee"]])
        if -(thigh @ trunk) < _TPOSE_STRAIGHT or -(shin @ trunk) < _TPOSE_STRAIGHT:
            return False
    local = joints[:3] - joints[:3, :1]
    jump01 = np.linalg.norm(local[1] - local[0], axis=-1).mean()
    jump12 = np.linalg.norm(local[2] - local[1], axis=-1).mean()
    return bool(jump01 > _TPOSE_JUMP_M and jump01 > _TPOSE_JUMP_RATIO * jump12)


def _rigid_pelvis(joints: np.ndarray) -> np.ndarray:
    """joints (T, 22, 3) with spine1 moved to where the pelvis's frame, fixed by the hips, puts it.

    SMPL's pelvis, hips and spine1 move as one rigid body; many rigs bend the spine at the pelvis
    (CMU's lowerback, iClone's waist), so no pelvis rotation fits all three. Left to IK's
    least-squares fit, the misfit would shift the hips and so the legs and feet by up to 4 cm;
    fixing the pelvis frame to the hips keeps the legs and feet exact and leaves the misfit at
    spine1, from where it barely reaches the rest of the upper body (only its component along the
    spine, as IK keeps each bone's direction).
    """
    pelvis, left, right, spine1 = (JOINT_INDEX[n] for n in ("pelvis", "left_hip", "right_hip", "spine1"))
    across = unit_vectors(joints[:, left] - joints[:, right])
    down = joints[:, left] + joints[:, right] - 2 * joints[:, pelvis]
    normal = unit_vectors(np.cross(across, down))
    frame = np.stack([across, np.cross(normal, across), normal], axis=-1)  # (T, 3, 3) orthonormal columns
    local = np.einsum("tji,tj->ti", frame, joints[:, spine1] - joints[:, pelvis])
    out = joints.copy()
    out[:, spine1] = joints[:, pelvis] + frame @ np.median(local, axis=0)
    return out


def _level(joints: np.ndarray, rotations: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The clip rotated so its capture floor is level (:func:`physmotion.io.floor.floor_tilt`), the root
    kept over the origin at frame 0; and the degrees it turned."""
    tilt = floor_tilt(joints, FPS)
    if np.allclose(tilt, np.eye(3)):
        return joints, rotations, 0.0
    levelled = joints @ tilt.T
    levelled[..., [0, 2]] -= levelled[0, 0, [0, 2]]
    rotations = rotations.copy()
    rotations[:, 0] = tilt @ rotations[:, 0]
    return levelled, rotations, float(np.degrees(np.arccos(np.clip(tilt[1, 1], -1.0, 1.0))))


def _place(
    joints: np.ndarray, rotations: np.ndarray, frame0_floor: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Origin and facing at frame 0 (a rigid motion of the world, applied to the root too), and with
    ``frame0_floor`` frame 0's lowest foot joint on y = 0 (else the floor is
    :func:`physmotion.io.floor.ground`'s)."""
    forward = facing_direction(joints[0])
    yaw = np.arctan2(forward[0], forward[2])  # angle from +Z to forward, about +Y
    turn = Rotation.from_euler("y", -yaw).as_matrix()
    floor = joints[0, list(FOOT_JOINTS), 1].min() if frame0_floor else 0.0
    shift = np.array([joints[0, 0, 0], floor, joints[0, 0, 2]])
    placed = (joints - shift) @ turn.T
    rotations = rotations.copy()
    rotations[:, 0] = turn @ rotations[:, 0]
    return placed, rotations


