"""BVH reader and writer for any rig.

Hand-written rather than taken from a BVH library: the files we import mix per-joint channel orders,
6 channels on every joint (Bandai, whose animated translations must replace the OFFSETs), CRLF and
LF line endings in one file and tabs; we need one-line errors for every malformed input; and the
result must be our generic :class:`~physmotion.io.rigs.RigMotion`, which ASF/AMC also produce.
The motion block is parsed by numpy in one call, so a file costs milliseconds.

Semantics (as Blender's importer): a node's position channels *replace* its OFFSET; rotation
channels listed as ``Zrotation Xrotation Yrotation`` mean ``R = Rz @ Rx @ Ry`` (intrinsic ZXY);
an ``End Site`` becomes a node named ``<parent>_end`` with ``is_end`` set.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from physmotion.errors import MotionFormatError, PhysmotionWarning
from physmotion.io.rigs import RigMotion, closure, euler_to_matrix, remap_parents
from physmotion.motion import write_atomic

WRITE_ORDER = "YZX"
"""Rotation order :func:`write_bvh` uses by default (channels ``Yrotation Zrotation Xrotation``).

The middle angle is the one limited to +-90 degrees (gimbal lock there). For a Y-up rig in T-pose
rest, Z (arm raise from the T-pose, leg abduction) is the axis that rarely passes 90 degrees,
whereas heading (Y), knee and hip flexion (X) and elbow flexion often do; so Z sits in the middle."""

_AXES = {"X": 0, "Y": 1, "Z": 2}


class Latin1Warning(PhysmotionWarning):
    """A motion file that is not UTF-8 and was read as Latin-1; ``path`` names it."""

    def __init__(self, message: str, path: Path) -> None:
        super().__init__(message)
        self.path = path


def read_text(path: str | Path, kind: str) -> str:
    """The text of a motion file, or a one-line MotionFormatError (missing, a folder, binary, empty).

    UTF-8 (a BOM is dropped); a file that is not UTF-8 is read as Latin-1, with a :class:`Latin1Warning`.
    """
    path = Path(path)
    if not path.exists():
        raise MotionFormatError(f"{path}: no such file")
    if not path.is_file():
        raise MotionFormatError(f"{path}: not a file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MotionFormatError(f"{path}: cannot read the file ({exc.strerror or exc})") from None
    if not data.strip():
        raise MotionFormatError(f"{path}: empty file")
    if b"\0" in data[:4096]:
        raise MotionFormatError(f"{path}: binary data, not a {kind} text file")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        # Real files carry Latin-1 / cp1252 in comments and names (HDM05's headers); every byte decodes.
        message = f"{path}: not UTF-8 (byte 0x{data[exc.start]:02x} at offset {exc.start}): read as Latin-1"
        warnings.warn(Latin1Warning(message, path), stacklevel=2)
        return data.decode("latin-1")


def read_bvh(path: str | Path, keep: set[str] | None = None) -> RigMotion:
    """Read a BVH file into a RigMotion (file units and axes, the header's frame rate).

    keep: node names needed; only they and their ancestors are built (iClone files have 142 nodes
    of which an import needs 30). None: every node.
    """
    return parse_bvh(read_text(path, "BVH"), str(path), keep)


def bvh_joint_names(path: str | Path) -> tuple[str, ...]:
    """Every node name of a BVH file's hierarchy, in file order (End Sites as ``<parent>_end``)."""
    text = read_text(path, "BVH")
    split = _MOTION.search(text)
    tokens = (text[: split.start()] if split else text).split()
    if not tokens or tokens[0] != "HIERARCHY":
        raise MotionFormatError(f"{path}: not a BVH file (it does not start with HIERARCHY)")
    return tuple(_parse_hierarchy(tokens, str(path))[0])


def read_bvh_rest(path: str | Path) -> RigMotion:
    """The rest pose of a BVH file's skeleton: one frame, every rotation the identity, every node at its
    header ``OFFSET`` (the pose a BVH's OFFSETs define, which Blender shows as the armature's rest pose;
    the motion block is not read). Names and ``is_end`` as :func:`read_bvh`; ``fps`` from the header."""
    text = read_text(path, "BVH")
    split = _MOTION.search(text)
    tokens = (text[: split.start()] if split else text).split()
    if not tokens or tokens[0] != "HIERARCHY":
        raise MotionFormatError(f"{path}: not a BVH file (it does not start with HIERARCHY)")
    names, parents, offsets, _, is_end = _parse_hierarchy(tokens, str(path))
    fps = None
    if split is not None:
        match = _FRAMES.match(text[split.end() :])
        try:
            frame_time = float(match.group(2)) if match else 0.0
        except ValueError:
            frame_time = 0.0
        fps = 1.0 / frame_time if frame_time > 0 else None
    count = len(names)
    return RigMotion(
        names=tuple(names),
        parents=np.array(parents, dtype=int),
        rotations=np.broadcast_to(np.eye(3), (1, count, 3, 3)).copy(),
        translations=np.array(offsets, dtype=np.float64)[None],
        fps=fps,
        is_end=tuple(is_end),
    )


def parse_bvh(text: str, where: str = "<bvh>", keep: set[str] | None = None) -> RigMotion:
    """Parse BVH text; ``where`` names the source in error messages; ``keep`` as in :func:`read_bvh`."""
    split = _MOTION.search(text)
    head, body = (text[: split.start()], text[split.end() :]) if split else (text, "")
    tokens = head.split()
    if not tokens or tokens[0] != "HIERARCHY":
        raise MotionFormatError(f"{where}: not a BVH file (it does not start with HIERARCHY)")
    if split is None:
        raise MotionFormatError(f"{where}: truncated BVH: no MOTION section")
    names, parents, offsets, channels, is_end = _parse_hierarchy(tokens, where)
    frames, frame_time, values = _parse_motion(body, where)
    n_channels = sum(len(c) for c in channels)
    if n_channels == 0:
        raise MotionFormatError(f"{where}: the hierarchy has no channels")
    need = frames * n_channels
    if values.size < need:
        raise MotionFormatError(
            f"{where}: truncated BVH: the header announces {frames} frames of {n_channels} channels, "
            f"the file holds {values.size // n_channels} complete frames"
        )
    values = values[:need].reshape(frames, n_channels)
    if not np.all(np.isfinite(values)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(values), axis=1))[0])
        raise MotionFormatError(f"{where}: NaN or infinite values in the motion block (frame {bad})")
    kept = np.arange(len(names)) if keep is None else closure(names, parents, keep)
    rotations, translations = _channels_to_local(values, offsets, channels, kept)
    return RigMotion(
        names=tuple(names[j] for j in kept),
        parents=remap_parents(parents, kept),
        rotations=rotations,
        translations=translations,
        fps=1.0 / frame_time if frame_time > 0 else None,
        is_end=tuple(is_end[j] for j in kept),
    )


def _parse_hierarchy(
    tokens: list[str], where: str
) -> tuple[list[str], list[int], list[np.ndarray], list[list[str]], list[bool]]:
    """Nodes in file order (parents first): names, parents, offsets, channel names, end flags."""
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[list[str]] = []
    is_end: list[bool] = []
    stack: list[int] = []  # open nodes
    pending: int | None = None  # node declared, waiting for its "{"
    i = 1
    try:
        while i < len(tokens):
            tok = tokens[i]
            if tok in ("ROOT", "JOINT") or (tok == "End" and tokens[i + 1] == "Site"):
                if tok == "ROOT" and names:
                    raise MotionFormatError(f"{where}: more than one ROOT is not supported")
                if tok != "ROOT" and not stack:
                    raise MotionFormatError(f"{where}: malformed BVH hierarchy: {tok} outside ROOT")
                parent = stack[-1] if stack else -1
                name = f"{names[parent]}_end" if tok == "End" else tokens[i + 1]
                names.append(name)
                parents.append(parent)
                offsets.append(np.zeros(3))
                channels.append([])
                is_end.append(tok == "End")
                pending = len(names) - 1
                i += 2
            elif tok == "{":
                if pending is None:
                    raise MotionFormatError(f"{where}: malformed BVH hierarchy: unexpected '{{'")
                stack.append(pending)
                pending = None
                i += 1
            elif tok == "}":
                if not stack:
                    raise MotionFormatError(f"{where}: malformed BVH hierarchy: unbalanced '}}'")
                stack.pop()
                i += 1
            elif tok == "OFFSET":
                offset = np.array([float(t) for t in tokens[i + 1 : i + 4]])
                if offset.shape != (3,) or not np.all(np.isfinite(offset)):
                    numbers = " ".join(tokens[i + 1 : i + 4])[:60]
                    raise MotionFormatError(f"{where}: bad OFFSET of {names[stack[-1]][:40]}: {numbers}")
                offsets[stack[-1]] = offset
                i += 4
            elif tok == "CHANNELS":
                count = int(tokens[i + 1])
                chans = tokens[i + 2 : i + 2 + count]
                unknown = [c for c in chans if c[1:] not in ("position", "rotation") or c[0] not in _AXES]
                if unknown or len(chans) != count:
                    raise MotionFormatError(f"{where}: bad BVH channel list {chans!r}")
                channels[stack[-1]] = chans
                i += 2 + count
            else:
                raise MotionFormatError(f"{where}: malformed BVH hierarchy: unexpected {tok[:40]!r}")
    except (IndexError, ValueError):
        raise MotionFormatError(f"{where}: malformed or truncated BVH hierarchy near token {i}") from None
    if stack or pending is not None or not names:
        raise MotionFormatError(f"{where}: truncated BVH hierarchy (unclosed braces)")
    seen: set[str] = set()
    for name, end in zip(names, is_end, strict=True):
        if name in seen and not end:  # a mapping could not tell the two apart
            raise MotionFormatError(f"{where}: joint name {name[:40]!r} appears twice in the hierarchy")
        seen.add(name)
    return names, parents, offsets, channels, is_end


_MOTION = re.compile(r"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE)
_FRAMES = re.compile(r"\s*Frames:\s*(\S+)\s+Frame\s+Time:\s*(\S+)")


def _parse_motion(body: str, where: str) -> tuple[int, float, np.ndarray]:
    """Frame count, frame time and the flat array of values of the MOTION section."""
    match = _FRAMES.match(body)
    if match is None:
        raise MotionFormatError(f"{where}: truncated or malformed BVH: no 'Frames:' and 'Frame Time:' lines")
    try:
        frames, frame_time = int(match.group(1)), float(match.group(2))
    except ValueError:
        raise MotionFormatError(f"{where}: bad 'Frames:' or 'Frame Time:' value in the BVH header") from None
    if frames <= 0:
        raise MotionFormatError(f"{where}: the BVH file has zero frames")
    try:  # C-speed text parse; raises on any token that is not a number
        values = np.fromstring(body[match.end() :], sep=" ")
    except ValueError:
        raise MotionFormatError(f"{where}: non-numeric text in the BVH motion block") from None
    return frames, frame_time, values


def _channels_to_local(
    values: np.ndarray, offsets: list[np.ndarray], channels: list[list[str]], kept: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations (T, K, 3, 3) and translations (T, K, 3) of the kept nodes from the (T, C) values."""
    n = values.shape[0]
    translations = np.broadcast_to(np.array(offsets)[kept], (n, len(kept), 3)).copy()
    rotations = np.broadcast_to(np.eye(3), (n, len(kept), 3, 3)).copy()
    by_order: dict[str, tuple[list[int], list[list[int]]]] = {}  # rotation order -> nodes, columns
    starts = np.cumsum([0] + [len(c) for c in channels])
    for j, node in enumerate(kept):
        rot_cols: list[int] = []
        order = ""
        for col, c in enumerate(channels[node], start=starts[node]):
            if c.endswith("position"):
                translations[:, j, _AXES[c[0]]] = values[:, col]
            else:
                rot_cols.append(col)
                order += c[0]
        if order:
            nodes, cols = by_order.setdefault(order, ([], []))
            nodes.append(j)
            cols.append(rot_cols)
    for order, (nodes, cols) in by_order.items():
        angles = values[:, np.array(cols)]  # (T, K, len(order))
        rotations[:, nodes] = euler_to_matrix(angles, order)
    return rotations, translations


def write_bvh(
    path: str | Path,
    rig: RigMotion,
    fps: float,
    *,
    order: str = WRITE_ORDER,
    end_offsets: dict[str, np.ndarray] | None = None,
    precision: int = 6,
) -> None:
    """Write any RigMotion as BVH, atomically (nothing is left at ``path`` if it fails).

    Every node gets rotation channels in ``order`` (intrinsic, e.g. "YZX"); the root, and any node
    whose translation changes over time, also gets ``Xposition Yposition Zposition`` first. Nodes
    flagged ``is_end`` become End Sites; other leaves get an End Site at ``end_offsets[name]``
    (default: half the leaf's own offset, so viewers draw a bone). Values are written in the rig's
    units. The root's OFFSET is 0 0 0 and its position channels hold its absolute position: importers
    that let the channels replace the OFFSET (Blender's ``import_bvh``, ours) and those that add the
    two read the same motion (CMU's cgspeed BVH files write the root the same way).
    """
    order = order.upper()
    if sorted(order) != ["X", "Y", "Z"]:
        raise ValueError(f"order must be a permutation of XYZ, got {order!r}")
    end_offsets = end_offsets or {}
    n, j_count = rig.rotations.shape[:2]
    kids: list[list[int]] = [[] for _ in range(j_count)]
    for j, p in enumerate(rig.parents):
        if p >= 0:
            kids[p].append(j)
    moving = np.ptp(rig.translations, axis=0).max(axis=-1) > 0  # (J,) animated translations
    joints = [j for j in range(j_count) if not rig.is_end[j]]
    euler_column = {j: k for k, j in enumerate(joints)}
    fmt = f"%.{precision}f"
    columns: list[np.ndarray] = []
    euler = _matrices_to_euler(rig.rotations[:, joints], order)  # (T, K, 3)

    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "\t" * depth
        off = np.zeros(3) if depth == 0 else rig.translations[0, j]
        if rig.is_end[j]:
            lines.extend([f"{pad}End Site", f"{pad}{{", f"{pad}\tOFFSET {_fmt3(off, fmt)}", f"{pad}}}"])
            return
        lines.extend([f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {rig.names[j]}", f"{pad}{{"])
        lines.append(f"{pad}\tOFFSET {_fmt3(off, fmt)}")
        chans = [f"{a}rotation" for a in order]
        if depth == 0 or moving[j]:
            chans = ["Xposition", "Yposition", "Zposition"] + chans
            columns.append(rig.translations[:, j])
        columns.append(euler[:, euler_column[j]])
        lines.append(f"{pad}\tCHANNELS {len(chans)} {' '.join(chans)}")
        for k in kids[j]:
            emit(k, depth + 1)
        if not kids[j]:
            end = np.asarray(end_offsets.get(rig.names[j], 0.5 * off), dtype=np.float64)
            lines.extend(
                [f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {_fmt3(end, fmt)}", f"{pad}\t}}"]
            )
        lines.append(f"{pad}}}")

    emit(0, 0)
    lines.extend(["MOTION", f"Frames: {n}", f"Frame Time: {1.0 / fps:.8f}"])
    table = np.concatenate(columns, axis=1) if columns else np.zeros((n, 0))
    if not np.all(np.isfinite(table)):
        raise MotionFormatError(f"{path}: refusing to write NaN or infinite values")

    def write(f: object) -> None:
        f.write("\n".join(lines) + "\n")  # type: ignore[attr-defined]
        np.savetxt(f, table, fmt=fmt, delimiter=" ")

    write_atomic(path, write, mode="w")


def _fmt3(v: np.ndarray, fmt: str) -> str:
    return " ".join(fmt % x for x in v)


def _matrices_to_euler(rot: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles in degrees (..., 3) from (T, K, 3, 3), unwrapped over time (axis 0)."""
    with warnings.catch_warnings():  # gimbal lock: scipy still returns an exact decomposition
        warnings.simplefilter("ignore", UserWarning)
        angles = Rotation.from_matrix(rot).as_euler(order, degrees=True)
    return np.unwrap(angles, period=360.0, axis=0)
