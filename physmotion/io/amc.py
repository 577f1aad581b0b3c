"""Acclaim ASF/AMC reader (CMU motion capture), into the generic :class:`~physmotion.io.rigs.RigMotion`.

Hand-written: no maintained Python library reads ASF/AMC, and we need CMU's exact conventions plus
one-line errors. The forward kinematics convention follows CalciferZh's AMCParser
(github.com/CalciferZh/AMCParser, ``amc_parser.py``: ``Joint.set_motion``) and the Acclaim format
notes it links (research.cs.wisc.edu/graphics/Courses/cs-838-1999/Jeff/ASF-AMC.html), read for
reference, not copied; ``tests/io/test_amc.py`` re-derives it independently with scipy:

* ``axis a b c ORDER`` gives C, the bone's local frame in world axes at rest; a frame's dof angles
  give M; the bone's rotation relative to its parent is ``L = C @ M @ C^-1`` (C and M composed in
  the axis order, ``XYZ`` -> ``Rz @ Ry @ Rx``: rotations about fixed axes X, then Y, then Z).
* bone b ends at ``start_b + G_b @ (direction_b * length_b)``, directions in world axes at rest,
  ``G_b = G_parent @ L_b``; the root's children start at the root.

Rig layout: one node per bone at the bone's START (so node positions are joint positions: ``lfemur``
is the hip joint, ``ltibia`` the knee), a ``root`` node, and an end node ``<bone>_end`` at the end of
each leaf bone. A node's offset is its parent bone's ``direction * length``; its rotation is its own
bone's ``L``, so one FK (:meth:`RigMotion.forward_kinematics`) serves ASF and BVH.
Units: ``:units length x`` means 1 unit = 1/x inch (CMU: x = 0.45, 1 unit = 5.644 cm); the AMC root
translation is absolute (the ASF root ``position``, 0 in CMU's files, is not added); angles in
degrees unless ``angle rad``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from physmotion.errors import MotionFormatError
from physmotion.io.bvh import read_text
from physmotion.io.rigs import METRES_PER_INCH, RigMotion, euler_to_matrix


@dataclass
class Bone:
    """One ASF bone: rest direction (world axes) and length, axis angles and order, dof names."""

    name: str
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    length: float = 0.0
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    order: str = "XYZ"  # the axis / rotation order
    dofs: tuple[str, ...] = ()  # e.g. ("rx", "rz"): the order of values in the AMC
    parent: str = ""


@dataclass
class Skeleton:
    """A parsed ASF: bones by name in parent-first order, units, angle unit."""

    bones: dict[str, Bone]
    metres_per_unit: float
    degrees: bool


def read_asf(path: str | Path) -> Skeleton:
    """Parse an ASF skeleton file."""
    text = read_text(path, "ASF")
    where = str(path)
    sections = _sections(text)
    if ":bonedata" not in sections or ":hierarchy" not in sections:
        raise MotionFormatError(f"{where}: not an ASF file (no :bonedata or :hierarchy section)")
    length_scale, degrees = 1.0, True
    for line in sections.get(":units", []):
        words = line.split()
        if len(words) >= 2 and words[0] == "length":
            length_scale = _float(words[1], where)
            if length_scale <= 0:
                raise MotionFormatError(f"{where}: ASF ':units length' must be positive, got {words[1][:40]}")
        elif len(words) >= 2 and words[0] == "angle":
            degrees = words[1].lower().startswith("deg")
    root = Bone("root", dofs=("tx", "ty", "tz", "rx", "ry", "rz"))
    for line in sections.get(":root", []):
        words = line.split()
        if words[0] == "order":
            root.dofs = tuple(w.lower() for w in words[1:])
            bad = [d for d in root.dofs if d not in _ROOT_DOFS]
            if bad or len(set(root.dofs)) != len(root.dofs):
                listed = " ".join(words[1:7])[:60]
                raise MotionFormatError(f"{where}: ASF root order must list distinct TX..RZ, got {listed!r}")
        elif words[0] == "axis" and len(words) == 2:
            root.order = _order(words[1], where, "root")
        elif words[0] == "orientation":
            root.axis = _vector(words, where, "root orientation")
    count = sum(line.split(maxsplit=1)[0] == "begin" for line in sections[":bonedata"])
    if count > _MAX_BONES:
        raise MotionFormatError(
            f"{where}: ASF file defines {count} bones; at most {_MAX_BONES} are read (CMU's skeletons have 30)"
        )
    bones = {"root": root}
    bone: Bone | None = None
    for line in sections[":bonedata"]:
        words = line.split()
        key = words[0]
        if key == "begin":
            bone = Bone("")
        elif bone is None:
            continue
        elif key == "end":
            if not bone.name:
                raise MotionFormatError(f"{where}: ASF bone without a name")
            if bone.name in bones:
                raise MotionFormatError(f"{where}: ASF bone {bone.name[:40]!r} is defined twice")
            bones[bone.name] = bone
            bone = None
        elif key == "name":
            bone.name = words[1] if len(words) > 1 else ""
        elif key == "direction":
            bone.direction = _vector(words, where, f"bone {bone.name} direction")
        elif key == "length":
            bone.length = _float(words[1] if len(words) > 1 else "", where)
        elif key == "axis":
            bone.axis = _vector(words, where, f"bone {bone.name} axis")
            bone.order = _order(words[4], where, bone.name) if len(words) > 4 else "XYZ"
        elif key == "dof":
            bone.dofs = tuple(w.lower() for w in words[1:])
            if any(d not in ("rx", "ry", "rz") for d in bone.dofs):
                raise MotionFormatError(
                    f"{where}: bone {bone.name}: only rotation dofs are supported, got {bone.dofs[:6]}"
                )
    children: dict[str, list[str]] = {}
    for line in sections[":hierarchy"]:
        words = line.split()
        if words[0] in ("begin", "end"):
            continue
        for child in words[1:]:
            if child not in bones or words[0] not in bones:
                raise MotionFormatError(
                    f"{where}: ASF hierarchy names an unknown bone ({words[0][:40]} -> {child[:40]})"
                )
            if bones[child].parent or child == "root":
                raise MotionFormatError(
                    f"{where}: ASF bone {child[:40]!r} has more than one parent (or is the root)"
                )
            bones[child].parent = words[0]
            children.setdefault(words[0], []).append(child)
    ordered = _parents_first(children, where)
    reached = set(ordered)
    missing = [b for b in bones if b not in reached]
    if missing:
        raise MotionFormatError(
            f"{where}: ASF bones not connected to the root (missing from the hierarchy, or in a cycle): "
            f"{', '.join(m[:40] for m in missing[:5])}"
        )
    return Skeleton({b: bones[b] for b in ordered}, METRES_PER_INCH / length_scale, degrees)


_ROOT_DOFS = ("tx", "ty", "tz", "rx", "ry", "rz")
# A body's skeleton has tens of bones; past this the file is not one, and parsing it would take seconds.
_MAX_BONES = 1000


def _vector(words: list[str], where: str, what: str) -> np.ndarray:
    """The three numbers after a keyword (``direction 0 1 0``)."""
    if len(words) < 4:
        raise MotionFormatError(f"{where}: ASF {what} needs three numbers, got {' '.join(words[1:])[:40]!r}")
    return np.array([_float(w, where) for w in words[1:4]])


def _order(word: str, where: str, bone: str) -> str:
    """A rotation order: a permutation of XYZ."""
    if sorted(word.upper()) != ["X", "Y", "Z"]:
        raise MotionFormatError(
            f"{where}: bone {bone[:40]}: axis order must be a permutation of XYZ, got {word[:40]!r}"
        )
    return word.upper()


def _sections(text: str) -> dict[str, list[str]]:
    """Non-empty, non-comment lines grouped under their ``:keyword`` (keyword's own line tail first)."""
    out: dict[str, list[str]] = {}
    current: list[str] = []
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith(":"):
            key, _, rest = line.partition(" ")
            current = out.setdefault(key.lower(), [])
            if rest.strip():
                current.append(rest.strip())
        else:
            current.append(line)
    return out


def _parents_first(children: dict[str, list[str]], where: str) -> list[str]:
    """Bones reachable from the root, parents before children (breadth first: linear, no recursion).

    Each bone has one parent (checked by the caller), so a bone in a cycle is never reached.
    """
    out = ["root"]
    for bone in out:  # the list grows while it is walked
        out.extend(children.get(bone, ()))
    return out


def _float(word: str, where: str) -> float:
    try:
        value = float(word)
    except ValueError:
        raise MotionFormatError(f"{where}: expected a number, got {word[:40]!r}") from None
    if not np.isfinite(value):
        raise MotionFormatError(f"{where}: NaN or infinite number {word[:40]!r} in the ASF file")
    return value


def read_amc(path: str | Path, skeleton: Skeleton | str | Path, keep: set[str] | None = None) -> RigMotion:
    """Read an AMC motion on its ASF skeleton (a path or a parsed :class:`Skeleton`).

    Returns a RigMotion in ASF units (``units`` set from ``:units length``), fps None.
    keep: node names needed (bones, or ``<bone>_end``); only they and their ancestors are built.
    None: every node.
    """
    skel = skeleton if isinstance(skeleton, Skeleton) else read_asf(skeleton)
    where = str(path)
    values = _parse_amc(read_text(path, "AMC"), skel, where)
    return _to_rig(skel, values, where, keep)


_NAME = re.compile(r"^[ \t]*([A-Za-z_][^ \t\r\n]*)", re.MULTILINE)  # a bone name opening a line
_FRAME = re.compile(r"^[ \t]*\d+[ \t]*\r?$", re.MULTILINE)  # a frame-number line


def _parse_amc(text: str, skel: Skeleton, where: str) -> dict[str, np.ndarray]:
    """Per bone, its values (T, len(dofs)).

    Fast path (every CMU file): each frame lists the same bones in the same order, so all numbers
    parse in one numpy call and are sliced per bone. Otherwise frame by frame.
    """
    first = _FRAME.search(text)
    header = text[: first.start()] if first else text
    if any(ln.strip() and ln.strip()[0] not in "#:" for ln in header.splitlines()):
        raise MotionFormatError(f"{where}: not an AMC file (text before the first frame number)")
    if first is None:
        raise MotionFormatError(f"{where}: the AMC file has zero frames")
    body = text[first.start() :]
    n_frames = len(_FRAME.findall(body))
    names = _NAME.findall(body)
    period = len(names) // n_frames
    if period == 0 or names != names[:period] * n_frames:
        return _parse_amc_slow(body.splitlines(), skel, where)
    for name in names[:period]:
        if name not in skel.bones:
            raise MotionFormatError(f"{where}: AMC names bone {name[:40]!r}, which its ASF does not define")
    widths = [len(skel.bones[n].dofs) for n in names[:period]]
    try:  # C-speed text parse of every number, frame numbers included
        numbers = np.fromstring(_NAME.sub("", body), sep=" ")
    except ValueError:
        raise MotionFormatError(f"{where}: non-numeric text in the AMC file") from None
    if numbers.size != n_frames * (1 + sum(widths)):
        return _parse_amc_slow(body.splitlines(), skel, where)
    table = numbers.reshape(n_frames, 1 + sum(widths))
    if not np.all(np.isfinite(table)):
        raise MotionFormatError(f"{where}: NaN or infinite values in the AMC file")
    bounds = np.cumsum([1] + widths)
    return {n: table[:, bounds[k] : bounds[k + 1]] for k, n in enumerate(names[:period])}


def _parse_amc_slow(lines: list[str], skel: Skeleton, where: str) -> dict[str, np.ndarray]:
    """Frame by frame, for files whose frames list their bones in different orders."""
    frames: list[dict[str, list[str]]] = []
    for ln in (raw.strip() for raw in lines):
        if not ln:
            continue
        if ln.isdigit():
            frames.append({})
            continue
        name, *vals = ln.split()
        if not frames:
            raise MotionFormatError(f"{where}: not an AMC file (bone values before the first frame number)")
        if name not in skel.bones:
            raise MotionFormatError(f"{where}: AMC names bone {name[:40]!r}, which its ASF does not define")
        if len(vals) != len(skel.bones[name].dofs):
            declared = len(skel.bones[name].dofs)
            raise MotionFormatError(
                f"{where}: truncated or malformed AMC: frame {len(frames)} bone {name} has "
                f"{len(vals)} values, its ASF declares {declared}"
            )
        frames[-1][name] = vals
    names = set().union(*frames) if frames else set()
    for k, frame in enumerate(frames, start=1):
        if set(frame) != names:  # AMC files are :FULLY-SPECIFIED: every frame lists every bone
            what = "truncated AMC: the last frame" if k == len(frames) else f"malformed AMC: frame {k}"
            raise MotionFormatError(
                f"{where}: {what} lacks bone(s) {', '.join(sorted(names - set(frame))[:4])}"
            )
    out: dict[str, np.ndarray] = {}
    for name in names:
        rows = [f[name] for f in frames]
        out[name] = _numbers(
            np.array(rows, dtype=str).reshape(len(frames), len(skel.bones[name].dofs)), where
        )
    return out


def _numbers(words: np.ndarray, where: str) -> np.ndarray:
    """Float array from an array of number strings, or a one-line MotionFormatError."""
    try:
        arr = words.astype(np.float64)
    except ValueError as exc:
        raise MotionFormatError(f"{where}: non-numeric value in the AMC file ({str(exc)[:80]})") from None
    if not np.all(np.isfinite(arr)):
        raise MotionFormatError(f"{where}: NaN or infinite values in the AMC file")
    return arr


def _kept_bones(skel: Skeleton, keep: set[str] | None) -> set[str]:
    """The bones whose nodes ``keep`` names, and their ancestors (every bone for None)."""
    if keep is None:
        return set(skel.bones)
    out: set[str] = set()
    for name in keep:
        bone = name if name in skel.bones else name.removesuffix("_end")
        while bone in skel.bones and bone not in out:
            out.add(bone)
            bone = skel.bones[bone].parent
    out.add("root")
    return out


def _to_rig(
    skel: Skeleton, values: dict[str, np.ndarray], where: str, keep: set[str] | None = None
) -> RigMotion:
    n = next(iter(values.values())).shape[0] if values else 0
    if n == 0:
        raise MotionFormatError(f"{where}: the AMC file has zero frames")
    kept = _kept_bones(skel, keep)
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    local: list[np.ndarray] = []
    is_end: list[bool] = []
    node_of: dict[str, int] = {}
    identity = np.broadcast_to(np.eye(3), (n, 3, 3))
    has_child = {b.parent for b in skel.bones.values()}
    for bone in skel.bones.values():
        if bone.name not in kept:
            continue
        parent_bone = skel.bones.get(bone.parent)
        node_of[bone.name] = len(names)
        names.append(bone.name)
        parents.append(node_of[bone.parent] if parent_bone else -1)
        offsets.append(parent_bone.direction * parent_bone.length if parent_bone else np.zeros(3))
        local.append(_bone_rotation(bone, values.get(bone.name), n, skel.degrees))
        is_end.append(False)
        if bone.name not in has_child and bone.length > 0:
            names.append(f"{bone.name}_end")
            parents.append(node_of[bone.name])
            offsets.append(bone.direction * bone.length)
            local.append(identity)
            is_end.append(True)
    translations = np.broadcast_to(np.array(offsets), (n, len(names), 3)).copy()
    root = skel.bones["root"]
    root_vals = values.get("root", np.zeros((n, len(root.dofs))))
    for k, dof in enumerate(root.dofs):
        if dof.startswith("t"):
            translations[:, 0, "xyz".index(dof[1])] = root_vals[:, k]
    return RigMotion(
        names=tuple(names),
        parents=np.array(parents),
        rotations=np.stack(local, axis=1),
        translations=translations,
        fps=None,
        units=skel.metres_per_unit,
        is_end=tuple(is_end),
    )


def _bone_rotation(bone: Bone, vals: np.ndarray | None, n: int, degrees: bool) -> np.ndarray:
    """L = C @ M @ C^-1 per frame, (T, 3, 3); M from the bone's rotation dofs in its axis order."""
    # ASF order "XYZ" rotates about fixed X, then Y, then Z: R = Rz @ Ry @ Rx, i.e. the matrix
    # product in the reversed order, which is how euler_to_matrix reads its axes.
    if vals is None or not any(d.startswith("r") for d in bone.dofs):
        return np.broadcast_to(np.eye(3), (n, 3, 3))  # C @ I @ C^-1: no need to build C
    seq = bone.order.upper()
    c = euler_to_matrix(bone.axis[::-1], seq[::-1], degrees)
    angles = np.zeros((n, 3))
    if vals is not None:
        for k, dof in enumerate(bone.dofs):
            if dof.startswith("r"):
                angles[:, seq.index(dof[1].upper())] = vals[:, k]
    m = euler_to_matrix(angles[:, ::-1], seq[::-1], degrees)
    return c @ m @ c.T
