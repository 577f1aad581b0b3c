"""The MuJoCo humanoid: an MJCF built from the 22-joint skeleton and a body's rest offsets.

Layout (in the manner of PHC's SMPL humanoid, ZhengyiLuo/PHC ``phc/data/assets/mjcf/smpl_humanoid.xml``):

- one body per skeleton joint, named exactly as :data:`physmotion.skeleton.JOINT_NAMES`; a body's frame
  sits at its joint and carries the geometry of the bone(s) to its children (the bone into the wrist
  carries the hand, there is no separate hand body);
- a free joint on the pelvis and three hinges per other joint, named ``<joint>_x``, ``_y``, ``_z`` after
  their axis in the body frame (MuJoCo frame, see :mod:`physmotion.physics.frames`: x forward, y left,
  z up). The hinges of one body nest in the order ``HumanoidConfig.hinge_order[group]`` (the Euler
  sequence that :mod:`physmotion.physics.retarget` decomposes into): nq = 7 + 63, nv = 69. Limits per
  joint group (:func:`default_limits`), armature 0.01 (0.03 on ankles and toes, see HumanoidConfig);
- 63 position actuators (kp, kv, force range; gains per joint group, :func:`default_gains`), one per
  hinge, in qpos order: ``ctrl[i]`` is the target of ``qpos[7 + i]``;
- the rest pose (all hinges 0) is the skeleton's T-pose; body frames are aligned with the world there,
  so a hinge angle is a local joint rotation of :mod:`physmotion.skeleton` in Euler form;
- feet: an ankle box with a heel behind the ankle and a toe box on the foot body, both soles flat at
  rest (``standing_height`` puts them on the floor);
- mass: de Leva's segment fractions of ``total_mass`` (70 kg by default), each body's density chosen
  to give its segment mass: limbs come out at 650-1100 kg/m^3 (human tissue ~1000-1100), pelvis,
  trunk and thighs at 2100-3000 because PHC's primitives are thinner than a torso or thigh (PHC's own
  densities there are 2000-4600);
- the floor plane, ``<option>`` from :class:`HumanoidConfig` (implicitfast, Newton, 50 iterations, dt 1/120),
  contact excludes between neighbouring torso/hip bodies (:data:`DEFAULT_EXCLUDES`).

Positions in this module are built in our Y-up frame and converted once, at the MJCF boundary.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field

import numpy as np

from physmotion.conventions import FPS
from physmotion.errors import ShapeError
from physmotion.physics.frames import to_mujoco
from physmotion.skeleton import (
    JOINT_INDEX,
    JOINT_NAMES,
    NUM_JOINTS,
    REST_OFFSETS,
    check_bone_lengths,
    children,
    offsets_from_joints,
)

AXES = "xyz"

JOINT_GROUP: dict[str, str] = {
    "left_hip": "hip", "right_hip": "hip", "left_knee": "knee", "right_knee": "knee",
    "left_ankle": "ankle", "right_ankle": "ankle", "left_foot": "foot", "right_foot": "foot",
    "spine1": "spine", "spine2": "spine", "spine3": "spine", "neck": "neck", "head": "head",
    "left_collar": "collar", "right_collar": "collar", "left_shoulder": "shoulder",
    "right_shoulder": "shoulder", "left_elbow": "elbow", "right_elbow": "elbow",
    "left_wrist": "wrist", "right_wrist": "wrist",
}  # fmt: skip
"""The group of each hinged joint: gains, limits and hinge order are given per group."""


@dataclass(frozen=True)
class PDGain:
    """Position-actuator gains of one hinge: torque = clip(kp (target - q) - kv qdot, +-torque_limit)."""

    kp: float  # N m / rad
    kv: float  # N m s / rad
    torque_limit: float  # N m


def default_gains() -> dict[str, PDGain]:
    """Gains per joint group.

    Stiffer than PHC/SMPLSim's SMPL humanoid gains (hip/knee/spine kp 250-500, ankle 150-300, toe ~100),
    under which this body falls forward in ~2 s under a PD hold: gravity's toppling stiffness m g h
    (~620 N m/rad) beats the ankles' (docs/decisions/projection.md: "PD gains stiffer than PHC's").
    kv = kp / 10 throughout. Torque limits: half a radian of error for the legs and spine (the ankle's
    1000 N m is far above a human's ~200 N m: it keeps the PD-only body upright, a balance controller should
    lower it), one radian for the upper body.
    """
    return {
        "hip": PDGain(1000.0, 100.0, 500.0),
        "knee": PDGain(1000.0, 100.0, 500.0),
        "spine": PDGain(1000.0, 100.0, 500.0),
        "ankle": PDGain(1500.0, 150.0, 1000.0),
        "foot": PDGain(1000.0, 100.0, 500.0),
        "neck": PDGain(200.0, 20.0, 200.0),
        "head": PDGain(100.0, 10.0, 100.0),
        "collar": PDGain(200.0, 20.0, 200.0),
        "shoulder": PDGain(200.0, 20.0, 200.0),
        "elbow": PDGain(150.0, 15.0, 150.0),
        "wrist": PDGain(50.0, 5.0, 50.0),
    }


Range = tuple[float, float]


def default_limits() -> dict[str, tuple[Range, Range, Range]]:
    """Hinge ranges in degrees per group, (x, y, z) about the MuJoCo body axes, for the LEFT side.

    Right-side joints are mirrored (x and z ranges negated and swapped, y kept). Signs, from the T-pose:
    +x moves a left limb's distal end to the left (hip abduction; arm up), +y swings a hanging bone
    backwards (hip extension, knee flexion, ankle plantarflexion) and an upright one forwards (spine
    flexion, nodding), +z turns a left limb backwards about the vertical (left arm back, left elbow
    extension; left toes out).
    Start: anatomical ranges (AAOS-style; SMPLSim's upright limits, ZhengyiLuo/SMPLSim
    smpl_sim/smpllib/smpl_local_robot.py, for the knee and elbow signs). Widened to cover the angles
    that retargeting produces on real mocap (Bandai, 300 clips, 35k frames at 20 fps): a limit the
    reference itself breaks makes the simulation fight the motion. What forced the widening: the
    neck's y (-112..-7 deg on Bandai: its head joint sits straight above the neck, while the rest body
    takes SMPL's forward-up head direction), spine y up to 80 deg per joint in deep bows, ankle y up
    to 101 deg (the toe joint's placement differs from SMPL's), elbow x/y (the part of the upper-arm
    twist that retargeting leaves in the elbow, see retarget._LIMBS). Leaf joints (foot, head, wrist)
    stay 0 in retargeted motion; their ranges are anatomical.
    """
    return {
        "hip": ((-45.0, 75.0), (-140.0, 45.0), (-70.0, 70.0)),
        "knee": ((-20.0, 20.0), (-20.0, 165.0), (-20.0, 20.0)),
        "ankle": ((-45.0, 45.0), (-60.0, 110.0), (-70.0, 70.0)),
        "foot": ((-30.0, 30.0), (-60.0, 60.0), (-30.0, 30.0)),
        "spine": ((-45.0, 45.0), (-50.0, 90.0), (-45.0, 45.0)),
        "neck": ((-50.0, 50.0), (-120.0, 70.0), (-70.0, 70.0)),
        "head": ((-50.0, 50.0), (-60.0, 70.0), (-70.0, 70.0)),
        "collar": ((-50.0, 50.0), (-30.0, 30.0), (-50.0, 50.0)),
        "shoulder": ((-120.0, 120.0), (-90.0, 90.0), (-150.0, 110.0)),
        "elbow": ((-90.0, 160.0), (-90.0, 90.0), (-170.0, 90.0)),
        "wrist": ((-80.0, 80.0), (-80.0, 80.0), (-90.0, 90.0)),
    }


def default_hinge_order() -> dict[str, str]:
    """Nesting order of the three hinges per group (= the intrinsic Euler sequence, outermost first).

    The middle axis gimbal-locks at +-90 degrees, so it must be an axis of small range: per group, the
    order whose middle angle stays smallest on retargeted real mocap (docs/decisions/projection.md: "hinge
    orders by the largest middle angle"). Leaf joints (foot, head, wrist) have no child: IK leaves them at 0,
    they follow their parent.
    """
    legs = "yzx"
    trunk = "yxz"
    arms = "zyx"
    return {
        "hip": legs, "knee": legs, "ankle": trunk, "foot": trunk, "spine": trunk, "neck": trunk,
        "head": trunk, "collar": arms, "shoulder": arms, "elbow": arms, "wrist": arms,
    }  # fmt: skip


# de Leva (1996) segment mass fractions (male, adjusted Zatsiorsky-Seluyanov), split onto our bodies:
# lower trunk -> pelvis, middle trunk -> spine1 + spine2, upper trunk -> spine3 + collars, head+neck ->
# neck + head, foot -> ankle (hind/mid foot) + foot (toes). Sums to 1.
_MASS_FRACTIONS: dict[str, float] = {
    "pelvis": 0.1117, "spine1": 0.08165, "spine2": 0.08165, "spine3": 0.1396,
    "left_collar": 0.010, "right_collar": 0.010, "neck": 0.010, "head": 0.0594,
    "left_hip": 0.1416, "right_hip": 0.1416, "left_knee": 0.0433, "right_knee": 0.0433,
    "left_ankle": 0.0100, "right_ankle": 0.0100, "left_foot": 0.0037, "right_foot": 0.0037,
    "left_shoulder": 0.0271, "right_shoulder": 0.0271, "left_elbow": 0.0162, "right_elbow": 0.0162,
    "left_wrist": 0.0061, "right_wrist": 0.0061,
}  # fmt: skip


def default_mass_fractions() -> dict[str, float]:
    return dict(_MASS_FRACTIONS)


# Pairs of bodies whose primitive shapes overlap in ordinary poses without a real collision: neighbouring
# torso segments, thighs at the pelvis, upper arms at the chest, the head sphere at the collars and at
# raised upper arms, PHC's own knee/toe pairs (its <contact> block). Without them, retargeted Bandai/CMU
# frames had >1 cm overlaps head-spine3 and spine1-spine3 in every frame, head-collars in 96 %.
# Parent-child pairs are excluded by MuJoCo already; hands and forearms still collide with the body.
DEFAULT_EXCLUDES: tuple[tuple[str, str], ...] = (
    ("pelvis", "spine2"), ("pelvis", "spine3"), ("spine1", "spine3"), ("spine1", "left_hip"),
    ("spine1", "right_hip"), ("left_hip", "right_hip"), ("spine2", "neck"), ("spine2", "left_collar"),
    ("spine2", "right_collar"), ("spine3", "head"), ("spine3", "left_shoulder"),
    ("spine3", "right_shoulder"), ("neck", "left_collar"), ("neck", "right_collar"),
    ("left_collar", "right_collar"), ("head", "left_collar"), ("head", "right_collar"),
    ("head", "left_shoulder"), ("head", "right_shoulder"), ("left_knee", "left_foot"),
    ("right_knee", "right_foot"),
)  # fmt: skip


@dataclass
class HumanoidConfig:
    """Everything that defines the simulated humanoid and its clocks, in one place.

    ``armature_feet``: the foot subtree is light (~1 kg) and the ankle stiff, and MuJoCo's implicitfast
    integrates kp explicitly: with the 0.01 of the other hinges the standing body buzzed on its feet and
    fell (docs/decisions/projection.md: "armature 0.03 on ankle and toe hinges").
    """

    # 360 Hz: the stiff ankle and contact need the small step (240 Hz tracks worse;
    # docs/decisions/projection.md: "projection humanoid").
    sim_dt: float = 1.0 / 360.0
    control_dt: float = 1.0 / 30.0  # PhysDiff's policy rate (Appendix C: 60 Hz sim, 30 Hz control)
    # The root residual is recomputed (in Python) every this many simulation steps and held between;
    # the steps in between run in one ``mj_step(nstep=...)`` call, in C, without the GIL.
    # 180 Hz: held over 4 steps (90 Hz), the runs' tracking error grew by half once the residual was
    # bounded at 0.2 W (docs/decisions/projection.md: "residual within 0.1 W on walks and runs").
    residual_every: int = 2
    total_mass: float = 70.0  # kg
    gains: dict[str, PDGain] = field(default_factory=default_gains)
    limits_deg: dict[str, tuple[Range, Range, Range]] = field(default_factory=default_limits)
    hinge_order: dict[str, str] = field(default_factory=default_hinge_order)
    mass_fractions: dict[str, float] = field(default_factory=default_mass_fractions)
    armature: float = 0.01  # kg m^2 added to every hinge (PHC's value) ...
    armature_feet: float = 0.03  # ... and to ankle and toe hinges instead: see the class docstring
    friction: tuple[float, float, float] = (1.0, 0.005, 0.0001)  # sliding, torsional, rolling
    # Time constant (s), damping ratio: 2.5x stiffer than MuJoCo's (0.02, 1) so loaded soles sink ~1 mm, not 2.
    contact_solref: tuple[float, float] = (0.008, 1.0)
    integrator: str = "implicitfast"  # Euler blows up: the actuators' kv is only implicit there
    solver: str = "Newton"
    iterations: int = 50
    # Friction cone and the frictional-to-normal impedance ratio: MuJoCo's defaults here; the search controller
    # runs elliptic at impratio 10 (docs/decisions/projection.md: "a searching controller with no outside hand"
    # has the figures of both).
    cone: str = "pyramidal"
    impratio: float = 1.0
    # MuJoCo's noslip solver iterations (the slip of soft contacts taken out); 0, off: it did not lower the
    # search's Skate (docs/decisions/projection.md: "MuJoCo's noslip solver for the search's feet").
    noslip: int = 0
    # Contact dimensionality (MuJoCo ``condim``): 3, sliding friction only; 4 adds torsional friction
    # (``friction[1]``, m), 6 rolling too (``friction[2]``). 3: torsion did not lower the search's Skate
    # (docs/decisions/projection.md: "the hand box and torsional friction").
    condim: int = 3
    contact_excludes: tuple[tuple[str, str], ...] = DEFAULT_EXCLUDES
    heel_length: float = 0.061  # m behind the ankle (default body; scales with it); PHC's ankle box
    sole_below_toe: float = 0.0145  # m from the toe joint down to the sole (PHC's toe box)
    # m from the wrist to the hand box's end (default body): PHC's straight hand to the fingertips; the
    # search's humanoid ends it at the knuckles (physics/search.py ``search_humanoid``).
    hand_length: float = 0.19
    joint_limits: bool = True
    # Body parts collide with the floor only. Mocap legs pass closer than these capsules and boxes
    # allow: in a Bandai side-step the reference itself had ankle-ankle contact in 42 of 134 frames
    # and knee-knee in 25; with self-collision on, the legs caught on each other and the tracker fell
    # within 0.5 s (measured). Turn on for studies of self-penetration.
    self_collision: bool = False

    def __post_init__(self) -> None:
        if not (self.sim_dt > 0 and self.control_dt >= self.sim_dt):
            raise ShapeError(f"need 0 < sim_dt <= control_dt, got {self.sim_dt}, {self.control_dt}")
        ratio = self.control_dt / self.sim_dt
        if abs(ratio - round(ratio)) > 1e-6:
            raise ShapeError(f"control_dt must be a multiple of sim_dt, got ratio {ratio:.4f}")
        if self.condim not in (1, 3, 4, 6):
            raise ShapeError(f"condim must be 1, 3, 4 or 6 (MuJoCo's contact dimensions), got {self.condim}")
        if not self.hand_length > 0.02:
            raise ShapeError(f"hand_length must reach past the wrist box's start (0.02 m), "
                             f"got {self.hand_length}")
        if self.residual_every < 1 or round(ratio) % self.residual_every:
            raise ShapeError(f"residual_every must divide the {round(ratio)} simulation steps per control "
                             f"step, got {self.residual_every}")
        if self.total_mass <= 0:
            raise ShapeError(f"total_mass must be positive, got {self.total_mass}")
        missing = [n for n in JOINT_NAMES if self.mass_fractions.get(n, 0.0) <= 0.0]
        if missing:
            raise ShapeError(f"HumanoidConfig.mass_fractions needs a positive entry for {', '.join(missing)}")
        for group in set(JOINT_GROUP.values()):
            for table, name in ((self.gains, "gains"), (self.limits_deg, "limits_deg"),
                                (self.hinge_order, "hinge_order")):  # fmt: skip
                if group not in table:
                    raise ShapeError(f"HumanoidConfig.{name} has no entry for joint group '{group}'")
            if sorted(self.hinge_order[group]) != list(AXES):
                raise ShapeError(f"hinge_order['{group}'] must be a permutation of 'xyz'")

    @property
    def substeps(self) -> int:
        """Simulation steps per control step."""
        return int(round(self.control_dt / self.sim_dt))


# ----------------------------------------------------------------------------------------------
# Geometry, in our Y-up frame (x left, y up, z forward), metres. Radii and foot/hand sizes are
# PHC's for the SMPL neutral body, scaled by the body's size; capsules span 20-80 % of their bone
# as in PHC, so neighbouring capsules meet at the joints with their rounded ends.


@dataclass(frozen=True)
class _Geom:
    kind: str  # "capsule" | "sphere" | "box"
    a: np.ndarray  # capsule and segment box: from; sphere and axis-aligned box: centre
    b: np.ndarray | None  # capsule and segment box: to; else None
    size: np.ndarray  # capsule/sphere (r,); box: half sizes along our x, y, z; segment box (width, thickness)

    def volume(self) -> float:
        if self.kind == "sphere":
            return 4.0 / 3.0 * math.pi * self.size[0] ** 3
        if self.kind == "capsule":
            r = self.size[0]
            return math.pi * r * r * float(np.linalg.norm(self.b - self.a)) + 4.0 / 3.0 * math.pi * r**3
        if self.b is not None:  # box along a segment: two half sizes, half-length from the segment
            return 4.0 * float(np.prod(self.size)) * float(np.linalg.norm(self.b - self.a))
        return 8.0 * float(np.prod(self.size))


_CAPSULE_RADIUS = {  # PHC's radii (left/right averaged)
    "left_hip": 0.061, "left_knee": 0.0541, "left_collar": 0.0516, "left_shoulder": 0.0524,
    "left_elbow": 0.0407, "spine1": 0.0769, "spine2": 0.0755, "spine3": 0.1002, "neck": 0.0436,
}  # fmt: skip
_CAPSULE_SPAN = {"spine1": (0.45, 0.55), "spine2": (0.45, 0.55), "spine3": (0.32, 0.39)}
_PELVIS_RADIUS = 0.0942
_HEAD_RADIUS = 0.1011


def _side_free(name: str) -> str:
    return name.replace("right_", "left_")


def body_scale(offsets: np.ndarray) -> float:
    """Size of a body relative to the default one: ratio of summed bone lengths."""
    return float(np.linalg.norm(offsets, axis=-1).sum() / np.linalg.norm(REST_OFFSETS, axis=-1).sum())


def body_from_joints(joints: np.ndarray, fps: float = float(FPS)) -> np.ndarray:
    """Rest offsets (22, 3) of the humanoid that fits a motion: its bone lengths, and feet that stand flat.

    joints: (T, 22, 3) metres, Y up. Bone lengths and the hip/shoulder layout come from
    :func:`skeleton.offsets_from_joints`. The foot bone (ankle -> toe joint) is then tilted to the pitch
    it has in the motion while the foot stands still on the floor (median over such frames), because
    the feet's boxes are flat in the rest pose: with the default 23 degree pitch, a rig whose standing
    foot is pitched 40 degrees (Bandai) stood the humanoid on its toe boxes with the heels in the air
    (measured), and one pitched 12 degrees (CMU iClone) buried its heels. Without a standing frame the
    default pitch is kept.
    """
    joints = np.asarray(joints, dtype=np.float64)
    offsets = offsets_from_joints(joints)
    for side in ("left", "right"):
        a, f = JOINT_INDEX[f"{side}_ankle"], JOINT_INDEX[f"{side}_foot"]
        bone = joints[:, f] - joints[:, a]
        pitch = np.arctan2(-bone[:, 1], np.linalg.norm(bone[:, [0, 2]], axis=-1))
        speed = np.linalg.norm(np.diff(joints[:, f], axis=0), axis=-1) * fps
        standing = (joints[:-1, f, 1] < joints[:, f, 1].min() + 0.02) & (speed < 0.2)
        if not standing.any():
            continue
        p = float(np.median(pitch[:-1][standing]))
        rest = offsets[f]
        flat = np.array([rest[0], 0.0, rest[2]])
        flat /= np.linalg.norm(flat)
        offsets[f] = np.linalg.norm(rest) * (math.cos(p) * flat + np.array([0.0, -math.sin(p), 0.0]))
    return offsets


def _sole_depth(offsets: np.ndarray, side: str, cfg: HumanoidConfig, s: float) -> float:
    """Height of the ankle above the sole at rest (> 0)."""
    foot = offsets[JOINT_INDEX[f"{side}_foot"]]
    return max(-foot[1] + cfg.sole_below_toe * s, 0.04 * s)


def _geoms(j: int, offsets: np.ndarray, cfg: HumanoidConfig, s: float) -> list[_Geom]:
    """The geoms of body ``j`` in its own frame (ours, Y-up)."""
    name = JOINT_NAMES[j]
    kids = children(j)
    if name == "pelvis":
        return [_Geom("sphere", np.zeros(3), None, np.array([_PELVIS_RADIUS * s]))]
    if name == "head":
        return [_Geom("sphere", np.zeros(3), None, np.array([_HEAD_RADIUS * s]))]
    if name.endswith("_ankle"):
        side = name.split("_")[0]
        foot = offsets[kids[0]]
        sole = -_sole_depth(offsets, side, cfg, s)
        top = 0.0225 * s
        back, front = -cfg.heel_length * s, foot[2] - 0.010 * s
        centre = np.array([0.9 * foot[0], 0.5 * (sole + top), 0.5 * (back + front)])
        half = np.array([0.0483 * s, 0.5 * (top - sole), 0.5 * (front - back)])
        return [_Geom("box", centre, None, half)]
    if name.endswith("_foot"):
        side = name.split("_")[0]
        ankle_sole = _sole_depth(offsets, side, cfg, s)
        sole = offsets[j][1] + ankle_sole  # toe joint above the sole: soles of both boxes coincide
        sole = -max(sole, 0.01 * s)
        top = 0.0255 * s
        centre = np.array([0.0, 0.5 * (sole + top), 0.0248 * s])
        half = np.array([0.0478 * s, 0.5 * (top - sole), 0.0496 * s])
        return [_Geom("box", centre, None, half)]
    if name.endswith("_wrist"):
        # PHC's wrist capsule and hand box as one box along the forearm's direction (fromto box), to
        # ``hand_length``: the body has no wrist hinge, so the hand cannot bend to lie flat.
        d = offsets[j] / max(np.linalg.norm(offsets[j]), 1e-9)
        return [_Geom("box", d * 0.02 * s, d * cfg.hand_length * s, np.array([0.054 * s, 0.016 * s]))]
    if len(kids) >= 1:
        # Single bone (spine3 has three children: its capsule follows the neck, as in PHC).
        child = JOINT_INDEX["neck"] if name == "spine3" else kids[0]
        lo, hi = _CAPSULE_SPAN.get(name, (0.2, 0.8))
        r = _CAPSULE_RADIUS[_side_free(name)] * s
        return [_Geom("capsule", lo * offsets[child], hi * offsets[child], np.array([r]))]
    raise AssertionError(f"no geometry rule for {name}")


def standing_height(offsets: np.ndarray | None = None, config: HumanoidConfig | None = None) -> float:
    """Pelvis height (m) of the rest pose standing with its soles on the floor."""
    offsets = REST_OFFSETS if offsets is None else _check_offsets(offsets)
    cfg = HumanoidConfig() if config is None else config
    s = body_scale(offsets)
    heights = []
    for side in ("left", "right"):
        chain = [JOINT_INDEX[f"{side}_{n}"] for n in ("hip", "knee", "ankle")]
        ankle_y = sum(offsets[k][1] for k in chain)
        heights.append(-(ankle_y - _sole_depth(offsets, side, cfg, s)))
    return float(max(heights))


def foot_lift(offsets: np.ndarray | None = None, config: HumanoidConfig | None = None) -> float:
    """Height (m) of the toe joints above the soles when a foot stands flat.

    Motion data puts its floor at the lowest joint (HumanML3D, :mod:`physmotion.io`), i.e. at the toes,
    while the model's soles are this much lower: pass it as ``joints_to_qpos(..., lift=foot_lift(...))``
    to stand the model's soles on the floor instead of sinking them.
    """
    offsets = REST_OFFSETS if offsets is None else _check_offsets(offsets)
    cfg = HumanoidConfig() if config is None else config
    return float(cfg.sole_below_toe * body_scale(offsets))


def _check_offsets(offsets: np.ndarray) -> np.ndarray:
    offsets = np.asarray(offsets, dtype=np.float64)
    if offsets.shape != (NUM_JOINTS, 3):
        raise ShapeError(f"offsets must have shape ({NUM_JOINTS}, 3), got {offsets.shape}")
    if not np.all(np.isfinite(offsets)):
        raise ShapeError("offsets contain NaN or infinite values")
    check_bone_lengths(offsets)
    return offsets


# ----------------------------------------------------------------------------------------------
# MJCF text


def _fmt(v: np.ndarray | list[float] | tuple[float, ...]) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


def hinge_range(name: str, axis: str, config: HumanoidConfig) -> Range:
    """Range (radians) of hinge ``<name>_<axis>``; right-side joints mirror the left-side table."""
    lo, hi = config.limits_deg[JOINT_GROUP[name]][AXES.index(axis)]
    if name.startswith("right_") and axis in "xz":
        lo, hi = -hi, -lo
    return math.radians(lo), math.radians(hi)


def body_masses(offsets: np.ndarray | None = None, config: HumanoidConfig | None = None) -> dict[str, float]:
    """Mass (kg) per body name."""
    cfg = HumanoidConfig() if config is None else config
    total = sum(cfg.mass_fractions.values())
    return {n: cfg.total_mass * cfg.mass_fractions[n] / total for n in JOINT_NAMES}


def build_mjcf(offsets: np.ndarray | None = None, config: HumanoidConfig | None = None) -> str:
    """The humanoid's MJCF text.

    offsets: (22, 3) rest offsets in metres, our Y-up parent frames (default ``REST_OFFSETS``; for a
    motion's own body use ``skeleton.offsets_from_joints(joints)``).
    """
    offsets = REST_OFFSETS.copy() if offsets is None else _check_offsets(offsets)
    cfg = HumanoidConfig() if config is None else config
    s = body_scale(offsets)
    masses = body_masses(offsets, cfg)
    fr = cfg.friction

    lines: list[str] = [
        '<mujoco model="physmotion_smpl22">',
        '  <compiler angle="radian" autolimits="true"/>',
        f'  <option timestep="{cfg.sim_dt:.10g}" integrator="{cfg.integrator}" solver="{cfg.solver}"'
        f' iterations="{cfg.iterations}" cone="{cfg.cone}" impratio="{cfg.impratio:g}"'
        f' noslip_iterations="{cfg.noslip}"/>',
        "  <default>",
        f'    <joint type="hinge" armature="{cfg.armature:g}" damping="0"'
        f' limited="{str(cfg.joint_limits).lower()}"/>',
        f'    <geom condim="{cfg.condim}" friction="{_fmt(fr)}" solref="{_fmt(cfg.contact_solref)}" '
        f'contype="1" conaffinity="{int(cfg.self_collision)}" rgba="0.8 0.6 0.4 1"/>',
        "  </default>",
        "  <worldbody>",
        f'    <geom name="floor" type="plane" size="0 0 0.05" friction="{_fmt(fr)}" '
        f'solref="{_fmt(cfg.contact_solref)}" contype="0" conaffinity="1" rgba="0.8 0.9 0.8 1"/>',
    ]
    actuators: list[str] = []

    def emit(j: int, depth: int) -> None:
        name = JOINT_NAMES[j]
        pad = "  " * depth
        pos = to_mujoco(np.array([0.0, standing_height(offsets, cfg), 0.0]) if j == 0 else offsets[j])
        lines.append(f'{pad}<body name="{name}" pos="{_fmt(pos)}">')
        if j == 0:
            lines.append(f'{pad}  <freejoint name="{name}"/>')
        else:
            group = JOINT_GROUP[name]
            gain = cfg.gains[group]
            arm = cfg.armature_feet if group in ("ankle", "foot") else cfg.armature
            for axis in cfg.hinge_order[group]:
                lo, hi = hinge_range(name, axis, cfg)
                vec = [1 if a == axis else 0 for a in AXES]
                lines.append(
                    f'{pad}  <joint name="{name}_{axis}" axis="{_fmt(vec)}" range="{lo:.6g} {hi:.6g}"'
                    f' armature="{arm:g}"/>'
                )
                actuators.append(
                    f'    <position name="{name}_{axis}" joint="{name}_{axis}" kp="{gain.kp:g}" '
                    f'kv="{gain.kv:g}" forcerange="{-gain.torque_limit:g} {gain.torque_limit:g}"/>'
                )
        geoms = _geoms(j, offsets, cfg, s)
        density = masses[name] / sum(g.volume() for g in geoms)
        for k, g in enumerate(geoms):
            gname = name if k == 0 else f"{name}_{k}"
            common = f'{pad}  <geom name="{gname}" density="{density:.9g}"'
            if g.kind == "sphere":
                lines.append(f'{common} type="sphere" size="{g.size[0]:.9g}" pos="{_fmt(to_mujoco(g.a))}"/>')
            elif g.kind == "capsule":
                ft = np.concatenate([to_mujoco(g.a), to_mujoco(g.b)])
                lines.append(f'{common} type="capsule" size="{g.size[0]:.9g}" fromto="{_fmt(ft)}"/>')
            elif g.b is not None:  # box along a segment (hand); MuJoCo's fromto would make it square
                half = np.array([g.size[0], g.size[1], 0.5 * np.linalg.norm(g.b - g.a)])
                centre, zaxis = to_mujoco(0.5 * (g.a + g.b)), to_mujoco(g.b - g.a)
                where = f'pos="{_fmt(centre)}" zaxis="{_fmt(zaxis)}"'
                lines.append(f'{common} type="box" size="{_fmt(half)}" {where}/>')
            else:  # axis-aligned box: half sizes along our (x, y, z) are MuJoCo's (y, z, x)
                size, centre = to_mujoco(g.size), to_mujoco(g.a)
                lines.append(f'{common} type="box" size="{_fmt(size)}" pos="{_fmt(centre)}"/>')
        for c in children(j):
            emit(c, depth + 1)
        lines.append(f"{pad}</body>")

    emit(0, 2)
    lines.append("  </worldbody>")
    if cfg.contact_excludes:
        lines.append("  <contact>")
        for a, b in cfg.contact_excludes:
            lines.append(f'    <exclude body1="{a}" body2="{b}"/>')
        lines.append("  </contact>")
    lines.append("  <actuator>")
    lines.extend(actuators)
    lines.append("  </actuator>")
    lines.append("</mujoco>")
    return "\n".join(lines) + "\n"


def build_model(offsets: np.ndarray | None = None, config: HumanoidConfig | None = None):  # -> mujoco.MjModel
    """The compiled humanoid (see :func:`build_mjcf`)."""
    import mujoco

    return mujoco.MjModel.from_xml_string(build_mjcf(offsets, config))


# ----------------------------------------------------------------------------------------------
# Reading a compiled model back in skeleton terms (works for any model built by build_mjcf).


@dataclass(frozen=True)
class Layout:
    """Where the skeleton lives in a model.

    body_ids: (22,) MuJoCo body id per skeleton joint (skeleton order; MuJoCo's is depth-first).
    hinge_qpos: (22, 3) qpos address of each joint's hinges in nesting order (row 0, the root, is -1).
    hinge_dof: (22, 3) qvel/dof address, same layout. hinge_order: per joint, the axes in nesting order
    ("" for the root). offsets: (22, 3) rest offsets in our frame, read from the model.
    """

    body_ids: np.ndarray
    hinge_qpos: np.ndarray
    hinge_dof: np.ndarray
    hinge_order: tuple[str, ...]
    offsets: np.ndarray


_LAYOUTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # model -> Layout, freed with the model


def layout(model) -> Layout:  # model: mujoco.MjModel
    """The :class:`Layout` of a model built by :func:`build_model` (read-only arrays, cached per model:
    a projection asks six times, and reading it takes ~2 ms)."""
    lay = _LAYOUTS.get(model)
    if lay is None:
        lay = _LAYOUTS[model] = _read_layout(model)
    return lay


def _read_layout(model) -> Layout:
    import mujoco

    from physmotion.physics.frames import from_mujoco

    body_ids = np.zeros(NUM_JOINTS, dtype=np.int64)
    qadr = -np.ones((NUM_JOINTS, 3), dtype=np.int64)
    dadr = -np.ones((NUM_JOINTS, 3), dtype=np.int64)
    orders: list[str] = [""]
    offsets = np.zeros((NUM_JOINTS, 3))
    for j, name in enumerate(JOINT_NAMES):
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        if b < 0:
            raise ShapeError(f"model has no body named '{name}': not a physmotion humanoid")
        body_ids[j] = b
        if j == 0:
            continue
        if not np.allclose(model.body_quat[b], [1, 0, 0, 0]):
            raise ShapeError(f"body '{name}' is rotated at rest: not a physmotion humanoid")
        offsets[j] = from_mujoco(model.body_pos[b])
        first, count = model.body_jntadr[b], model.body_jntnum[b]
        if count != 3:
            raise ShapeError(f"body '{name}' has {count} joints, expected 3 hinges")
        order = ""
        for k in range(3):
            jid = first + k
            axis = model.jnt_axis[jid]
            order += AXES[int(np.argmax(np.abs(axis)))]
            qadr[j, k] = model.jnt_qposadr[jid]
            dadr[j, k] = model.jnt_dofadr[jid]
        orders.append(order)
    for arr in (body_ids, qadr, dadr, offsets):
        arr.setflags(write=False)  # shared by every caller through the cache
    return Layout(body_ids, qadr, dadr, tuple(orders), offsets)
