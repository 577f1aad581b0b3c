"""Retargeting both ways: joint positions (Y-up) <-> humanoid qpos (MuJoCo, Z-up).

qpos layout (see :mod:`physmotion.physics.humanoid`): ``[root pos (3), root quat (4, w first),
63 hinge angles]``, hinges in MuJoCo's depth-first body order, three per body in that body's nesting
order (:func:`physmotion.physics.humanoid.layout` says where each joint's hinges are).

The pelvis origin is the root joint, so ``qpos[:3]`` is ``to_mujoco(joints[:, 0])`` (plus ``lift``).
Hinge angles are the skeleton's IK local rotations (:func:`physmotion.skeleton.inverse_kinematics`
with the offsets the model was built from; thighs and upper arms then twisted about their own bone so
knees and elbows bend about their hinge axis, which moves no joint), in the MuJoCo frame, decomposed
into each body's intrinsic Euler sequence and made continuous over time (the Euler branch nearest the
previous frame, then 2 pi unwrapping), so the PD targets never flip.

Retargeting with the model built from the motion's own body (``offsets_from_joints``) reproduces the
joints exactly (FK of rigid data); with another body the bone directions are kept and the positions
differ by the bone-length differences (several cm).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from physmotion.errors import ShapeError
from physmotion.physics.frames import from_mujoco, rot_from_mujoco, rot_to_mujoco, to_mujoco
from physmotion.physics.humanoid import JOINT_GROUP, HumanoidConfig, Layout, default_hinge_order, layout
from physmotion.skeleton import (
    JOINT_INDEX,
    JOINT_NAMES,
    NUM_JOINTS,
    PARENTS,
    REST_OFFSETS,
    children,
    forward_kinematics,
    inverse_kinematics,
    swing_rotation,
    unit_vectors,
)

NQ = 7 + 3 * (NUM_JOINTS - 1)
NV = 6 + 3 * (NUM_JOINTS - 1)


# ----------------------------------------------------------------------------------------------
# Where the hinges are, for a model or for the default build from offsets alone.


def _layout_for(model_or_offsets: Any, config: HumanoidConfig | None = None) -> Layout:
    """Layout from a compiled model, or the layout build_model would give for these offsets."""
    if model_or_offsets is None or isinstance(model_or_offsets, np.ndarray):
        offsets = REST_OFFSETS if model_or_offsets is None else np.asarray(model_or_offsets, dtype=np.float64)
        if offsets.shape != (NUM_JOINTS, 3) or not np.all(np.isfinite(offsets)):
            raise ShapeError(f"offsets must be a finite ({NUM_JOINTS}, 3) array, got shape {offsets.shape}")
        return _static_layout(offsets, config)
    return layout(model_or_offsets)


def _static_layout(offsets: np.ndarray, config: HumanoidConfig | None) -> Layout:
    """The layout of ``build_model(offsets, config)`` without compiling it (same depth-first walk)."""
    order_of = config.hinge_order if config is not None else default_hinge_order()
    body_ids = np.zeros(NUM_JOINTS, dtype=np.int64)
    qadr = -np.ones((NUM_JOINTS, 3), dtype=np.int64)
    dadr = -np.ones((NUM_JOINTS, 3), dtype=np.int64)
    orders = [""] * NUM_JOINTS
    counter = {"body": 1, "q": 7, "d": 6}

    def walk(j: int) -> None:
        body_ids[j] = counter["body"]
        counter["body"] += 1
        if j > 0:
            orders[j] = order_of[JOINT_GROUP[JOINT_NAMES[j]]]
            qadr[j] = counter["q"] + np.arange(3)
            dadr[j] = counter["d"] + np.arange(3)
            counter["q"] += 3
            counter["d"] += 3
        for c in children(j):
            walk(c)

    walk(0)
    return Layout(body_ids, qadr, dadr, tuple(orders), offsets.copy())


# ----------------------------------------------------------------------------------------------
# Input checks: one-line ShapeErrors.


def _as_batch(x: Any, tail: tuple[int, ...], name: str, shape_text: str) -> tuple[np.ndarray, bool]:
    """(B, T, *tail) float64 view of x and whether x was batched; raises ShapeError otherwise."""
    x = np.asarray(x, dtype=np.float64)
    n = len(tail)
    if x.ndim not in (n + 1, n + 2) or x.shape[x.ndim - n :] != tail:
        raise ShapeError(f"{name} must have shape {shape_text}, got {tuple(x.shape)}")
    if x.shape[x.ndim - n - 1] == 0:
        raise ShapeError(f"{name} has zero frames")
    if not np.all(np.isfinite(x)):
        raise ShapeError(f"{name} contains NaN or infinite values")
    if tail == (NQ,) and np.any(np.linalg.norm(x[..., 3:7], axis=-1) < 1e-9):
        raise ShapeError(f"{name} has a zero root quaternion (qpos[3:7])")
    batched = x.ndim == n + 2
    return (x if batched else x[None]), batched


# ----------------------------------------------------------------------------------------------
# Euler angles, continuous over time.


def _euler_branches(rot: np.ndarray, seq: str) -> tuple[np.ndarray, np.ndarray]:
    """The two intrinsic Euler solutions (..., 3) of rotations (..., 3, 3) for a Tait-Bryan sequence.

    scipy gives the one with the middle angle in [-pi/2, pi/2]; the other is (a + pi, pi - b, c + pi).
    """
    flat = rot.reshape(-1, 3, 3)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # gimbal lock: scipy still returns a valid solution
        a = Rotation.from_matrix(flat).as_euler(seq.upper()).reshape(rot.shape[:-2] + (3,))
    b = a.copy()
    b[..., 0] += np.pi
    b[..., 1] = np.pi - a[..., 1]
    b[..., 2] += np.pi
    return a, b


def _nearest_2pi(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """x shifted by multiples of 2 pi to lie within pi of ref."""
    return x - 2.0 * np.pi * np.round((x - ref) / (2.0 * np.pi))


def _continuous_euler(rot: np.ndarray, seq: str) -> np.ndarray:
    """Euler angles (T, N, 3) of rotations (T, N, 3, 3) with no branch flips or 2 pi jumps over T.

    Frame 0 takes the principal branch wrapped to (-pi, pi]; every later frame the branch (after 2 pi
    unwrapping) nearest to the previous frame's angles.
    """
    a, b = _euler_branches(rot, seq)
    both = np.stack([a, b], axis=1)  # (T, 2, N, 3): both branches go through each step together
    out = np.empty_like(a)
    out[0] = _nearest_2pi(a[0], np.zeros_like(a[0]))
    for t in range(1, a.shape[0]):
        c = _nearest_2pi(both[t], out[t - 1])
        dist = np.sum((c - out[t - 1]) ** 2, -1)  # (2, N)
        out[t] = np.where((dist[1] < dist[0])[:, None], c[1], c[0])
    return out


def _euler_to_matrix(angles: np.ndarray, seq: str) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of intrinsic Euler angles (..., 3)."""
    flat = angles.reshape(-1, 3)
    return Rotation.from_euler(seq.upper(), flat).as_matrix().reshape(angles.shape[:-1] + (3, 3))


# ----------------------------------------------------------------------------------------------
# Limb twist. skeleton.inverse_kinematics gives single-child joints the minimal rotation ("swing")
# from the parent, so a thigh or upper arm keeps an arbitrary twist and the knee or elbow then bends
# about whatever axis that twist leaves: on the Bandai set elbows reached 300 degrees on their "x"
# hinge and knees 120 degrees on theirs. Twisting the thigh (upper arm) about its own bone moves no
# joint, so we choose the twist that makes the knee (elbow) bend about its anatomical axis and
# re-solve the joints below it; positions stay exactly those of the plain IK.

# (parent, child, anatomical hinge axis of the child in OUR frame, largest twist in rad or None).
# Knee flexion is about +y in MuJoCo = +x ours; in the T-pose (palms down) the left elbow flexes
# about -z in MuJoCo = -y ours, the right one about +y ours.
# Knees (None): the twist needed is small; a knee bent "backwards" is hyperextension, so the axis line
# is kept and flipped rather than the thigh turned by half a turn (the twist stays within 90 degrees).
# Arms: a raised arm needs any twist (arm forward: the elbow bends upwards, a quarter turn from the
# swing's frame), and all of it in the shoulder sends the shoulder's Euler angles through gimbal lock.
# The twist is unwrapped over time and clipped to 50 degrees, the rest stays in the elbow, which is then
# mostly its flexion hinge (docs/decisions/projection.md: "upper-arm twist clipped to 50 degrees").
_LIMBS: tuple[tuple[str, str, tuple[float, float, float], float | None], ...] = (
    ("left_hip", "left_knee", (1.0, 0.0, 0.0), None),
    ("right_hip", "right_knee", (1.0, 0.0, 0.0), None),
    ("left_shoulder", "left_elbow", (0.0, -1.0, 0.0), np.radians(50.0)),
    ("right_shoulder", "right_elbow", (0.0, 1.0, 0.0), np.radians(50.0)),
)
# Bends above _BEND_FULL show the twist fully; below _BEND_NONE the bending axis is noise and the
# twist is interpolated in time from the bent frames around (a straight leg keeps its rotation).
_BEND_FULL = np.radians(20.0)
_BEND_NONE = np.radians(5.0)


def _axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotations (..., 3, 3) about unit axes (..., 3) by angles (...)."""
    rotvec = (axis * angle[..., None]).reshape(-1, 3)
    return Rotation.from_rotvec(rotvec).as_matrix().reshape(angle.shape + (3, 3))


def _global(local: np.ndarray) -> np.ndarray:
    """Global rotations (T, 22, 3, 3) from local ones."""
    glob = np.empty_like(local)
    glob[:, 0] = local[:, 0]
    for j in range(1, NUM_JOINTS):
        glob[:, j] = glob[:, PARENTS[j]] @ local[:, j]
    return glob


def _twist_series(
    psi: np.ndarray, w: np.ndarray, period: float, limit: float, fade_far: bool = False
) -> np.ndarray:
    """Twist per frame (T,) from the measured twist psi (T,) and how much the bend shows it, w (T,).

    Where the limb is bent (w = 1) the measured twist holds; across straight frames (w = 0, the bend
    axis is noise there) it is interpolated in time between its neighbours (held at the ends; 0 if the
    limb never bends), and blended in between. Unwrapped with ``period``, clipped to +-limit:
    continuous wherever the measurement is. fade_far: in the blend, follow a measurement far from the
    interpolated twist less (see below).
    """

    def near(x: np.ndarray, ref: np.ndarray | float) -> np.ndarray:
        return x - period * np.round((x - ref) / period)

    known = np.flatnonzero(w >= 1.0)
    if len(known) == 0:
        base = np.zeros_like(psi)
    else:
        samples = psi[known].copy()
        samples[0] = near(samples[0], 0.0)
        for i in range(1, len(samples)):
            samples[i] = near(samples[i], samples[i - 1])
        base = np.interp(np.arange(len(psi)), known, samples)
    d = near(psi, base) - base
    if fade_far:
        # Where the bend only partly shows the twist, follow the measured offset from the base up to a quarter
        # period, and less beyond, none at half a period: there the measurement is as near one way round as
        # the other, and a plain blend flips (docs/decisions/projection.md: "the limb twist where a bend half
        # shows it"; arms only, as measured there).
        fade = np.clip(2.0 - 4.0 * np.abs(d) / period, 0.0, 1.0)
        d = d * fade * fade * (3.0 - 2.0 * fade)
    # Clip last: clipping before unwrapping would let a twist beyond the limit jump to the other end.
    return np.clip(base + w * d, -limit, limit)


def _anatomical_twist(joints: np.ndarray, local: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """IK local rotations (T, 22, 3, 3), thighs/upper arms twisted so knees/elbows bend about their axis.

    joints: (T, 22, 3); local: (T, 22, 3, 3) from ``inverse_kinematics(joints, offsets)``.
    """
    local = local.copy()
    glob = _global(local)
    for p_name, c_name, n_des, max_twist in _LIMBS:
        p, c = JOINT_INDEX[p_name], JOINT_INDEX[c_name]
        a = unit_vectors(offsets[c])  # the bone p -> c, in p's frame: the twist axis
        rotvec = Rotation.from_matrix(local[:, c]).as_rotvec()  # (T, 3) the child's bend, in p's frame
        bend = np.linalg.norm(rotvec, axis=-1)
        n = rotvec - np.outer(rotvec @ a, a)  # bend axis, projected off the twist axis
        want = np.asarray(n_des) - a * (a @ np.asarray(n_des))
        # Signed angle about a from the wanted axis to the current one; twisting p by it maps n onto want.
        psi = np.arctan2(np.cross(want, n) @ a, n @ want)
        w = np.clip((bend - _BEND_NONE) / (_BEND_FULL - _BEND_NONE), 0.0, 1.0)
        w = w * w * (3.0 - 2.0 * w)  # smoothstep
        if max_twist is None:  # knee: the axis line matters, not its sign (period pi)
            psi = _twist_series(psi, w, np.pi, 0.5 * np.pi)
        else:
            psi = _twist_series(psi, w, 2.0 * np.pi, max_twist, fade_far=True)
        twist = _axis_angle(np.broadcast_to(a, (len(psi), 3)), psi)
        local[:, p] = local[:, p] @ twist
        glob[:, p] = glob[:, PARENTS[p]] @ local[:, p]
        # Re-solve the chain below p with the skeleton's swing rule (same as its IK).
        j, parent = c, p
        while True:
            kids = children(j)
            if len(kids) != 1:
                glob[:, j] = glob[:, parent]  # leaf: follows its parent, local = identity
                local[:, j] = np.eye(3)
                break
            k = kids[0]
            rest = unit_vectors(np.einsum("tij,j->ti", glob[:, parent], offsets[k]))
            now = unit_vectors(joints[:, k] - joints[:, j])
            glob[:, j] = swing_rotation(rest, now) @ glob[:, parent]
            local[:, j] = np.swapaxes(glob[:, parent], -1, -2) @ glob[:, j]
            j, parent = k, j
    return local


# ----------------------------------------------------------------------------------------------
# Arms of a generated motion, fitted to the body's bones before the directions are copied

_ARMS = tuple(tuple(JOINT_INDEX[f"{side}_{part}"] for part in ("shoulder", "elbow", "wrist"))
              for side in ("left", "right"))  # fmt: skip
# A frame whose arm bones are within the first length of the body's is left as it is, one past the second
# is fitted whole, and one between is blended (smoothstep): captured clips' rigid bones (within 0.001 mm of
# the body's) stay untouched bit for bit; 98 % of generated frames are off by more than 2 mm (median 11).
_LENGTH_TOLERANCE = (0.0001, 0.001)  # m
# The elbow may bend further than the motion's own elbow only where that bend shows its plane: by up to
# ``_EXTRA_BEND`` once the motion's elbow bends ``_TRUSTED_BEND`` or more, in proportion below; a straight
# arm whose bones are short stays straight, short of its wrist, instead of bending in a guessed plane.
_TRUSTED_BEND = np.radians(20.0)
_EXTRA_BEND = np.radians(60.0)


def reach_arm_ends(joints: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Joints with each arm refitted to the body's upper-arm and forearm lengths, wrist kept.

    joints: (T, 22, 3) metres, any frame; offsets: (22, 3) the body's rest offsets. A generated motion's
    bones change length from frame to frame (the features do not tie them); copying bone directions onto
    fixed bones then moves the wrist by the length changes, up to 15 cm and faster than the motion's
    own wrist. Here the wrist keeps its place relative to the shoulder (or the nearest place the arm
    reaches) and the elbow goes to the point of the two-bone solution nearest the motion's own elbow.
    Returns a new (T, 22, 3) float64 array; the shoulders and every other joint are unchanged
    (docs/decisions/projection.md: "arms fitted to the body's bones").
    """
    x = np.array(joints, dtype=np.float64, copy=True)
    for s, e, w in _ARMS:
        upper, fore = float(np.linalg.norm(offsets[e])), float(np.linalg.norm(offsets[w]))
        sh, el, wr = x[:, s], x[:, e], x[:, w]
        a1, a2 = el - sh, wr - el
        n1, n2 = np.linalg.norm(a1, axis=-1), np.linalg.norm(a2, axis=-1)
        off = np.maximum(np.abs(n1 - upper), np.abs(n2 - fore))
        lo, hi = _LENGTH_TOLERANCE
        blend = np.clip((off - lo) / (hi - lo), 0.0, 1.0)
        blend = blend * blend * (3.0 - 2.0 * blend)
        d = wr - sh
        r = np.linalg.norm(d, axis=-1)
        fit = (blend > 0) & (r > 1e-6) & (n1 > 1e-6) & (n2 > 1e-6)
        u = d / np.maximum(r, 1e-12)[:, None]
        # the motion's own elbow bend, and the bend at which the body's arm reaches the wrist
        own = np.arccos(np.clip(np.sum(a1 * a2, -1) / np.maximum(n1 * n2, 1e-12), -1.0, 1.0))
        reach = np.arccos(np.clip((r**2 - upper**2 - fore**2) / (2 * upper * fore), -1.0, 1.0))
        bend = np.minimum(reach, own + _EXTRA_BEND * np.clip(own / _TRUSTED_BEND, 0.0, 1.0))
        span = np.sqrt(upper**2 + fore**2 + 2 * upper * fore * np.cos(bend))  # shoulder to wrist, fitted
        side = a1 - np.sum(a1 * u, -1, keepdims=True) * u  # the motion's elbow off the shoulder-wrist line
        side_len = np.linalg.norm(side, axis=-1)
        along = (upper**2 - fore**2 + span**2) / (2 * np.maximum(span, 1e-12))
        out = np.sqrt(np.maximum(upper**2 - along**2, 0.0))
        fit &= (side_len > 1e-9) | (out < 1e-6)  # a bent fitted elbow needs the motion's plane
        side_dir = side / np.maximum(side_len, 1e-12)[:, None]
        new_el = sh + along[:, None] * u + out[:, None] * side_dir
        new_wr = sh + span[:, None] * u
        b = blend[:, None]
        x[fit, e] = (el + b * (new_el - el))[fit]
        x[fit, w] = (wr + b * (new_wr - wr))[fit]
    return x


# ----------------------------------------------------------------------------------------------
# joints -> qpos


def joints_to_qpos(
    joints: np.ndarray,
    model_or_offsets: Any = None,
    *,
    lift: float = 0.0,
    config: HumanoidConfig | None = None,
    anatomical: bool = True,
) -> np.ndarray:
    """Humanoid qpos that put the model's joints on ``joints``.

    joints: (T, 22, 3) or (B, T, 22, 3), metres, our Y-up world.
    model_or_offsets: the ``mujoco.MjModel`` from :func:`~physmotion.physics.humanoid.build_model`, or
    the (22, 3) offsets it was built from (with ``config``'s hinge orders), default ``REST_OFFSETS``.
    For an exact fit build the model from ``skeleton.offsets_from_joints(joints)``.
    lift: metres added to the root height (e.g. to put a data floor at the joints onto the soles).
    anatomical: twist thighs and upper arms so knees and elbows bend about their hinge axis (joint
    positions are the same either way; off = the skeleton's plain swing IK).
    Returns qpos (T, 70) or (B, T, 70) float64, continuous over T.
    """
    shape_text = f"(T, {NUM_JOINTS}, 3) or (B, T, {NUM_JOINTS}, 3)"
    x, batched = _as_batch(joints, (NUM_JOINTS, 3), "joints", shape_text)
    lay = _layout_for(model_or_offsets, config)
    bsz, t = x.shape[:2]
    qpos = np.zeros((bsz, t, NQ))
    for b in range(bsz):
        local, root = inverse_kinematics(x[b], lay.offsets)  # (T, 22, 3, 3), (T, 3)
        if anatomical:
            local = _anatomical_twist(x[b], local, lay.offsets)
        qpos[b, :, 0:3] = to_mujoco(root)
        qpos[b, :, 2] += lift
        quat = Rotation.from_matrix(rot_to_mujoco(local[:, 0])).as_quat(scalar_first=True)
        # Same rotation either sign; keep neighbours in one hemisphere so the series interpolates.
        flip = np.cumprod(np.where(np.sum(quat[1:] * quat[:-1], -1) < 0, -1.0, 1.0))
        quat[1:] *= flip[:, None]
        qpos[b, :, 3:7] = quat
        local_mj = rot_to_mujoco(local)
        for seq in set(lay.hinge_order[1:]):
            js = [j for j in range(1, NUM_JOINTS) if lay.hinge_order[j] == seq]
            ang = _continuous_euler(local_mj[:, js], seq)  # (T, n, 3)
            for k, j in enumerate(js):
                qpos[b][:, lay.hinge_qpos[j]] = ang[:, k]
    return qpos if batched else qpos[0]


# ----------------------------------------------------------------------------------------------
# qpos -> joints


def qpos_to_local(
    qpos: np.ndarray, model_or_offsets: Any = None, *, config: HumanoidConfig | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Skeleton pose of qpos (..., 70): local rotations (..., 22, 3, 3) and root positions (..., 3), ours.

    The inverse of the angle part of :func:`joints_to_qpos` (``lift`` is not taken off here).
    """
    lay = _layout_for(model_or_offsets, config)
    local_mj = np.zeros(qpos.shape[:-1] + (NUM_JOINTS, 3, 3))
    quat = qpos[..., 3:7]
    quat = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    root_rot = Rotation.from_quat(quat.reshape(-1, 4), scalar_first=True).as_matrix()
    local_mj[..., 0, :, :] = root_rot.reshape(qpos.shape[:-1] + (3, 3))
    for j in range(1, NUM_JOINTS):
        local_mj[..., j, :, :] = _euler_to_matrix(qpos[..., lay.hinge_qpos[j]], lay.hinge_order[j])
    return rot_from_mujoco(local_mj), from_mujoco(qpos[..., 0:3])


def qpos_to_joints(
    qpos: np.ndarray,
    model_or_offsets: Any = None,
    *,
    lift: float = 0.0,
    method: str = "fk",
    config: HumanoidConfig | None = None,
) -> np.ndarray:
    """Joint positions of the model at ``qpos``.

    qpos: (T, 70) or (B, T, 70). model_or_offsets: as in :func:`joints_to_qpos`.
    method: "fk" (our forward kinematics, vectorised) or "mujoco" (``mj_kinematics`` body positions,
    needs a model). Returns joints (T, 22, 3) or (B, T, 22, 3), metres, our Y-up world, with ``lift``
    taken off the height again.
    """
    x, batched = _as_batch(qpos, (NQ,), "qpos", f"(T, {NQ}) or (B, T, {NQ})")
    if method == "fk":
        lay = _layout_for(model_or_offsets, config)
        local, root = qpos_to_local(x, model_or_offsets, config=config)
        root[..., 1] -= lift
        out = forward_kinematics(local, root, lay.offsets)
    elif method == "mujoco":
        import mujoco

        if model_or_offsets is None or isinstance(model_or_offsets, np.ndarray):
            raise ShapeError("method='mujoco' needs a compiled model, not offsets")
        model = model_or_offsets
        lay = layout(model)
        data = mujoco.MjData(model)
        flat = x.reshape(-1, NQ)
        pos = np.zeros((flat.shape[0], NUM_JOINTS, 3))
        for i, q in enumerate(flat):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            pos[i] = data.xpos[lay.body_ids]
        pos[..., 2] -= lift
        out = from_mujoco(pos).reshape(x.shape[:2] + (NUM_JOINTS, 3))
    else:
        raise ShapeError(f"method must be 'fk' or 'mujoco', got '{method}'")
    return out if batched else out[0]


# ----------------------------------------------------------------------------------------------
# Velocities


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of scalar-first quaternions (..., 4)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
         aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1,
    )  # fmt: skip


def _quat_log_diff(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Rotation vector (..., 3) of q1^-1 q2, i.e. the turn from q1 to q2 in q1's local frame.

    As MuJoCo's ``mju_subQuat(q2, q1)``: shortest way round (the quaternion's sign is free).
    """
    conj = q1 * np.array([1.0, -1.0, -1.0, -1.0])
    rel = _quat_mul(conj, q2)
    rel = rel / np.linalg.norm(rel, axis=-1, keepdims=True)
    rel = np.where(rel[..., :1] < 0, -rel, rel)
    vec = rel[..., 1:]
    s = np.linalg.norm(vec, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, rel[..., :1])
    scale = np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 2.0)
    return vec * scale


def _diff(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Tangent-space difference q2 - q1 (..., 69) of qpos pairs (..., 70), as mj_differentiatePos * dt."""
    out = np.empty(q1.shape[:-1] + (NV,))
    out[..., 0:3] = q2[..., 0:3] - q1[..., 0:3]  # world frame
    out[..., 3:6] = _quat_log_diff(q1[..., 3:7], q2[..., 3:7])  # root's local frame
    out[..., 6:] = q2[..., 7:] - q1[..., 7:]
    return out


def qvel_from_qpos(qpos: np.ndarray, dt: float, scheme: str = "central") -> np.ndarray:
    """Generalised velocities (T, 69) or (B, T, 69) of a qpos series (T, 70) or (B, T, 70) at step dt.

    Consistent with MuJoCo's ``mj_differentiatePos``: root linear velocity in the world frame, root
    angular velocity in the pelvis' local frame, hinge rates. scheme: "forward" (v[t] = q[t+1] - q[t],
    last frame repeats the one before; ``mj_integratePos(q[t], v[t], dt)`` lands on q[t+1]), "backward",
    or "central" (mean of both, each taken from frame t; the ends fall back to one side).
    A single frame has zero velocity.
    """
    x, batched = _as_batch(qpos, (NQ,), "qpos", f"(T, {NQ}) or (B, T, {NQ})")
    if not dt > 0:
        raise ShapeError(f"dt must be positive, got {dt}")
    t = x.shape[1]
    v = np.zeros(x.shape[:2] + (NV,))
    if t > 1:
        fwd = _diff(x[:, :-1], x[:, 1:]) / dt  # (B, T-1, 69): v at t from t to t+1, in t's frame
        if scheme == "forward":
            v[:, :-1] = fwd
            v[:, -1] = fwd[:, -1]
        elif scheme == "backward":
            v[:, 1:] = -_diff(x[:, 1:], x[:, :-1]) / dt  # in frame t (the later one)
            v[:, 0] = v[:, 1]
        elif scheme == "central":
            bwd = -_diff(x[:, 1:], x[:, :-1]) / dt  # (B, T-1): v at t+1 from t to t+1, in frame t+1
            v[:, 1:-1] = 0.5 * (fwd[:, 1:] + bwd[:, :-1])
            v[:, 0] = fwd[:, 0]
            v[:, -1] = bwd[:, -1]
        else:
            raise ShapeError(f"scheme must be 'forward', 'backward' or 'central', got '{scheme}'")
    return v if batched else v[0]


def qpos_at(qpos: np.ndarray, times: np.ndarray, fps: float = 1.0) -> np.ndarray:
    """qpos (T, 70), whose frame i is at time i / fps, read at ``times`` (N,) within its span: (N, 70), the
    hinges and root position linearly, the root quaternion by slerp (fps 1: fractional frame indices)."""

    t_in = np.arange(len(qpos)) / fps
    out = np.empty((len(times), qpos.shape[1]))
    for i in [0, 1, 2, *range(7, qpos.shape[1])]:
        out[:, i] = np.interp(times, t_in, qpos[:, i])
    if len(qpos) == 1:
        out[:, 3:7] = qpos[0, 3:7]
        return out
    rots = Rotation.from_quat(qpos[:, 3:7], scalar_first=True)
    out[:, 3:7] = Slerp(t_in, rots)(times).as_quat(scalar_first=True)
    return out


__all__ = ["NQ", "NV", "joints_to_qpos", "qpos_at", "qpos_to_joints", "qpos_to_local", "qvel_from_qpos"]
