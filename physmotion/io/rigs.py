"""Rigs: the generic tree every reader produces, and per-rig tables mapping a rig onto the 22 SMPL joints.

Every file format is read into a :class:`RigMotion`, a tree of nodes with local rotations and local
translations per frame, so one forward kinematics serves BVH, ASF/AMC and any later format. A
:class:`RigTable` then says, as data, which rig point each SMPL joint is, plus the rig's units and
up axis. Tables for the conventions of ``shared/data/mocap`` are in :data:`RIGS`; a user's own rig
is a plain ``dict`` of SMPL joint name -> rig joint name, see :func:`table_from_mapping`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.skeleton import JOINT_NAMES

# ------------------------------------------------------------------------------------------------
# The generic tree


@dataclass
class RigMotion:
    """A motion on any tree-shaped rig, in the file's own units and axes.

    names: (J,) node names; parents: (J,) int, ``parents[j] < j``, -1 for the root (node 0).
    rotations: (T, J, 3, 3) local rotations; ``G[j] = G[parents[j]] @ rotations[:, j]``.
    translations: (T, J, 3) local translations in the parent's frame (the OFFSET, or a channel value
    where the file animates it); the root's entry is its world position.
    fps: the rate the file claims (BVH header), or None (AMC has none).
    units: metres per file unit where the file says (ASF ``:units length``), else None.
    is_end: (J,) True for end points with no rotation of their own (BVH End Site, ASF bone ends).
    """

    names: tuple[str, ...]
    parents: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    fps: float | None = None
    units: float | None = None
    is_end: tuple[bool, ...] = ()

    def __post_init__(self) -> None:
        if not self.is_end:
            self.is_end = (False,) * len(self.names)

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    def index(self, name: str) -> int:
        """Index of node ``name``; KeyError if the rig has none."""
        return self.names.index(name)

    def forward_kinematics(self) -> np.ndarray:
        """World positions of every node, (T, J, 3), in the rig's units and axes."""
        n, j_count = self.rotations.shape[:2]
        glob = np.empty((n, j_count, 3, 3))
        pos = np.empty((n, j_count, 3))
        for j, p in enumerate(self.parents):
            if p < 0:
                glob[:, j] = self.rotations[:, j]
                pos[:, j] = self.translations[:, j]
            else:
                glob[:, j] = glob[:, p] @ self.rotations[:, j]
                pos[:, j] = pos[:, p] + (glob[:, p] @ self.translations[:, j, :, None])[..., 0]
        return pos

    def subset(self, keep: set[str]) -> RigMotion:
        """The rig pruned to the nodes in ``keep`` and their ancestors (FK and resampling get cheaper)."""
        old = closure(self.names, self.parents, keep)
        return replace(
            self,
            names=tuple(self.names[j] for j in old),
            parents=remap_parents(self.parents, old),
            rotations=self.rotations[:, old],
            translations=self.translations[:, old],
            is_end=tuple(self.is_end[j] for j in old),
        )

    def frames(self, index: slice | np.ndarray) -> RigMotion:
        """The same rig with only some frames."""
        return replace(self, rotations=self.rotations[index], translations=self.translations[index])


def closure(
    names: tuple[str, ...] | list[str], parents: np.ndarray | list[int], keep: set[str]
) -> np.ndarray:
    """Sorted indices of the nodes named in ``keep`` (unknown names ignored) and all their ancestors."""
    wanted = np.zeros(len(names), dtype=bool)
    for j, name in enumerate(names):
        if name in keep:
            while j >= 0 and not wanted[j]:
                wanted[j] = True
                j = int(parents[j])
    return np.flatnonzero(wanted)


def remap_parents(parents: np.ndarray | list[int], kept: np.ndarray) -> np.ndarray:
    """Parent indices within ``kept`` (a sorted, ancestor-closed index set)."""
    new_of_old = -np.ones(len(parents), dtype=int)
    new_of_old[kept] = np.arange(len(kept))
    return np.array([new_of_old[parents[j]] if parents[j] >= 0 else -1 for j in kept], dtype=int)


def euler_to_matrix(angles: np.ndarray, axes: str, degrees: bool = True) -> np.ndarray:
    """Rotation matrices ``R_axes[0](a0) @ R_axes[1](a1) @ ...`` (BVH channel order), (..., 3, 3).

    angles: (..., len(axes)). Written in numpy because scipy's ``from_euler`` costs more than the
    whole BVH parse on our files; scipy is used to test it.
    """
    rad = np.radians(angles) if degrees else np.asarray(angles, dtype=np.float64)
    out = np.broadcast_to(np.eye(3), rad.shape[:-1] + (3, 3))
    for k, axis in enumerate(axes.upper()):
        i = "XYZ".index(axis)
        a, b = (i + 1) % 3, (i + 2) % 3
        c, s = np.cos(rad[..., k]), np.sin(rad[..., k])
        r = np.zeros(rad.shape[:-1] + (3, 3))
        r[..., i, i] = 1.0
        r[..., a, a], r[..., a, b], r[..., b, a], r[..., b, b] = c, -s, s, c
        out = out @ r
    return out


# ------------------------------------------------------------------------------------------------
# Per-rig tables: data, not code

JointSource = str | tuple[tuple[str, float], ...]
"""Where an SMPL joint sits on a rig: a rig node's name, or a weighted blend of rig nodes
(weights >= 0 summing to 1), e.g. ``(("Spine", 0.5), ("Chest", 0.5))``. Blend two nodes of one
rigid bone (a node and its child) so the point stays fixed on that bone and bone lengths stay
constant."""

UP_AXES = ("X", "Y", "Z")


@dataclass(frozen=True)
class RigTable:
    """How one rig convention maps onto the 22 SMPL joints, with its units and up axis.

    joints: SMPL joint name -> :data:`JointSource`, for all 22 joints.
    units: metres per file unit, or None to take it from the file (an ASF's ``:units length``).
    up_axis: the world up axis of the file's *animated* frames ("X", "Y" or "Z"), or None to take
    it from the manifest or the caller (default Y).
    source: where the convention comes from (a few words, for ``physmotion import --rig list``).
    placed: the rig's files are already in the project's placement (our own export: metres, Y up, on
    the floor y = 0), so an import keeps their position and facing instead of placing and grounding
    them again: an export -> import round trip then returns the motion where it was.
    """

    name: str
    joints: Mapping[str, JointSource]
    units: float | None
    up_axis: str | None = "Y"
    note: str = ""
    source: str = ""
    placed: bool = False

    def __post_init__(self) -> None:
        missing = [j for j in JOINT_NAMES if j not in self.joints]
        extra = [j for j in self.joints if j not in JOINT_NAMES]
        if missing or extra:
            raise PhysmotionError(
                f"rig table {self.name!r}: mapping must name exactly the 22 SMPL joints "
                f"(missing {missing[:4]}, unknown {extra[:4]})"
            )
        for joint, src in self.joints.items():
            weights = [w for _, w in _blend(src)]
            if min(weights) < 0 or abs(sum(weights) - 1.0) > 1e-6:
                raise PhysmotionError(
                    f"rig table {self.name!r}: weights of {joint} must be >= 0 and sum to 1"
                )
        if self.up_axis is not None and self.up_axis not in UP_AXES:
            raise PhysmotionError(
                f"rig table {self.name!r}: up axis must be one of {UP_AXES}, got {self.up_axis!r}"
            )
        if self.units is not None and not (np.isfinite(self.units) and self.units > 0):
            raise PhysmotionError(f"rig table {self.name!r}: units must be a positive number of metres")
        object.__setattr__(self, "joints", MappingProxyType(dict(self.joints)))

    def nodes(self) -> set[str]:
        """Every rig node the table uses."""
        return {node for src in self.joints.values() for node, _ in _blend(src)}

    def weights(self, names: tuple[str, ...]) -> np.ndarray:
        """(22, J) matrix W with SMPL joints = W @ rig node positions, for a rig with these node names."""
        index = {n: i for i, n in enumerate(names)}
        missing = sorted(self.nodes() - set(index))
        if missing:
            listed = ", ".join(missing[:5])
            raise PhysmotionError(f"rig {self.name!r} does not fit this file: it has no joint(s) {listed}")
        w = np.zeros((len(JOINT_NAMES), len(names)))
        for j, joint in enumerate(JOINT_NAMES):
            for node, weight in _blend(self.joints[joint]):
                w[j, index[node]] += weight
        return w


def _blend(src: JointSource) -> tuple[tuple[str, float], ...]:
    return ((src, 1.0),) if isinstance(src, str) else tuple((str(n), float(w)) for n, w in src)


def _sided(table: dict[str, JointSource], left: str, right: str) -> dict[str, JointSource]:
    """Complete a table written for the left side (``{L}`` in names) with both sides."""
    out: dict[str, JointSource] = {}
    for joint, src in table.items():
        if "{L}" not in str(src):
            out[joint] = src
            continue
        for side, tag in (("left", left), ("right", right)):
            if isinstance(src, str):
                out[f"{side}_{joint}"] = src.replace("{L}", tag)
            else:
                out[f"{side}_{joint}"] = tuple((n.replace("{L}", tag), w) for n, w in src)
    return out


def table_from_mapping(
    mapping: Mapping[str, JointSource],
    *,
    name: str = "custom",
    units: float | None = None,
    up_axis: str | None = None,
) -> RigTable:
    """A RigTable for a user's own rig from a dict of SMPL joint name -> rig joint (or blend)."""
    return RigTable(name=name, joints=dict(mapping), units=units, up_axis=up_axis)


METRES_PER_INCH = 0.0254
_CM = 0.01
_CMU_UNIT = METRES_PER_INCH / 0.45  # CMU's ASF length unit: 1/0.45 inch = 5.644 cm

# Choices shared by every table (why the blends are where they are):
# - SMPL's pelvis sits ~9 cm above the hip joints; rigs whose root node is at hip height (Bandai,
#   iClone) use a point fixed on the root's frame higher up.
# - collar: near the sternoclavicular joint, ~5 cm from the midline. CMU clavicles start on the
#   midline, so the collar is a quarter of the way along the clavicle (iClone's own clavicle joint
#   sits 5.6 cm out, which this matches).
# - head: the rig's head joint, where the head turns on the neck, as SMPL's (8 cm from its neck
#   joint, about the middle of the head's height; CMU's head bone runs 9 cm further up). A point
#   higher up would sit on another rig bone than the neck joint, so its distance to it would vary.
#   neck: the base of the neck, a few cm above the shoulder joints as in SMPL.
# - every SMPL bone joins two points fixed in one rig frame (a node and its child, or points on one
#   bone), so its length is constant over time; the exceptions are said where they are. What the
#   22-joint tree cannot hold rigid is fitted in canonical.py.
_BANDAI = {
    "pelvis": (("Hips", 0.7), ("Spine", 0.3)),  # Hips is at hip-joint height
    "hip": "UpperLeg_{L}", "knee": "LowerLeg_{L}", "ankle": "Foot_{L}", "foot": "Toes_{L}",
    "spine1": "Spine",
    "spine2": (("Spine", 0.5), ("Chest", 0.5)),
    "spine3": "Chest",
    "neck": "Neck", "head": "Head",
    "collar": "Shoulder_{L}", "shoulder": "UpperArm_{L}", "elbow": "LowerArm_{L}", "wrist": "Hand_{L}",
}  # fmt: skip

_CGSPEED = {  # CMU's skeleton without the thorax bone: collars and lower neck start at Chest2
    "pelvis": "Hips",
    "hip": "{L}Hip", "knee": "{L}Knee", "ankle": "{L}Ankle", "foot": "{L}Toe",
    "spine1": "Chest",
    "spine2": (("Chest", 0.5), ("Chest2", 0.5)),
    "spine3": "Chest2",
    "neck": "Neck", "head": "Head",
    "collar": (("{L}Collar", 0.75), ("{L}Shoulder", 0.25)),
    "shoulder": "{L}Shoulder", "elbow": "{L}Elbow", "wrist": "{L}Wrist",
}  # fmt: skip

_CMU_ASF = {  # nodes sit at bone starts: "lfemur" is the hip joint, "lhumerus" the shoulder
    "pelvis": "root",
    "hip": "{L}femur", "knee": "{L}tibia", "ankle": "{L}foot", "foot": "{L}toes",
    "spine1": "upperback", "spine2": "thorax",
    "spine3": "lowerneck",  # thorax end: the clavicles start here too, so spine3 -> collar is rigid
    "neck": "upperneck", "head": "head",
    "collar": (("{L}clavicle", 0.75), ("{L}humerus", 0.25)),
    # the wrist joint is where the hand bone starts: CMU's "lwrist" bone is the distal forearm
    # (its only dof twists about its own axis), so lradius -> lhand is one rigid segment
    "shoulder": "{L}humerus", "elbow": "{L}radius", "wrist": "{L}hand",
}  # fmt: skip

_ICLONE = {
    "pelvis": "CC_Base_Waist",  # CC_Base_Hip is at hip-joint height; Waist is ~10 cm above the thighs
    "hip": "CC_Base_{L}_Thigh", "knee": "CC_Base_{L}_Calf", "ankle": "CC_Base_{L}_Foot",
    "foot": "CC_Base_{L}_ToeBase",
    # CC_Base's spine joints sit lower than CMU's (Spine02 -> NeckTwist01 spans the whole chest);
    # these blends put spine1..3 at CMU's heights along the trunk, measured on the takes present in
    # both formats (cmu_02_*, cmu_03_*), so the two imports of one take agree. The price: Waist ->
    # spine1 and spine1 -> spine2 cross a rig joint, and head hangs off NeckTwist02, so those rig
    # distances vary by up to 2.7 mm (std) before the fit to the 22-joint body makes them constant.
    "spine1": (("CC_Base_Spine01", 0.5), ("CC_Base_Spine02", 0.5)),
    "spine2": (("CC_Base_Spine02", 0.81), ("CC_Base_NeckTwist01", 0.19)),
    "spine3": (("CC_Base_Spine02", 0.35), ("CC_Base_NeckTwist01", 0.65)),
    "neck": "CC_Base_NeckTwist01", "head": "CC_Base_Head",
    "collar": "CC_Base_{L}_Clavicle", "shoulder": "CC_Base_{L}_Upperarm",
    "elbow": "CC_Base_{L}_Forearm", "wrist": "CC_Base_{L}_Hand",
}  # fmt: skip

_MIXAMO = {  # Adobe Mixamo's rig: "mixamorig:Hips", or the same names without the prefix in many exports
    "pelvis": "Hips",  # Mixamo's Hips sits between and above the hip joints, as SMPL's pelvis
    "hip": "{L}UpLeg", "knee": "{L}Leg", "ankle": "{L}Foot", "foot": "{L}ToeBase",
    "spine1": "Spine", "spine2": "Spine1", "spine3": "Spine2",
    "neck": "Neck", "head": "Head",
    "collar": "{L}Shoulder", "shoulder": "{L}Arm", "elbow": "{L}ForeArm", "wrist": "{L}Hand",
}  # fmt: skip


def _prefixed(table: dict[str, JointSource], prefix: str) -> dict[str, JointSource]:
    """A table with ``prefix`` before every rig node name."""
    return {
        joint: prefix + src if isinstance(src, str) else tuple((prefix + n, w) for n, w in src)
        for joint, src in table.items()
    }


_SMPL22 = {name: name for name in JOINT_NAMES}

RIGS: Mapping[str, RigTable] = MappingProxyType(
    {
        t.name: t
        for t in (
            RigTable(
                "bandai", _sided(_BANDAI, "L", "R"), units=_CM, up_axis="Y",
                source="Bandai Namco Research Motiondataset BVH (Hips, UpperLeg_L, ...)",
            ),
            RigTable(
                "cmu_bvh_cgspeed_max", _sided(_CGSPEED, "Left", "Right"), units=_CMU_UNIT, up_axis="Y",
                source="CMU mocap, cgspeed's 3dsMax-friendly BVH (Hips, LeftHip, ...)",
            ),
            RigTable(
                "cmu_bvh_cgspeed_max_scaled_m", _sided(_CGSPEED, "Left", "Right"), units=1.0, up_axis="Y",
                source="the same CMU cgspeed BVH rescaled to metres (bvh11's scaled_*.bvh)",
            ),
            RigTable(
                "cmu_asf", _sided(_CMU_ASF, "l", "r"), units=None, up_axis="Y",
                source="CMU's original ASF/AMC (root, lfemur, ...)",
            ),
            RigTable(
                "cmu_iclone_cc_base",
                _sided(_ICLONE, "L", "R"),
                units=_CM,
                up_axis="Y",
                note="The rest pose is Z-up (CC_Base_Hip OFFSET 0 0 105), but the root's animated "
                "rotation turns every frame Y-up: the animated world is Y-up, which is what matters.",
                source="CMU mocap retargeted to iClone's CC_Base rig (CC_Base_Hip, ...)",
            ),
            RigTable(
                "mixamo", _prefixed(_sided(_MIXAMO, "Left", "Right"), "mixamorig:"), units=_CM, up_axis="Y",
                source="Adobe Mixamo rig (mixamorig:Hips, mixamorig:LeftUpLeg, ...); BVH exports in cm",
            ),
            RigTable(
                "mixamo_plain", _sided(_MIXAMO, "Left", "Right"), units=_CM, up_axis="Y",
                source="Mixamo's rig with the prefix stripped (Hips, LeftUpLeg, ...), as many exports write it",
            ),
            RigTable(
                "smpl22", _SMPL22, units=1.0, up_axis="Y", note="our own BVH export (physmotion.io.export)",
                source="physmotion's own BVH export (pelvis, left_hip, ...)", placed=True,
            ),
        )
    }
)
"""Tables by convention name (the manifest's ``skeleton`` column; ``cmu_asf`` for any CMU ASF)."""

_UNIT_NAMES = {1.0: "m", _CM: "cm", _CMU_UNIT: "CMU units (1/0.45 inch)"}


def describe_rig(table: RigTable) -> str:
    """One line about a rig table: its units, up axis and source."""
    if table.units is None:
        units = "units from the file"
    else:
        units = _UNIT_NAMES.get(table.units, f"{table.units:g} m per unit")
    up = f"{table.up_axis} up" if table.up_axis else "up axis from the file"
    return f"{units}, {up}; {table.source or table.note or 'custom'}"


def parse_units(text: str | float) -> float:
    """Metres per unit from a number or a name: "m", "cm", "mm", "inch", "1/0.45 inch" (CMU's ASF unit)."""
    if not isinstance(text, str):
        value = float(text)
    else:
        s = text.strip().lower()
        inch = METRES_PER_INCH
        named = {"m": 1.0, "metre": 1.0, "meter": 1.0, "cm": _CM, "mm": 0.001, "in": inch, "inch": inch}
        frac = re.search(r"1\s*/\s*([0-9.]+)\s*inch", s)
        if s in named:
            value = named[s]
        elif frac:
            value = METRES_PER_INCH / float(frac.group(1))
        else:
            try:
                value = float(s)
            except ValueError:
                hint = "use m, cm, mm, inch, '1/0.45 inch' or metres per unit"
                raise PhysmotionError(f"unknown units {text!r}: {hint}") from None
    if not (np.isfinite(value) and value > 0):
        raise PhysmotionError(f"units must be a positive number of metres per unit, got {text!r}")
    return value
