"""The 22-joint SMPL / HumanML3D skeleton: joint order, tree, rest body, kinematics, mirror map.

Conventions (see :mod:`physmotion.conventions`): metres, Y up, the body faces +Z, so its left is +X
(as in SMPL). Rotations are 3x3 matrices; ``local[j]`` rotates joint ``j`` relative to its parent, and a
child's rest offset is expressed in its parent's frame::

    G[j] = G[parent[j]] @ local[j]
    p[j] = p[parent[j]] + G[parent[j]] @ offsets[j]

Forward kinematics works on numpy arrays and torch tensors alike (one implementation, ``@`` and
broadcasting only).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from physmotion.errors import ShapeError

JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar",
    "right_collar", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist",
)  # fmt: skip
NUM_JOINTS = len(JOINT_NAMES)
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINT_NAMES)}

PARENTS: tuple[int, ...] = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)

# HumanML3D's t2m_kinematic_chain: the chains used by its IK and by plots.
KINEMATIC_CHAINS: tuple[tuple[int, ...], ...] = (
    (0, 2, 5, 8, 11), (0, 1, 4, 7, 10), (0, 3, 6, 9, 12, 15), (9, 14, 17, 19, 21), (9, 13, 16, 18, 20),
)  # fmt: skip

# HumanML3D's t2m_raw_offsets: unit rest directions of each bone (arms hang down).
RAW_OFFSETS = np.array(
    [[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, -1, 0], [0, 1, 0], [0, -1, 0],
     [0, -1, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1], [0, 1, 0], [1, 0, 0], [-1, 0, 0], [0, 0, 1],
     [0, -1, 0], [0, -1, 0], [0, -1, 0], [0, -1, 0], [0, -1, 0], [0, -1, 0]],
    dtype=np.float64,
)  # fmt: skip

# Rest offsets of a default adult (SMPL neutral body, beta = 0, T-pose), metres, parent frame.
# Values follow the SMPL neutral joint regressor as laid out in PHC's smpl_humanoid.xml, rounded and
# made left/right symmetric so the default body mirrors onto itself.
REST_OFFSETS = np.array(
    [[0.0, 0.0, 0.0],
     [0.0686, -0.0910, -0.0056], [-0.0686, -0.0910, -0.0056], [0.0, 0.1089, -0.0267],
     [0.0363, -0.3789, -0.0067], [-0.0363, -0.3789, -0.0067], [0.0, 0.1352, 0.0011],
     [-0.0146, -0.3982, -0.0430], [0.0146, -0.3982, -0.0430], [0.0, 0.0529, 0.0254],
     [0.0259, -0.0520, 0.1213], [-0.0259, -0.0520, 0.1213], [0.0, 0.2139, -0.0429],
     [0.0803, 0.1203, -0.0364], [-0.0803, 0.1203, -0.0364], [0.0, 0.0650, 0.0513],
     [0.0935, 0.0316, -0.0090], [-0.0935, 0.0316, -0.0090], [0.2567, -0.0131, -0.0216],
     [-0.2567, -0.0131, -0.0216], [0.2524, 0.0084, -0.0036], [-0.2524, 0.0084, -0.0036]],
    dtype=np.float64,
)  # fmt: skip

MIRROR_MAP: tuple[int, ...] = tuple(
    JOINT_INDEX[n.replace("left_", "@").replace("right_", "left_").replace("@", "right_")]
    for n in JOINT_NAMES
)
"""``MIRROR_MAP[j]`` is the joint that ``j`` becomes under a left/right mirror (x -> -x)."""

FOOT_JOINTS: tuple[int, ...] = (7, 10, 8, 11)  # left ankle, left foot, right ankle, right foot
# HumanML3D's face_joint_indx: right hip, left hip, right shoulder, left shoulder.
FACE_JOINTS: tuple[int, int, int, int] = (2, 1, 17, 16)


def children(j: int) -> list[int]:
    """Joints whose parent is ``j``."""
    return [c for c, p in enumerate(PARENTS) if p == j]


def bone_lengths(joints: np.ndarray) -> np.ndarray:
    """Length of the bone into each joint.

    joints: (..., 22, 3). Returns (..., 22); the root's entry is 0.
    """
    parents = np.array([max(p, 0) for p in PARENTS])
    return np.linalg.norm(joints - joints[..., parents, :], axis=-1)


MIN_BONE_LENGTH = 1e-4
"""Metres. A shorter bone has no direction: IK cannot aim it and the humanoid cannot give it a geom."""


def check_bone_lengths(offsets: np.ndarray, hint: str = "") -> None:
    """Raise ShapeError naming the first bone of ``offsets`` (22, 3) shorter than MIN_BONE_LENGTH.

    hint: appended to the message (what the caller's user can change, e.g. a rig mapping).
    """
    lengths = np.linalg.norm(np.asarray(offsets, dtype=np.float64), axis=-1)
    short = [j for j in range(1, NUM_JOINTS) if not lengths[j] >= MIN_BONE_LENGTH]  # NaN counts as short
    if short:
        j = short[0]
        parent, child = JOINT_NAMES[PARENTS[j]], JOINT_NAMES[j]
        more = f" (and {len(short) - 1} more)" if len(short) > 1 else ""
        tail = f": {hint}" if hint else ""
        raise ShapeError(f"zero-length bone {parent} -> {child} ({1000 * lengths[j]:.2g} mm){more}{tail}")


def rest_joints(offsets: np.ndarray | None = None, root_height: float | None = None) -> np.ndarray:
    """Joint positions of the rest (T-)pose, (22, 3); the lowest joint sits on y = 0 by default."""
    offsets = REST_OFFSETS if offsets is None else offsets
    pos = np.zeros((NUM_JOINTS, 3))
    for j in range(1, NUM_JOINTS):
        pos[j] = pos[PARENTS[j]] + offsets[j]
    pos[:, 1] += -pos[:, 1].min() if root_height is None else root_height
    return pos


def forward_kinematics(local_rot: Any, root_pos: Any, offsets: Any) -> Any:
    """Joint positions from local rotations; numpy or torch, batched over leading dims.

    local_rot: (..., 22, 3, 3); root_pos: (..., 3); offsets: (22, 3) or (..., 22, 3).
    Returns joints (..., 22, 3) of the same array type.
    """
    glob: list[Any] = [local_rot[..., 0, :, :]]
    pos: list[Any] = [root_pos]
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        pos.append(pos[p] + (glob[p] @ offsets[..., j, :, None])[..., 0])
        glob.append(glob[p] @ local_rot[..., j, :, :])
    stack = np.stack if isinstance(root_pos, np.ndarray) else _torch_stack
    return stack(pos, -2)


def _torch_stack(items: list[Any], dim: int) -> Any:
    import torch

    return torch.stack(items, dim)


def mirror_joints(joints: np.ndarray) -> np.ndarray:
    """Left/right mirror of joint positions: x -> -x and left joints swapped with right ones.

    joints: (..., 22, 3). mirror_joints(mirror_joints(x)) == x exactly.
    """
    out = joints[..., list(MIRROR_MAP), :].copy()
    out[..., 0] *= -1
    return out


def facing_direction(joints: np.ndarray) -> np.ndarray:
    """Unit horizontal forward direction per frame, HumanML3D's definition (hips + shoulders).

    joints: (..., 22, 3) Y-up. Returns (..., 3) with y = 0.
    """
    r_hip, l_hip, r_sdr, l_sdr = FACE_JOINTS
    across = (joints[..., r_hip, :] - joints[..., l_hip, :]) + (joints[..., r_sdr, :] - joints[..., l_sdr, :])
    across = across / np.linalg.norm(across, axis=-1, keepdims=True)
    forward = np.cross(np.array([0.0, 1.0, 0.0]), across)
    forward[..., 1] = 0.0
    return forward / np.linalg.norm(forward, axis=-1, keepdims=True)


# ----------------------------------------------------------------------------------------------
# Inverse kinematics: joint positions -> local rotations on a body with fixed offsets.
# Hand-written because no maintained library solves this for an arbitrary tree in batch. Branching
# joints (pelvis, spine3) are solved by Kabsch over all their child bones, so a rigid configuration
# is reproduced exactly; single-child joints take the minimal rotation ("swing") from the parent's
# frame, as HumanML3D's IK does, so bone twist is not recovered (positions are).


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Rotations R (..., 3, 3) minimising sum |R src_k - dst_k|^2; src, dst: (..., K, 3)."""
    h = np.swapaxes(src, -1, -2) @ dst
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(u, -1, -2)))
    fix = np.ones(u.shape[:-1])
    fix[..., -1] = d
    return np.swapaxes(vt, -1, -2) @ (fix[..., :, None] * np.swapaxes(u, -1, -2))


def swing_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Minimal rotations (..., 3, 3) taking unit vectors a to unit vectors b (HumanML3D's qbetween).

    Rodrigues' formula; for antiparallel vectors (where qbetween returns 0/0) it turns by pi about
    an axis normal to a.
    """
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)[..., None, None]
    vx = np.zeros(v.shape + (3,))
    vx[..., 0, 1], vx[..., 0, 2] = -v[..., 2], v[..., 1]
    vx[..., 1, 0], vx[..., 1, 2] = v[..., 2], -v[..., 0]
    vx[..., 2, 0], vx[..., 2, 1] = -v[..., 1], v[..., 0]
    opposite = c[..., 0, 0] < -1.0 + 1e-9
    rot = np.eye(3) + vx + (vx @ vx) / np.where(opposite[..., None, None], 1.0, 1.0 + c)
    if np.any(opposite):
        a_opp = a[opposite]
        helper = np.eye(3)[np.argmin(np.abs(a_opp), axis=-1)]
        n = unit_vectors(np.cross(a_opp, helper))
        rot[opposite] = 2.0 * n[:, :, None] * n[:, None, :] - np.eye(3)
    return rot


def unit_vectors(v: np.ndarray) -> np.ndarray:
    """v (..., 3) scaled to unit length (zero vectors stay zero)."""
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def offsets_from_joints(joints: np.ndarray) -> np.ndarray:
    """The body of a motion: rest offsets (22, 3) with its bone lengths, in T-pose directions.

    joints: (T, 22, 3). Single-child bones take REST_OFFSETS' direction and the motion's median
    length; the children of branching joints keep the motion's own (median) layout, so IK and FK
    reproduce that layout exactly.
    """
    joints = np.asarray(joints, dtype=np.float64)
    lengths = np.median(bone_lengths(joints), axis=0)
    offsets = unit_vectors(REST_OFFSETS) * lengths[:, None]
    for j in range(NUM_JOINTS):
        kids = children(j)
        if len(kids) < 2:
            continue
        vec = joints[:, kids] - joints[:, j : j + 1]  # (T, K, 3)
        frame = kabsch(np.broadcast_to(REST_OFFSETS[kids], vec.shape), vec)  # (T, 3, 3)
        local = np.einsum("tji,tkj->tki", frame, vec)  # R^T v, in the joint's own frame
        offsets[kids] = np.median(local, axis=0)
    return offsets


def inverse_kinematics(joints: np.ndarray, offsets: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations that put ``offsets`` onto ``joints``.

    joints: (T, 22, 3) metres. offsets: (22, 3), by default :func:`offsets_from_joints`.
    Returns (local_rot (T, 22, 3, 3) float64, root_pos (T, 3)). With the default offsets,
    ``forward_kinematics(local_rot, root_pos, offsets)`` gives back ``joints`` up to the motion's
    own non-rigidity (bone-length jitter).
    """
    joints = np.asarray(joints, dtype=np.float64)
    offsets = offsets_from_joints(joints) if offsets is None else np.asarray(offsets, dtype=np.float64)
    n = joints.shape[0]
    glob = np.zeros((n, NUM_JOINTS, 3, 3))
    local = np.zeros((n, NUM_JOINTS, 3, 3))
    for j in range(NUM_JOINTS):
        parent_rot = glob[:, PARENTS[j]] if j > 0 else np.broadcast_to(np.eye(3), (n, 3, 3))
        kids = children(j)
        if len(kids) >= 2:
            vec = joints[:, kids] - joints[:, j : j + 1]
            glob[:, j] = kabsch(np.broadcast_to(offsets[kids], vec.shape), vec)
        elif len(kids) == 1:
            rest_dir = unit_vectors(np.einsum("tij,j->ti", parent_rot, offsets[kids[0]]))
            dir_now = unit_vectors(joints[:, kids[0]] - joints[:, j])
            glob[:, j] = swing_rotation(rest_dir, dir_now) @ parent_rot
        else:
            glob[:, j] = parent_rot
        local[:, j] = np.swapaxes(parent_rot, -1, -2) @ glob[:, j]
    return local, joints[:, 0].copy()
