"""The humanoid's collision geometry as the body surface of the ground metrics.

PhysDiff measures Penetrate and Float at the lowest SMPL mesh vertex. We have no SMPL mesh; the issue
asks for the humanoid's collision geometry in the same pose, and that matters: the joint-only surface
model of :mod:`physmotion.metrics.geometry` assumes the default foot, and on Bandai walks (feet pitched
40 degrees) it put the simulated soles 13-21 mm above where MuJoCo had them (measured).
:class:`HumanoidSurface` poses the humanoid on the joints (retargeting, no lift) and reads the geoms.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from physmotion.errors import ShapeError
from physmotion.physics.humanoid import HumanoidConfig, body_from_joints, build_model, hinge_range
from physmotion.physics.retarget import joints_to_qpos
from physmotion.skeleton import FOOT_JOINTS, JOINT_INDEX, JOINT_NAMES, NUM_JOINTS


HAND_JOINTS: tuple[int, int] = (JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"])
"""The joints whose bodies carry the hands (the 22-joint skeleton has no hand joint)."""


def lowest_point(model, data) -> float:
    """Height (m, MuJoCo z) of the lowest point of the body (every geom but the floor, geom 0)."""
    return float(body_lowest(model, data.geom_xpos, data.geom_xmat))


def body_lowest(model, geom_xpos: np.ndarray, geom_xmat: np.ndarray) -> np.ndarray:
    """Height (...) of the body's lowest point (every geom but the floor, geom 0) from the geom poses
    geom_xpos (..., ngeom, 3) and geom_xmat (..., ngeom, 9): one frame or many (see :func:`lowest_of`)."""
    return lowest_of(model, geom_xpos, geom_xmat, np.arange(1, model.ngeom)).min(axis=-1)


def geoms_lowest(model, data, geoms: np.ndarray) -> np.ndarray:
    """Lowest heights (G,) of the given geoms in the pose of ``data`` (see :func:`lowest_of`)."""
    return lowest_of(model, data.geom_xpos, data.geom_xmat, geoms)


def lowest_of(model, geom_xpos: np.ndarray, geom_xmat: np.ndarray, geoms: np.ndarray) -> np.ndarray:
    """Lowest heights (..., G) of the given geoms from their poses, geom_xpos (..., ngeom, 3) and
    geom_xmat (..., ngeom, 9), for one frame or many at once: a box reaches down by the sum of its half
    sizes times the |z| of its axes, a capsule by its half length along its axis plus the radius, a
    sphere by its radius."""
    import mujoco

    size = model.geom_size[geoms]
    zrow = geom_xmat[..., geoms, 6:9]  # third row of each rotation: the z of the geom's axes
    kind = model.geom_type[geoms]
    reach = np.where(kind == mujoco.mjtGeom.mjGEOM_BOX, np.abs(zrow * size).sum(-1),
                     np.where(kind == mujoco.mjtGeom.mjGEOM_CAPSULE,
                              np.abs(zrow[..., 2]) * size[:, 1] + size[:, 0], size[:, 0]))  # fmt: skip
    return geom_xpos[..., geoms, 2] - reach


_TOES = [i for i, j in enumerate(FOOT_JOINTS) if JOINT_NAMES[j].endswith("_foot")]  # FOOT_JOINTS' toe boxes


class _Heights(NamedTuple):
    """Posed heights (m) of a batch: ``rest`` (..., T) the lowest point of everything but the toe boxes;
    ``feet`` (..., T, 4) the foot patches as posed (toes rigid with the foot); ``toes`` (..., T, 2) the
    toe boxes bent to their highest (:func:`toe_lowest`); ``hands`` (..., T, 2) flat hands."""

    rest: np.ndarray
    feet: np.ndarray
    toes: np.ndarray
    hands: np.ndarray


def _bent(posed: np.ndarray, highest: np.ndarray, floor: float) -> np.ndarray:
    """A toe box's lowest point where a floor at ``floor`` bends it: as posed where it clears the floor,
    else bent up to the floor, or as far as its hinge allows (``highest``)."""
    return np.where(posed >= floor, posed, np.minimum(floor, highest))


_BOX_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
_TOE_PITCH_STEP = np.radians(2.5)  # the pitches tried over the toe hinge's range (exact to ~1 mm)


def toe_lowest(
    model, xpos: np.ndarray, geom_xmat: np.ndarray, geom: int, config: HumanoidConfig
) -> np.ndarray:
    """Lowest height (T,) of the toe box ``geom`` when it pitches about its joint (the toe hinge's y,
    within its range) to the angle that holds that lowest point highest: a toe the floor bends.

    xpos: (T, nbody, 3) body positions and geom_xmat: (T, ngeom, 9) geom rotations of the posed frames
    (:func:`pose_frames`). The box is axis-aligned in its body (the toe joint at the origin), so its
    rotation is the body's and its corners are ``geom_pos`` +- ``geom_size``. At pitch 0 this is
    :func:`lowest_of`; the best pitch is searched on a grid, both directions (a foot pitched up at a heel
    strike levels its toes downwards).
    """
    lo, hi = hinge_range(model.geom(geom).name, "y", config)
    beta = np.union1d(np.arange(lo, hi, _TOE_PITCH_STEP), [0.0, hi])  # (K,) radians, 0 included
    c, s = np.cos(beta), np.sin(beta)
    pitch = np.zeros((len(beta), 3, 3))  # (K, 3, 3) rotations about the body's y axis (MuJoCo frame)
    pitch[:, 0, 0], pitch[:, 0, 2], pitch[:, 1, 1], pitch[:, 2, 0], pitch[:, 2, 2] = c, s, 1.0, -s, c
    corners = model.geom_pos[geom] + _BOX_CORNERS * model.geom_size[geom]  # (8, 3) in the toe body
    up = geom_xmat[:, geom, 6:9]  # (T, 3) the world z of the body's axes
    height = np.einsum("ti,kni->tkn", up, np.einsum("kij,nj->kni", pitch, corners))  # (T, K, 8)
    return xpos[:, model.geom_bodyid[geom], 2] + height.min(axis=-1).max(axis=-1)


def pose_frames(model, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward kinematics of every frame of qpos (N, nq): body positions xpos (N, nbody, 3) and geom
    poses geom_xpos (N, ngeom, 3), geom_xmat (N, ngeom, 9). One C call per frame; the arithmetic on the
    poses is then done for all frames at once (the per-frame numpy calls cost more than the kinematics)."""
    import mujoco

    data = mujoco.MjData(model)
    n = len(qpos)
    xpos = np.empty((n, model.nbody, 3))
    gpos, gmat = np.empty((n, model.ngeom, 3)), np.empty((n, model.ngeom, 9))
    for k in range(n):
        data.qpos[:] = qpos[k]
        mujoco.mj_kinematics(model, data)
        xpos[k], gpos[k], gmat[k] = data.xpos, data.geom_xpos, data.geom_xmat
    return xpos, gpos, gmat


class HumanoidSurface:
    """A :class:`physmotion.metrics.geometry.BodySurface` read from the MuJoCo humanoid.

    offsets: the body to pose: (22, 3) for every motion, or one per motion of a batch ((B, 22, 3) or a
    list whose None entries mean "estimate"); by default each call measures it from the joints it is given
    (:func:`body_from_joints`). For P's output, pass the body P simulated (``ProjectedMotion.body``):
    the estimate from the simulated joints can pitch the feet a few degrees off the humanoid's, which
    moved the soles by up to 10 mm against MuJoCo's (measured on generated motions).
    Foot patches: the ankle box (heel) and the toe box.

    Toes: the 22-joint skeleton's toe joint is a leaf, so the joints say nothing of the toes' bend and
    retargeting leaves the toe box rigid with the foot. At a push-off (foot pitched 20-60 degrees past
    its standing pitch) that box pointed its tip 1-3 cm into the floor while the toe joint stood 1-6 cm
    above it (captured CMU walks). Here a toe box that reaches under the floor is bent up to it, as far
    as the toe hinge's range allows (:func:`toe_lowest`); one that clears the floor keeps its pose. The
    heights therefore depend on the floor (``floor`` below): the toes bend as the floor bends them, as the
    simulated humanoid's toe hinges do (docs/decisions/metrics.md "toes that bend").

    Hands: the simulated humanoid has no wrist joint, so its hand box runs on along the forearm to
    0.19 m past the wrist (PHC's hand; fingertips of a hand held straight). A pose read from joints
    says nothing of the wrist's bend, and a hand resting flat on the floor bends it ~90 degrees: the
    palm lies about its half thickness under the wrist joint, while the rigid box pointed 19 cm into the
    floor and lifted hand-supported clips (cartwheels, get-ups) 10-20 cm at import. Here each hand's
    lowest point is the wrist joint less the hand box's half thickness (a flat hand, fingertips on the
    palm's level); the simulated humanoid keeps PHC's box (docs/decisions/data.md "import floor").
    """

    def __init__(
        self,
        offsets: np.ndarray | Sequence[np.ndarray | None] | None = None,
        config: HumanoidConfig | None = None,
    ) -> None:
        if isinstance(offsets, np.ndarray):
            if offsets.ndim not in (2, 3) or offsets.shape[-2:] != (NUM_JOINTS, 3):
                raise ShapeError(f"offsets must be (22, 3) or (B, 22, 3), got {offsets.shape}")
            if offsets.ndim == 3:
                offsets = list(offsets)
        elif offsets is not None:
            offsets = list(offsets)  # one body (or None) per motion
        self.offsets, self.config = offsets, config or HumanoidConfig()
        self._cache: tuple[object, _Heights] | None = None

    def _per_frame(self, joints: np.ndarray) -> _Heights:
        """The posed heights of ``joints`` (..., T, 22, 3); the metrics ask for more than one of the same
        array in turn, so the last result is kept."""
        # Keyed on the array object itself, held here: an id() alone can be reused by the next array
        # once the first is freed, and would then return another motion's heights.
        if self._cache is not None and self._cache[0] is joints:
            return self._cache[1]

        x = np.asarray(joints, dtype=np.float64)
        flat = x.reshape((-1,) + x.shape[-3:])
        rest = np.zeros(flat.shape[:2])
        feet = np.zeros(flat.shape[:2] + (4,))
        toes = np.zeros(flat.shape[:2] + (2,))
        hands = np.zeros(flat.shape[:2] + (2,))
        for b, motion in enumerate(flat):
            offsets = self._body(b, len(flat))
            offsets = body_from_joints(motion) if offsets is None else offsets
            model = build_model(offsets, self.config)
            patch = np.array([model.geom(JOINT_NAMES[j]).id for j in FOOT_JOINTS])
            hand = np.array([model.geom(JOINT_NAMES[j]).id for j in HAND_JOINTS])
            others = np.setdiff1d(np.arange(1, model.ngeom), np.concatenate([hand, patch[_TOES]]))
            xpos, gpos, gmat = pose_frames(model, joints_to_qpos(motion, model, config=self.config))
            wrist = np.array([model.body(JOINT_NAMES[j]).id for j in HAND_JOINTS])
            hands[b] = xpos[:, wrist, 2] - model.geom_size[hand, 1]  # flat hand: wrist less half thickness
            rest[b] = np.minimum(lowest_of(model, gpos, gmat, others).min(axis=-1), hands[b].min(axis=-1))
            feet[b] = lowest_of(model, gpos, gmat, patch)
            toes[b] = np.stack([toe_lowest(model, xpos, gmat, g, self.config) for g in patch[_TOES]], axis=-1)
        shape = x.shape[:-2]
        result = _Heights(rest.reshape(shape), feet.reshape(shape + (4,)), toes.reshape(shape + (2,)),
                          hands.reshape(shape + (2,)))  # fmt: skip
        self._cache = (joints, result)
        return result

    def _body(self, b: int, count: int) -> np.ndarray | None:
        """The given body of motion ``b`` of ``count``, or None (estimate it)."""
        given = self.offsets
        if not isinstance(given, list):  # None, or one body for every motion
            return given
        if len(given) != count:
            raise ShapeError(f"{len(given)} bodies given for {count} motions")
        return given[b]

    def lowest_height(self, joints: np.ndarray, floor: float = 0.0) -> np.ndarray:
        """(..., T) the body's lowest point, m, its toes bent by a floor at height ``floor`` (np.inf: every
        toe pressed as far as it bends, e.g. where the floor is not known yet)."""
        h = self._per_frame(joints)
        return np.minimum(h.rest, _bent(h.feet[..., _TOES], h.toes, floor).min(axis=-1))

    def foot_heights(self, joints: np.ndarray, floor: float = 0.0) -> np.ndarray:
        """(..., T, 4) lowest point of the foot patches in FOOT_JOINTS order (heel, toe, heel, toe), m; the
        toes bent by a floor at height ``floor``, as in :meth:`lowest_height`."""
        h = self._per_frame(joints)
        feet = h.feet.copy()
        feet[..., _TOES] = _bent(h.feet[..., _TOES], h.toes, floor)
        return feet

    def hand_heights(self, joints: np.ndarray) -> np.ndarray:
        """(..., T, 2) lowest point of the left and right hand (a flat hand: see the class docstring)."""
        return self._per_frame(joints).hands


_GROUNDING_PERCENTILES = np.arange(0, 55, 5)  # candidate floors: percentiles of the per-frame lowest point


def ground_on_surface(
    joints: np.ndarray, body: np.ndarray | None = None, config: HumanoidConfig | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """A motion moved up or down by the constant that leaves the least Phys-Err on the humanoid's
    surface (:func:`surface_lift`): the best a constant shift can do, and the physical metrics' floor
    convention (:mod:`physmotion.metrics.physical`).

    joints: (T, 22, 3) metres, Y up, e.g. in the data convention (lowest joint at y = 0, which leaves
    the soles ~1.5-2 cm under the floor). body: the humanoid's rest offsets (22, 3), estimated from the
    joints if None. Returns (joints shifted, same dtype; the body used), so the motion can be measured on
    the very body it was grounded with.
    """
    x = np.asarray(joints)
    if x.ndim != 3 or x.shape[1:] != (NUM_JOINTS, 3):
        raise ShapeError(f"joints must be (T, 22, 3), got {x.shape}")
    body = body_from_joints(x) if body is None else np.asarray(body, dtype=np.float64)
    return (x + np.array([0.0, surface_lift(x, body, config), 0.0])).astype(x.dtype), body


def surface_lift(joints: np.ndarray, body: np.ndarray, config: HumanoidConfig | None = None) -> float:
    """Metres to move a motion up (down if negative) for the least Phys-Err on the humanoid's surface.

    Why not "the lowest point over the clip on the floor": the heel boxes dip their corners below the flat
    stance at heel strikes (and, before the toes bent, the toe boxes 15-30 mm at toe-offs), so on captured
    walks that floor left the stance foot floating (test split: Float 23 mm, Phys-Err 23 mm;
    docs/decisions/data.md: "floor convention"). The candidates are the 0th to 50th percentiles of the
    per-frame lowest surface point.
    joints: (T, 22, 3) metres, Y up; body: the humanoid's rest offsets (22, 3).
    """
    from physmotion.metrics.physical import phys_err

    surface = HumanoidSurface(np.asarray(body, dtype=np.float64), config)
    x64 = np.asarray(joints, dtype=np.float64)
    low = surface.lowest_height(x64)
    up = np.zeros(3)
    best = (np.inf, 0.0)
    for floor in np.unique(np.percentile(low, _GROUNDING_PERCENTILES)):
        up[1] = floor
        best = min(best, (phys_err(x64 - up, body=surface), floor))
    return -float(best[1])
