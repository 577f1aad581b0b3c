"""HumanML3D's 263-d motion representation: joints -> features and features -> joints.

Followed, detail by detail (the code here is our own, vectorised over frames):

- EricGuo5513/HumanML3D ``motion_representation.ipynb``: ``uniform_skeleton``, ``process_file``,
  ``recover_root_rot_pos``, ``recover_from_ric``, ``recover_from_rot``;
- EricGuo5513/HumanML3D ``common/skeleton.py``: ``Skeleton.inverse_kinematics_np``,
  ``forward_kinematics_cont6d``;
- EricGuo5513/HumanML3D ``common/quaternion.py``: ``qbetween``, ``qrot``, ``quaternion_to_cont6d``,
  ``cont6d_to_matrix``;
- GuyTevet/motion-diffusion-model ``data_loaders/humanml/scripts/motion_process.py`` (same functions).

Layout of one feature frame ``t`` (``SLICES``), for a clip of T frames -> T - 1 feature frames::

    root_rot_vel  (1)   half-angle (rad) of the root's yaw change from frame t to t+1 (see below)
    root_lin_vel  (2)   root XZ displacement t -> t+1 (metres/frame), in the root frame of t+1
    root_y        (1)   root height at t (metres)
    ric           (63)  joints 1..21 at t, root-relative in XZ, in the root frame of t
    rot6d         (126) joints 1..21: first two columns of HumanML3D's local bone rotation at t
    local_vel     (66)  all 22 joints' displacement t -> t+1 (metres/frame), in the root frame of t
    foot_contact  (4)   left ankle, left foot, right ankle, right foot: 1 if |p[t+1]-p[t]|^2 < feet_thre

The last frame is dropped (it has no velocity); ``recover_from_ric(features)`` gives back frames 0..T-2 of
the canonical joints.

"Root frame" is HumanML3D's root rotation ``r_rot[t]``: the yaw taking a smoothed forward direction to +Z,
identity at frame 0. Quaternions are (w, x, y, z), Hamilton product; ``r_rot`` is the pure-yaw quaternion
(cos a, 0, sin a, 0) = rotation about +Y by 2a, so ``root_rot_vel`` is a *half* angle, as published.

Quirks of the published code that the released dataset carries, and which we keep on purpose:

- The forward direction inside ``inverse_kinematics_np`` unpacks ``face_joint_idx`` as (l_hip, r_hip, ...)
  although it is ordered (r_hip, l_hip, ...), so the hips enter with the opposite sign (HumanML3D issues
  #107, #112, #119; the authors keep it because the dataset was built with it). ``process_file``'s initial
  facing uses the correct order; so do we.
- That forward direction is Gaussian-smoothed over time (sigma 20 frames, mode 'nearest') before use, and
  the root rotation of frame 0 is forced to identity (``root_quat[0] = [1, 0, 0, 0]``, as in MDM's,
  MoMask's and the HumanML3D forks' copies of ``common/skeleton.py``; a later HumanML3D commit comments
  that line out, which would rotate every recovered motion by the frame-0 smoothed heading).
- The bones of the arm chains (9 -> 13/14 -> ...) take their local rotation relative to the root rotation,
  not to spine3 (issue #119, point 2), and the root "rotation" in the IK is world -> facing (``qbetween(
  forward, +Z)``) used as if it were facing -> world. The rot6d block is therefore not the SMPL local
  rotations; it is what HumanML3D publishes, and ``recover_from_rot`` (same conventions) inverts it.

Where we differ from the published code:

- ``root_rot_vel`` is the half-angle difference wrapped to [-pi/2, pi/2]. The published
  ``arcsin(q_y)`` of ``r_rot[t+1] * inv(r_rot[t])`` gets the sign wrong on the one frame where the heading
  crosses 180 degrees (the quaternion flips to its antipode, w < 0), which bends every later recovered
  frame by twice that frame's turn. Everywhere else the two are equal.
- ``uniform_skeleton`` (IK with minimal "swing" rotations, then FK on the target offsets) is computed
  directly as "keep each bone's direction, set its length to the target's": the two are identical, and
  this form has no 0/0 when a bone is antiparallel to its rest direction. In the rot6d block such a bone
  (where ``qbetween`` returns NaN) gets a half-turn about an axis normal to its rest direction.
- Computation is in float64 (the published code goes through float32 torch); the output is float32.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple, TypeVar

import numpy as np
from scipy.ndimage import gaussian_filter1d

from physmotion.errors import ShapeError
from physmotion.skeleton import (
    FACE_JOINTS,
    FOOT_JOINTS,
    KINEMATIC_CHAINS,
    MIRROR_MAP,
    NUM_JOINTS,
    PARENTS,
    RAW_OFFSETS,
    REST_OFFSETS,
    facing_direction,
    swing_rotation,
    unit_vectors,
)

if TYPE_CHECKING:
    import torch

    Array = TypeVar("Array", np.ndarray, torch.Tensor)
else:
    Array = TypeVar("Array")

FEATURE_DIM = 263

SLICES: dict[str, slice] = {
    "root_rot_vel": slice(0, 1),
    "root_lin_vel": slice(1, 3),
    "root_y": slice(3, 4),
    "ric": slice(4, 67),  # joints 1..21 x 3
    "rot6d": slice(67, 193),  # joints 1..21 x 6
    "local_vel": slice(193, 259),  # joints 0..21 x 3
    "foot_contact": slice(259, 263),  # skeleton.FOOT_JOINTS: HumanML3D's fid_l = [7, 10], fid_r = [8, 11]
}
"""Named groups of the 263-d vector: the single source of truth for its layout."""

# HumanML3D scales the body by the ratio of these two bones (its l_idx1, l_idx2 = 5, 8: right thigh and shin).
_LEG_BONES = (5, 8)

# The target body of uniform_skeleton. HumanML3D uses subject 000021's bone lengths along t2m_raw_offsets;
# we do not ship that file, so the lengths are our default body's (skeleton.REST_OFFSETS).
UNIFORM_OFFSETS: np.ndarray = RAW_OFFSETS * np.linalg.norm(REST_OFFSETS, axis=-1, keepdims=True)
"""(22, 3) offsets of the uniform skeleton: RAW_OFFSETS directions x REST_OFFSETS bone lengths (metres)."""

# First bone of each kinematic chain: its HumanML3D local rotation is taken relative to the root rotation,
# even for the arm chains that start at spine3 (joint 9).
_CHAIN_HEADS = frozenset(chain[1] for chain in KINEMATIC_CHAINS)
_ROT_PARENT = np.array([0] + [0 if j in _CHAIN_HEADS else PARENTS[j] for j in range(1, NUM_JOINTS)])
_PARENT = np.array([max(p, 0) for p in PARENTS])

_MIN_NORM = 1e-12

# The dims that hold absolute heights: root y and the y of each ric joint (joints 1..21).
_HEIGHT_DIMS = [SLICES["root_y"].start] + list(range(SLICES["ric"].start + 1, SLICES["ric"].stop, 3))


class _Extracted(NamedTuple):
    """Everything computed by :func:`_extract`, float64 (used by :mod:`physmotion.features.biomech`)."""

    features: np.ndarray  # (T-1, 263)
    canonical: np.ndarray  # (T, 22, 3)
    half_yaw: np.ndarray  # (T,) half-angle a_t of the root rotation r_rot[t] = Ry(2 a_t)


# ---------------------------------------------------------------------------------------------------
# joints -> features


def extract_features(
    joints: np.ndarray, *, uniform: bool = True, feet_thre: float = 0.002, floor: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """HumanML3D features of a motion (its ``process_file``).

    joints: (T, 22, 3) joint positions, metres, Y up, T >= 2 (20 fps for HumanML3D-compatible values).
    uniform: first retarget onto the uniform skeleton (:data:`UNIFORM_OFFSETS`: HumanML3D's
        ``t2m_raw_offsets`` directions with the bone lengths of our default body ``skeleton.REST_OFFSETS``,
        standing in for HumanML3D's subject 000021, which we do not have), scaled by the ratio of right-leg
        lengths in frame 0 as HumanML3D does.
    feet_thre: a foot joint is in contact at t when its squared displacement t -> t+1 is below this
        (m^2 per frame; HumanML3D uses 0.002 at 20 fps, i.e. under ~4.5 cm per frame).
    floor: put the clip's lowest joint on y = 0 (HumanML3D's convention, :data:`~physmotion.conventions.
        FLOOR_JOINTS`). False keeps the heights as given (scaled with the uniform skeleton), e.g. a
        simulated motion whose soles stand on the floor (:data:`~physmotion.conventions.FLOOR_SURFACE`):
        the features store absolute heights (root y and the ric block's y), so they can hold either.

    Returns (features (T-1, 263) float32, canonical_joints (T, 22, 3) float32): the canonical joints are the
    positions the features encode (uniform skeleton if asked, lowest joint of the clip on y = 0 unless
    ``floor`` is False, root XZ of frame 0 at the origin, facing +Z at frame 0);
    ``recover_from_ric(features) ~ canonical_joints[:-1]``.
    Raises ShapeError for a wrong shape, NaN/inf values or fewer than 2 frames.
    """
    out = _extract(joints, uniform=uniform, feet_thre=feet_thre, floor=floor)
    return out.features.astype(np.float32), out.canonical.astype(np.float32)


def raise_features(features: Array, dy: float) -> Array:
    """The motion of ``features`` moved up by ``dy`` metres (down for dy < 0).

    features: (..., T, D) numpy array or torch tensor, D = 263 or 329. Only the absolute heights move (root
    y and the ric block's y); every other dim is a velocity, a rotation, a contact or an acceleration,
    which a vertical shift leaves as they are. Returns a new array of the same type and dtype.
    """
    ops = _ops_for(features, SLICES["ric"].stop)
    out = features.clone() if ops.torch else np.array(features, copy=True)
    out[..., _HEIGHT_DIMS] += dy
    return out


def _extract(joints: np.ndarray, *, uniform: bool, feet_thre: float, floor: bool = True) -> _Extracted:
    pos = _checked_joints(joints)
    if uniform:
        pos = _uniform_skeleton(pos, UNIFORM_OFFSETS)
    pos = _canonicalise(pos, floor)

    step2 = np.sum((pos[1:, list(FOOT_JOINTS)] - pos[:-1, list(FOOT_JOINTS)]) ** 2, axis=-1)  # (T-1, 4)
    contacts = (step2 < feet_thre).astype(np.float64)

    half = _root_half_yaw(pos)  # r_rot[t] = Ry(2 half[t])
    yaw = 2.0 * half

    # Root angular velocity: the half-angle change, wrapped so that q and -q count as the same rotation.
    d_half = half[1:] - half[:-1]
    rot_vel = d_half - np.pi * np.round(d_half / np.pi)
    # Root linear velocity in the root frame of the *next* frame (r_rot[1:]), as published.
    lin_vel = _rot_y(yaw[1:], pos[1:, 0] - pos[:-1, 0])[:, [0, 2]]
    root_y = pos[:-1, 0, 1]

    # Root-relative positions ("rifke"): remove the root's XZ, then turn by r_rot[t].
    rel = pos - pos[:, :1] * np.array([1.0, 0.0, 1.0])
    ric = _rot_y(yaw[:, None], rel)[:, 1:]  # (T, 21, 3)

    rot6d = _local_rot6d(pos, yaw)  # (T, 21, 6)
    # Joint velocities in the root frame of the *current* frame (r_rot[:-1]), as published.
    local_vel = _rot_y(yaw[:-1, None], pos[1:] - pos[:-1])  # (T-1, 22, 3)

    n = pos.shape[0] - 1
    features = np.concatenate(
        [rot_vel[:, None], lin_vel, root_y[:, None], ric[:-1].reshape(n, -1), rot6d[:-1].reshape(n, -1),
         local_vel.reshape(n, -1), contacts],
        axis=-1,
    )  # fmt: skip
    if not np.all(np.isfinite(features)):  # e.g. hips and shoulders stacked vertically: no facing
        raise ShapeError("joints give a degenerate pose (no facing direction can be computed)")
    return _Extracted(features, pos, half)


def _checked_joints(joints: Any) -> np.ndarray:
    if not isinstance(joints, np.ndarray):
        raise ShapeError(f"joints must be a numpy array, got {type(joints).__name__}")
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise ShapeError(f"joints must have shape (T, {NUM_JOINTS}, 3), got {tuple(joints.shape)}")
    if joints.shape[0] < 2:
        raise ShapeError(f"joints need at least 2 frames for velocities, got {joints.shape[0]}")
    if not np.all(np.isfinite(joints)):
        raise ShapeError("joints contain NaN or infinite values")
    return joints.astype(np.float64)


def _uniform_skeleton(pos: np.ndarray, target_offsets: np.ndarray) -> np.ndarray:
    """HumanML3D's ``uniform_skeleton``: the motion on the target bone lengths; pos (T, 22, 3).

    Its IK stores, per bone, the minimal rotation taking the rest direction u to the bone's direction v;
    its FK applies that rotation to u * target_length, which is v * target_length. So every bone keeps its
    direction and takes the target length; the root trajectory is scaled by the ratio of right-leg lengths
    (thigh + shin) of the target over those of frame 0.
    """
    src_len = np.linalg.norm(pos[0] - pos[0, _PARENT], axis=-1)
    tgt_len = np.linalg.norm(target_offsets, axis=-1)
    src_leg = src_len[list(_LEG_BONES)].sum()
    if src_leg < 1e-6:
        raise ShapeError("joints have zero-length legs in frame 0; cannot scale to the uniform skeleton")
    scale = tgt_len[list(_LEG_BONES)].sum() / src_leg

    out = np.empty_like(pos)
    out[:, 0] = pos[:, 0] * scale
    for j in range(1, NUM_JOINTS):  # parents come before children in the SMPL order
        p = PARENTS[j]
        out[:, j] = out[:, p] + unit_vectors(pos[:, j] - pos[:, p]) * tgt_len[j]
    return out


def _canonicalise(pos: np.ndarray, floor: bool = True) -> np.ndarray:
    """Lowest joint of the clip on y = 0 (if ``floor``), root XZ of frame 0 at the origin, frame 0 facing +Z."""
    pos = pos.copy()
    if floor:
        pos[..., 1] -= pos[..., 1].min()
    pos -= pos[0, 0] * np.array([1.0, 0.0, 1.0])
    fwd = facing_direction(pos[0])  # process_file's correct (r_hip - l_hip) + (r_sdr - l_sdr) order
    return _rot_y(-np.arctan2(fwd[0], fwd[2]), pos)


def _root_half_yaw(pos: np.ndarray) -> np.ndarray:
    """Half-angles a_t (T,) of HumanML3D's root rotation r_rot[t] = qbetween(forward_t, +Z) = Ry(2 a_t).

    Follows ``inverse_kinematics_np(..., smooth_forward=True)``: swapped-hip forward direction, Gaussian
    smoothing (sigma 20) of the unnormalised forward vectors, and r_rot[0] forced to identity.
    """
    r_hip, l_hip, r_sdr, l_sdr = FACE_JOINTS
    # Published quirk (see module doc): the hips enter as (l_hip - r_hip).
    across = (pos[:, l_hip] - pos[:, r_hip]) + (pos[:, r_sdr] - pos[:, l_sdr])
    across = across / np.maximum(np.linalg.norm(across, axis=-1, keepdims=True), _MIN_NORM)
    forward = np.stack([across[:, 2], np.zeros(len(across)), -across[:, 0]], axis=-1)  # (0, 1, 0) x across
    forward = gaussian_filter1d(forward, 20, axis=0, mode="nearest")
    # qbetween(f, +Z) = normalise(1 + f_z, 0, -f_x, 0) for unit horizontal f: half-angle -atan2(f_x, f_z)/2,
    # with w >= 0 as qbetween returns it.
    half = -0.5 * np.arctan2(forward[:, 0], forward[:, 2])
    half[0] = 0.0
    return half


def _local_rot6d(pos: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """HumanML3D's cont6d joint rotations (T, 21, 6) of canonical positions pos (T, 22, 3).

    Each bone's global rotation is the minimal rotation from its RAW_OFFSETS direction to its direction
    now; its local rotation is relative to its chain parent's bone, or to the root rotation r_rot[t] for
    the first bone of every chain. cont6d = first two columns of the rotation matrix.
    """
    bone_dir = unit_vectors(pos[:, 1:] - pos[:, _PARENT[1:]])  # (T, 21, 3)
    rest_dir = np.broadcast_to(RAW_OFFSETS[1:], bone_dir.shape)
    glob = np.concatenate([_yaw_matrix(yaw)[:, None], swing_rotation(rest_dir, bone_dir)], axis=1)  # (T, 22, 3, 3)
    local = np.swapaxes(glob[:, _ROT_PARENT[1:]], -1, -2) @ glob[:, 1:]  # (T, 21, 3, 3)
    return np.concatenate([local[..., :, 0], local[..., :, 1]], axis=-1)


def _rot_y(angle: np.ndarray | float, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) about +Y by angle (broadcast against v[..., 0])."""
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)


def _yaw_matrix(angle: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) about +Y."""
    c, s = np.cos(angle), np.sin(angle)
    zero, one = np.zeros_like(c), np.ones_like(c)
    return np.stack([c, zero, s, zero, one, zero, -s, zero, c], axis=-1).reshape(c.shape + (3, 3))


# ---------------------------------------------------------------------------------------------------
# features -> joints (numpy and torch)


class _Ops:
    """The few array operations whose numpy and torch spellings differ."""

    def __init__(self, torch_mode: bool) -> None:
        self.torch = torch_mode
        if torch_mode:
            import torch

            self.xp: Any = torch
        else:
            self.xp = np

    def cat(self, xs: list[Any], axis: int) -> Any:
        return self.xp.cat(xs, dim=axis) if self.torch else np.concatenate(xs, axis=axis)

    def stack(self, xs: list[Any], axis: int) -> Any:
        return self.xp.stack(xs, dim=axis) if self.torch else np.stack(xs, axis=axis)

    def cumsum(self, x: Any, axis: int) -> Any:
        return self.xp.cumsum(x, dim=axis) if self.torch else np.cumsum(x, axis=axis)

    def cross(self, a: Any, b: Any) -> Any:
        return self.xp.linalg.cross(a, b, dim=-1) if self.torch else np.cross(a, b)

    def norm(self, x: Any) -> Any:
        if self.torch:
            return self.xp.linalg.vector_norm(x, dim=-1, keepdim=True)
        return np.linalg.norm(x, axis=-1, keepdims=True)


def _ops_for(x: Any, min_dim: int, min_ndim: int = 2) -> _Ops:
    if isinstance(x, np.ndarray):
        ops = _Ops(False)
    elif type(x).__module__.split(".")[0] == "torch":
        ops = _Ops(True)
    else:
        raise ShapeError(f"features must be a numpy array or a torch tensor, got {type(x).__name__}")
    if x.ndim < min_ndim or x.shape[-1] < min_dim or (min_ndim >= 2 and x.shape[-2] < 1):
        raise ShapeError(f"features must have shape (..., T, D) with D >= {min_dim}, got {tuple(x.shape)}")
    return ops


def _as_float(x: Any, ops: _Ops) -> Any:
    """numpy: compute in float64 (cast back at the end); torch: keep dtype/device/autograd."""
    return x if ops.torch else x.astype(np.float64)


def _root_half_angles(f: Any, ops: _Ops) -> Any:
    """Accumulated half-angles (..., T) of the root yaw; frame 0 has angle 0."""
    rot_vel = f[..., 0]
    return ops.cat([rot_vel[..., :1] * 0, ops.cumsum(rot_vel[..., :-1], -1)], -1)


def _unrot_y(half: Any, x: Any, z: Any, ops: _Ops) -> tuple[Any, Any]:
    """(x, z) turned by inv(r_rot) = rotation about +Y by -2 * half."""
    c, s = ops.xp.cos(2 * half), ops.xp.sin(2 * half)
    return c * x - s * z, s * x + c * z


def _recover_root(f: Any, ops: _Ops) -> tuple[Any, Any]:
    half = _root_half_angles(f, ops)
    # r_pos[t] = sum_{k < t} inv(r_rot[k+1]) (lin_vel[k]); frame 0 at the origin.
    vx, vz = _unrot_y(half[..., 1:], f[..., :-1, 1], f[..., :-1, 2], ops)
    zero = f[..., :1, 1] * 0
    root_x = ops.cumsum(ops.cat([zero, vx], -1), -1)
    root_z = ops.cumsum(ops.cat([zero, vz], -1), -1)
    return half, ops.stack([root_x, f[..., 3], root_z], -1)


def recover_root_rot_pos(features: Array) -> tuple[Array, Array]:
    """Root rotation and position from features (HumanML3D's ``recover_root_rot_pos``).

    features: (..., T, D) numpy array or torch tensor, D >= 4 (263 or 329).
    Returns (r_rot_quat (..., T, 4) as (w, x, y, z) = (cos a, 0, sin a, 0), the world -> root-frame yaw
    with a the accumulated half-angle; r_pos (..., T, 3) root positions), same array type and dtype.
    """
    ops = _ops_for(features, 4)
    f = _as_float(features, ops)
    half, r_pos = _recover_root(f, ops)
    zeros = half * 0
    quat = ops.stack([ops.xp.cos(half), zeros, ops.xp.sin(half), zeros], -1)
    return _like(quat, features, ops), _like(r_pos, features, ops)


def recover_from_ric(features: Array, joints_num: int = NUM_JOINTS) -> Array:
    """Joint positions from the root data and the ric block (HumanML3D's ``recover_from_ric``).

    features: (..., T, D) numpy array or torch tensor (D = 263, or 329; only dims 0..66 are read).
    Returns (..., T, joints_num, 3) of the same array type and dtype; for features from
    :func:`extract_features` this is ``canonical_joints[:-1]``. Differentiable for torch inputs.
    """
    ops = _ops_for(features, 4 + (joints_num - 1) * 3)
    f = _as_float(features, ops)
    half, r_pos = _recover_root(f, ops)
    ric = f[..., 4 : 4 + (joints_num - 1) * 3].reshape(tuple(f.shape[:-1]) + (joints_num - 1, 3))
    x, z = _unrot_y(half[..., None], ric[..., 0], ric[..., 2], ops)
    joints = ops.stack([x + r_pos[..., None, 0], ric[..., 1], z + r_pos[..., None, 2]], -1)
    return _like(ops.cat([r_pos[..., None, :], joints], -2), features, ops)


def recover_from_rot(features: Array, offsets: np.ndarray | None = None) -> Array:
    """Joint positions by forward kinematics of the rot6d block (HumanML3D's ``recover_from_rot``).

    features: (..., T, D), D >= 193. offsets: (22, 3) bone offsets along RAW_OFFSETS directions, by
    default :data:`UNIFORM_OFFSETS` (the body :func:`extract_features` retargets to). The root takes the
    recovered position and yaw; each bone's rotation composes along HumanML3D's kinematic chains (the
    chains starting at spine3 restart from the root rotation, as published).
    Returns (..., T, 22, 3), same array type and dtype.
    """
    ops = _ops_for(features, SLICES["rot6d"].stop)
    f = _as_float(features, ops)
    half, r_pos = _recover_root(f, ops)
    offs = UNIFORM_OFFSETS if offsets is None else np.asarray(offsets, dtype=np.float64)
    if offs.shape != (NUM_JOINTS, 3):
        raise ShapeError(f"offsets must have shape ({NUM_JOINTS}, 3), got {offs.shape}")
    if ops.torch:
        offs = ops.xp.as_tensor(offs, dtype=f.dtype, device=f.device)

    c, s = ops.xp.cos(2 * half), ops.xp.sin(2 * half)
    zero, one = c * 0, c * 0 + 1
    root_rot = ops.stack([c, zero, s, zero, one, zero, -s, zero, c], -1).reshape(tuple(c.shape) + (3, 3))
    six = f[..., SLICES["rot6d"]].reshape(tuple(f.shape[:-1]) + (NUM_JOINTS - 1, 6))
    local = _cont6d_to_matrix(six, ops)  # (..., T, 21, 3, 3)

    pos: list[Any] = [r_pos] + [None] * (NUM_JOINTS - 1)
    for chain in KINEMATIC_CHAINS:
        rot = root_rot
        for prev, j in zip(chain[:-1], chain[1:]):
            rot = rot @ local[..., j - 1, :, :]
            pos[j] = pos[prev] + (rot @ offs[j][:, None])[..., 0]
    return _like(ops.stack(pos, -2), features, ops)


def _cont6d_to_matrix(six: Any, ops: _Ops) -> Any:
    """HumanML3D's ``cont6d_to_matrix``: Gram-Schmidt of the two columns; columns (x, y, z)."""
    x = six[..., 0:3] / ops.norm(six[..., 0:3])
    z = ops.cross(x, six[..., 3:6])
    z = z / ops.norm(z)
    y = ops.cross(z, x)
    return ops.stack([x, y, z], -1)


def _like(x: Any, ref: Any, ops: _Ops) -> Any:
    return x if ops.torch else x.astype(ref.dtype, copy=False)


# ---------------------------------------------------------------------------------------------------
# left/right mirror on the feature vector


def _mirror_index(dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(source index, sign) such that mirrored[..., i] = features[..., index[i]] * sign[i]."""
    index = np.arange(dim)
    sign = np.ones(dim)
    sign[SLICES["root_rot_vel"]] = -1.0  # a left turn becomes a right turn
    sign[SLICES["root_lin_vel"].start] = -1.0  # x

    def joint_vectors(block: slice, first_joint: int, width: int, pattern: np.ndarray) -> None:
        for k in range((block.stop - block.start) // width):
            j = k + first_joint
            src = block.start + (MIRROR_MAP[j] - first_joint) * width
            index[block.start + k * width : block.start + (k + 1) * width] = np.arange(src, src + width)
            sign[block.start + k * width : block.start + (k + 1) * width] = pattern

    xyz = np.array([-1.0, 1.0, 1.0])
    joint_vectors(SLICES["ric"], 1, 3, xyz)
    # A rotation R becomes M R M with M = diag(-1, 1, 1): columns 0 and 1 of M R M are
    # (R00, -R10, -R20) and (-R01, R11, R21).
    joint_vectors(SLICES["rot6d"], 1, 6, np.array([1.0, -1.0, -1.0, -1.0, 1.0, 1.0]))
    joint_vectors(SLICES["local_vel"], 0, 3, xyz)
    contact = SLICES["foot_contact"]
    index[contact] = contact.start + np.array([2, 3, 0, 1])  # (l ankle, l foot) <-> (r ankle, r foot)
    if dim == FEATURE_DIM + NUM_JOINTS * 3:  # BioMoDiffuse's 329: + per-joint vectors in the root frame
        joint_vectors(slice(FEATURE_DIM, dim), 0, 3, xyz)
    return index, sign


_MIRROR = {d: _mirror_index(d) for d in (FEATURE_DIM, FEATURE_DIM + NUM_JOINTS * 3)}


def mirror_features(features: Array) -> Array:
    """Left/right mirror (x -> -x, left and right joints swapped) applied to the feature vector itself.

    features: (..., D) numpy array or torch tensor with D = 263 (or 329, whose extra joint vectors are
    mirrored like local_vel). Equals ``extract_features(mirror_joints(joints))[0]`` for a left/right
    symmetric body, up to float error; ``mirror_features(mirror_features(x)) == x`` exactly.
    """
    dim = features.shape[-1] if hasattr(features, "shape") else None
    if dim not in _MIRROR:
        dims = " or ".join(str(d) for d in _MIRROR)
        raise ShapeError(f"features must have last dimension {dims}, got {dim}")
    ops = _ops_for(features, 1, min_ndim=1)
    index, sign = _MIRROR[dim]
    if ops.torch:
        idx = ops.xp.as_tensor(index, device=features.device)
        return features[..., idx] * ops.xp.as_tensor(sign, dtype=features.dtype, device=features.device)
    return (features[..., index] * sign).astype(features.dtype, copy=False)
