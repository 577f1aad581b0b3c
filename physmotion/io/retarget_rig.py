"""Retarget a motion of our 22-joint body onto a user's own skeleton (``export --rig-from THEIR.bvh``).

Their skeleton (hierarchy, offsets, rest pose) comes from their BVH file's header: the pose every
rotation channel at zero gives, whatever it is (T-pose, A-pose, Bandai's bones along +X). Which of
their joints is which of ours is a rig table (:data:`~physmotion.io.rigs.RIGS`) or a mapping file
(:mod:`physmotion.io.mapping`), the same ones ``import`` reads, so the output imports back with them.

Method (bone direction matching, as Blender's and Rokoko's retargeters do it; read for the idea, not
copied: Rokoko's ``retargeting.py`` in rokoko-studio-live-blender and the Blender manual's "Copy
Rotation"/"Track To" based set-ups):

1. each of our joints that has children has one *driving* node on their rig: the node of its mapping
   (the heaviest of a blend). Going down the tree, a driving node's world rotation is chosen so that the
   rig points of our children lie in the directions ours do: one child, the smallest rotation from
   where the bone points now (the parent's frame carried down, so the bone keeps its parent's twist);
   two or more (pelvis, chest), the best rotation of all child directions (Kabsch). Nodes that drive
   nothing (fingers, twist bones, extra spine joints, the hands and head) keep their rest rotation
   relative to their parent, so they follow it rigidly. Their bone lengths are kept.
2. the root is placed so that their pelvis point is ours scaled by the leg-length ratio (their
   hip-to-ankle length over ours in rest), all three axes, so a taller rig walks further and higher;
3. feet: in the frames where our foot joint touches the floor (the metrics' contact rule,
   :func:`physmotion.metrics.physical.foot_contacts` on the humanoid's surface), the joint holding the foot (the ankle, else the toe) is
   kept where it was in the previous frame, horizontally; the correction fades out over
   :attr:`RetargetConfig.release_s` after contact ends; an analytic two-bone IK (hip-knee-ankle, law of
   cosines, the knee kept in its current bending plane) moves the ankle there, and the foot keeps its
   world rotation. So retargeting adds no sliding to a planted foot.

Units and axes: everything is solved in our world (metres, Y up) with their offsets converted by the
rig's units and up axis; the rotations are converted back to their axes at the end.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.io.bvh import WRITE_ORDER, read_bvh_rest, write_bvh
from physmotion.io.canonical import TO_Y_UP
from physmotion.io.mapping import load_mapping
from physmotion.io.rigs import RIGS, JointSource, RigMotion, RigTable, parse_units, table_from_mapping
from physmotion.motion import Motion
from physmotion.skeleton import (
    JOINT_INDEX,
    JOINT_NAMES,
    NUM_JOINTS,
    bone_lengths,
    children,
    kabsch,
    swing_rotation,
    unit_vectors,
)

_SIDES = ("left", "right")


@dataclass(frozen=True)
class RetargetConfig:
    """Settings of :func:`retarget`.

    release_s: seconds over which a foot's pin correction fades out after its contact ends (an
    exponential time constant; shorter pops, longer drags the swing foot).
    pin_feet: whether to pin stance feet at all (off: pure direction matching, for comparison).
    """

    release_s: float = 0.1
    pin_feet: bool = True


@dataclass(frozen=True)
class TargetRig:
    """A user's skeleton to retarget onto: its rest pose (file units and axes), the table that maps our
    joints onto it, metres per file unit and the file's up axis."""

    rest: RigMotion
    table: RigTable
    units: float
    up_axis: str
    path: Path


@dataclass
class RetargetResult:
    """What :func:`retarget` made: ``rig`` (T frames in file units and axes, every node), the leg-length
    ratio (theirs / ours), ``contacts`` (T, 2) the frames each foot (left, right) was held, and
    ``correction`` (T, 2) the horizontal pin correction of each ankle, metres."""

    rig: RigMotion
    leg_ratio: float
    contacts: np.ndarray
    correction: np.ndarray


def load_target(
    path: str | Path,
    *,
    rig: str | None = None,
    mapping: Mapping[str, JointSource] | str | Path | None = None,
    units: str | float | None = None,
    up_axis: str | None = None,
) -> TargetRig:
    """Read the skeleton of BVH ``path`` and the table mapping our joints onto it.

    rig: a name in :data:`~physmotion.io.rigs.RIGS`; mapping: a mapping JSON path or dict (as
    ``import --mapping``); neither: the known table whose joints the file has. units (metres per unit or
    a name) and up_axis override the table's or mapping's. Errors are one-line PhysmotionErrors.
    """
    path = Path(path)
    rest = read_bvh_rest(path)
    if rig is not None and mapping is not None:
        raise PhysmotionError(f"give a rig ({rig!r}) or a mapping, not both")
    map_units = map_up = None
    if isinstance(mapping, (str, Path)):
        loaded = load_mapping(mapping)
        mapping, map_units, map_up = loaded.joints, loaded.units, loaded.up_axis
    if mapping is not None:
        table = table_from_mapping(mapping, name="mapping", units=map_units, up_axis=map_up)
    elif rig is not None:
        if rig not in RIGS:
            raise PhysmotionError(f"unknown rig {rig!r} (known: {', '.join(RIGS)}; or give --mapping map.json)")
        table = RIGS[rig]
    else:
        fits = [t for t in RIGS.values() if t.nodes() <= set(rest.names)]
        if not fits:
            shown = ", ".join(rest.names[:4])
            raise PhysmotionError(f"{path}: unknown rig (joints {shown}, ...): give --rig NAME or --mapping map.json")
        table = fits[0]
    missing = sorted(table.nodes() - set(rest.names))
    if missing:
        what = "mapping" if table.name == "mapping" else f"rig {table.name}"
        raise PhysmotionError(f"{path}: {what} names joint(s) the file lacks: {', '.join(missing[:5])}")
    metres = parse_units(units) if units is not None else table.units
    if metres is None:
        raise PhysmotionError(f"{path}: units unknown for rig {table.name!r}: give --units (e.g. cm)")
    up = (up_axis or table.up_axis or "Y").upper()
    if up not in TO_Y_UP:
        raise PhysmotionError(f"up axis must be one of X, Y, Z, got {up_axis!r}")
    return TargetRig(rest=rest, table=table, units=float(metres), up_axis=up, path=path)


def retarget(motion: Motion, target: TargetRig, config: RetargetConfig | None = None) -> RetargetResult:
    """Our motion (``motion.joints`` (T, 22, 3) metres, Y up, floor y = 0) on ``target``'s skeleton.

    Returns the rig motion in the file's units and axes: local rotations (T, J, 3, 3) and translations
    (T, J, 3), the root's its world position, every other node's its rest OFFSET (bone lengths kept).
    """
    from physmotion.metrics.physical import foot_contacts
    from physmotion.physics.surface import HumanoidSurface  # MuJoCo: the surface `physmotion metrics` uses

    cfg = config or RetargetConfig()
    ours = np.asarray(motion.joints, dtype=np.float64)
    n = ours.shape[0]
    rest = target.rest
    j_count = len(rest.names)
    turn = TO_Y_UP[target.up_axis]  # file axes -> ours (a proper rotation)
    offsets = rest.translations[0] @ turn.T * target.units  # (J, 3) metres, our axes
    parents = np.asarray(rest.parents)
    weights = target.table.weights(rest.names)  # (22, J): our joints = weights @ node positions
    drive = _driving_nodes(target.table, rest.names, parents)
    local = np.broadcast_to(np.eye(3), (n, j_count, 3, 3)).copy()
    root = np.zeros((n, 3))

    # 1. directions, top down: a driving node's rotation only moves the points below it
    for j in range(NUM_JOINTS):
        a = drive[j]
        kids = [c for c in children(j) if a is not None and _below(_nodes_of(target.table, c, rest.names), a, parents)]
        if a is None or not kids:
            continue
        glob, pos = _fk(local, root, offsets, parents)
        points = np.einsum("kj,tjd->tkd", weights, pos)
        now = np.stack([points[:, c] - points[:, j] for c in kids], axis=1)  # (T, K, 3)
        want = unit_vectors(np.stack([ours[:, c] - ours[:, j] for c in kids], axis=1))
        if len(kids) == 1:
            new = swing_rotation(unit_vectors(now[:, 0]), want[:, 0]) @ glob[:, a]
        else:
            in_node = np.einsum("tji,tkj->tki", glob[:, a], now)  # G^T v: the vectors in the node's frame
            new = kabsch(unit_vectors(in_node), want)
        parent_glob = glob[:, parents[a]] if parents[a] >= 0 else np.broadcast_to(np.eye(3), (n, 3, 3))
        local[:, a] = np.swapaxes(parent_glob, -1, -2) @ new

    # 2. the root: their pelvis point at ours scaled by the leg-length ratio
    ratio = _leg_length(rest, weights, offsets, parents) / _our_leg_length(ours)
    _, pos = _fk(local, root, offsets, parents)
    pelvis = np.einsum("j,tjd->td", weights[JOINT_INDEX["pelvis"]], pos)
    root = ratio * ours[:, 0] - pelvis

    # 3. stance feet held, by two-bone IK
    contact = foot_contacts(ours, HumanoidSurface())  # (T, 4): left ankle, left foot, right ankle, right foot
    correction = np.zeros((n, 2))
    if cfg.pin_feet:
        for s, side in enumerate(_SIDES):
            shift = _pin_shift(local, root, offsets, parents, weights, side, contact[:, 2 * s : 2 * s + 2],
                               motion.fps, cfg.release_s)  # fmt: skip
            correction[:, s] = np.linalg.norm(shift, axis=-1)
            if np.any(correction[:, s] > 0):
                _two_bone_ik(local, root, offsets, parents, weights, drive, side, shift)

    # back to the file's axes and units
    file_local = np.einsum("ji,tnjk,kl->tnil", turn, local, turn)  # turn^T L turn
    translations = np.broadcast_to(rest.translations[0], (n, j_count, 3)).copy()
    translations[:, 0] = root @ turn / target.units  # turn^T p
    out = RigMotion(
        names=rest.names, parents=parents, rotations=file_local, translations=translations,
        fps=motion.fps, is_end=rest.is_end,
    )  # fmt: skip
    held = contact.reshape(n, 2, 2).any(axis=-1)
    return RetargetResult(out, float(ratio), held, correction)


def save_retargeted_bvh(
    motion: Motion, path: str | Path, target: TargetRig, config: RetargetConfig | None = None
) -> RetargetResult:
    """Retarget ``motion`` onto ``target`` and write it as BVH at ``path`` (atomically): their hierarchy
    and OFFSETs, rotation channels on every joint (order :data:`~physmotion.io.bvh.WRITE_ORDER`), the
    root's position channels in their units, frame time ``1 / motion.fps``."""
    result = retarget(motion, target, config)
    write_bvh(path, result.rig, motion.fps, order=WRITE_ORDER)
    return result


# ------------------------------------------------------------------------------------------------


def _nodes_of(table: RigTable, joint: int, names: tuple[str, ...]) -> list[int]:
    """Indices of the rig nodes our joint ``joint`` is made of (one, or a blend's)."""
    src = table.joints[JOINT_NAMES[joint]]
    pairs = ((src, 1.0),) if isinstance(src, str) else src
    return [names.index(node) for node, _ in pairs]


def _driving_nodes(table: RigTable, names: tuple[str, ...], parents: np.ndarray) -> list[int | None]:
    """Per joint of ours, the rig node whose rotation aims its bones: the heaviest node of its mapping,
    None where an ancestor joint already drives that node (a blend between two joints' nodes)."""
    out: list[int | None] = []
    taken: set[int] = set()
    for j in range(NUM_JOINTS):
        src = table.joints[JOINT_NAMES[j]]
        pairs = [(src, 1.0)] if isinstance(src, str) else list(src)
        node = names.index(max(pairs, key=lambda p: p[1])[0])  # max keeps the first of equal weights
        out.append(None if node in taken else node)
        taken.add(node)
    return out


def _below(nodes: list[int], a: int, parents: np.ndarray) -> bool:
    """Whether every node in ``nodes`` is ``a`` or a descendant of it (so ``a`` moves it)."""
    for node in nodes:
        k = node
        while k >= 0 and k != a:
            k = int(parents[k])
        if k != a:
            return False
    return True


def _fk(
    local: np.ndarray, root: np.ndarray, offsets: np.ndarray, parents: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (T, J, 3, 3) and positions (T, J, 3) of a rig: local (T, J, 3, 3), root (T, 3)."""
    n, j_count = local.shape[:2]
    glob = np.empty_like(local)
    pos = np.empty((n, j_count, 3))
    for j, p in enumerate(parents):
        if p < 0:
            glob[:, j] = local[:, j]
            pos[:, j] = root + offsets[j] if j else root
        else:
            glob[:, j] = glob[:, p] @ local[:, j]
            pos[:, j] = pos[:, p] + glob[:, p] @ offsets[j]
    return glob, pos


def _leg_length(rest: RigMotion, weights: np.ndarray, offsets: np.ndarray, parents: np.ndarray) -> float:
    """Their mean hip-knee-ankle length in rest, metres."""
    _, pos = _fk(rest.rotations[:1], np.zeros((1, 3)), offsets, parents)
    points = weights @ pos[0]  # (22, 3)
    return float(np.mean([_chain(points, side) for side in _SIDES]))


def _our_leg_length(joints: np.ndarray) -> float:
    """Our mean hip-knee-ankle length (median bone lengths over the motion), metres."""
    lengths = np.median(bone_lengths(joints), axis=0)
    return float(np.mean([lengths[JOINT_INDEX[f"{s}_knee"]] + lengths[JOINT_INDEX[f"{s}_ankle"]] for s in _SIDES]))


def _chain(points: np.ndarray, side: str) -> float:
    hip, knee, ankle = (points[JOINT_INDEX[f"{side}_{n}"]] for n in ("hip", "knee", "ankle"))
    return float(np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee))


def _pin_shift(
    local: np.ndarray, root: np.ndarray, offsets: np.ndarray, parents: np.ndarray, weights: np.ndarray,
    side: str, contact: np.ndarray, fps: float, release_s: float,
) -> np.ndarray:  # fmt: skip
    """(T, 3) horizontal shift of one ankle that holds its planted foot joint still.

    contact: (T, 2) our ankle's and toe's contact. In a frame where the joint holding the foot (the
    ankle if it touches, else the toe) touched in the frame before too, the shift makes it stay where it
    was; otherwise the shift decays by exp(-1 / (fps * release_s)) per frame.
    """
    _, pos = _fk(local, root, offsets, parents)
    points = np.einsum("kj,tjd->tkd", weights, pos)
    feet = points[:, [JOINT_INDEX[f"{side}_ankle"], JOINT_INDEX[f"{side}_foot"]]]  # (T, 2, 3)
    decay = float(np.exp(-1.0 / max(fps * release_s, 1e-6)))
    shift = np.zeros((len(points), 3))
    for t in range(1, len(points)):
        held = [k for k in (0, 1) if contact[t, k] and contact[t - 1, k]]
        if held:
            k = held[0]
            step = feet[t, k] - feet[t - 1, k]
            shift[t] = shift[t - 1] - step
            shift[t, 1] = 0.0
        else:
            shift[t] = shift[t - 1] * decay
    return shift


def _two_bone_ik(
    local: np.ndarray, root: np.ndarray, offsets: np.ndarray, parents: np.ndarray, weights: np.ndarray,
    drive: list[int | None], side: str, shift: np.ndarray,
) -> None:  # fmt: skip
    """Move one ankle node by ``shift`` (T, 3) with its hip and knee nodes (in place on ``local``),
    keeping the knee in its bending plane and the ankle node's world rotation (the foot's aim)."""
    hip, knee, ankle = (drive[JOINT_INDEX[f"{side}_{n}"]] for n in ("hip", "knee", "ankle"))
    if hip is None or knee is None or ankle is None:
        return
    glob, pos = _fk(local, root, offsets, parents)
    foot_rot = glob[:, ankle].copy()
    h, k, a = pos[:, hip], pos[:, knee], pos[:, ankle]
    goal = a + shift
    l1 = np.linalg.norm(k - h, axis=-1)
    l2 = np.linalg.norm(a - k, axis=-1)
    to_goal = goal - h
    d = np.clip(np.linalg.norm(to_goal, axis=-1), np.abs(l1 - l2) + 1e-6, l1 + l2 - 1e-6)
    u = unit_vectors(to_goal)
    bend = (k - h) - np.sum((k - h) * u, axis=-1, keepdims=True) * u  # the knee's side of the hip-goal line
    w = unit_vectors(bend)
    cos_hip = np.clip((l1**2 + d**2 - l2**2) / (2 * l1 * d), -1.0, 1.0)
    new_knee = h + l1[:, None] * (cos_hip[:, None] * u + np.sqrt(1 - cos_hip**2)[:, None] * w)
    _turn_node(local, glob, parents, hip, swing_rotation(unit_vectors(k - h), unit_vectors(new_knee - h)))
    glob, pos = _fk(local, root, offsets, parents)
    k, a = pos[:, knee], pos[:, ankle]
    goal_dir = unit_vectors(h + u * d[:, None] - k)
    _turn_node(local, glob, parents, knee, swing_rotation(unit_vectors(a - k), goal_dir))
    glob, _ = _fk(local, root, offsets, parents)
    local[:, ankle] = np.swapaxes(glob[:, parents[ankle]], -1, -2) @ foot_rot


def _turn_node(local: np.ndarray, glob: np.ndarray, parents: np.ndarray, node: int, turn: np.ndarray) -> None:
    """Pre-multiply node's world rotation by ``turn`` (T, 3, 3), as a change of its local rotation."""
    p = parents[node]
    parent_glob = glob[:, p] if p >= 0 else np.broadcast_to(np.eye(3), turn.shape)
    local[:, node] = np.swapaxes(parent_glob, -1, -2) @ turn @ glob[:, node]



def error_at_our_proportions(ours: np.ndarray, back: np.ndarray, leg_ratio: float) -> tuple[float, float]:
    """Mean joint distance (m) between ``ours`` and ``back``, a motion retargeted and imported again, after
    scaling ``back`` to our proportions; and the heading (degrees) the placement fit turned it by.

    ours, back: (T, 22, 3) metres, Y up. ``back`` is rebuilt with our bone lengths and its own bone
    directions (:func:`~physmotion.skeleton.inverse_kinematics` onto our rest offsets), its root path
    divided by ``leg_ratio``; then, since ``import`` puts frame 0 over the origin facing +Z, it is
    placed on ours by the heading and shift that fit best (least squares, closed form).
    """
    from physmotion.skeleton import forward_kinematics, inverse_kinematics, offsets_from_joints

    a = np.asarray(ours, dtype=np.float64)
    offsets = offsets_from_joints(a)
    rotations, _ = inverse_kinematics(np.asarray(back, dtype=np.float64), offsets)
    b = forward_kinematics(rotations, np.asarray(back, dtype=np.float64)[:, 0] / leg_ratio, offsets)
    pa, pb = a.reshape(-1, 3), b.reshape(-1, 3)
    ca, cb = pa - pa.mean(0), pb - pb.mean(0)
    # the yaw about +Y that best turns b's (x, z) onto a's: 2-D Procrustes
    num = np.sum(cb[:, 2] * ca[:, 0] - cb[:, 0] * ca[:, 2])
    den = np.sum(cb[:, 0] * ca[:, 0] + cb[:, 2] * ca[:, 2])
    yaw = float(np.arctan2(num, den))
    c, s = np.cos(yaw), np.sin(yaw)
    turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    placed = cb @ turn.T + pa.mean(0)
    return float(np.linalg.norm(placed - pa, axis=-1).mean()), float(np.degrees(yaw))
