"""Export a Motion as binary glTF 2.0 (.glb): the 22-joint skeleton, a low-poly skinned body, the animation.

What the file holds (glTF 2.0 specification, https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html):

- one node per joint of :data:`physmotion.skeleton.JOINT_NAMES`, parented as ``PARENTS``; each node's rest
  translation is the motion's rest offset (``Motion.offsets``, else estimated from the joints), its rest
  rotation the identity: the bind pose is our T-pose;
- a body mesh of capsules, one per bone plus a head and two hands (8-sided rings, hemispherical caps), each
  vertex weighted to the one joint whose rotation moves its bone (spec 3.7.3 "Skins"), with the inverse bind
  matrices of that T-pose;
- one animation: a rotation channel per joint (the local rotations of ``Motion.with_rotations()`` as unit
  quaternions x, y, z, w) and the root's translation, one keyframe per frame at ``1 / fps`` s, LINEAR.

Axes: glTF is right-handed, Y up, metres, and "the front of a glTF asset faces +Z" (spec 3.4), which is
:mod:`physmotion.conventions`' frame (Y up, metres, the body faces +Z, its left is +X): no axis change.
Written with pygltflib (a maintained glTF library); the licence tag and its terms go in ``asset.extras``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pygltflib as gl
from scipy.spatial.transform import Rotation

from physmotion.motion import Motion, joined_licence_tag, write_atomic
from physmotion.physics.humanoid import body_scale
from physmotion.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS, rest_joints


@dataclass(frozen=True)
class BodyConfig:
    """The capsule body's look: ring sides, latitude rings per cap, and radii (m, default-size body;
    scaled by the motion's :func:`body_scale`). Radii are near the physics humanoid's capsules
    (physmotion/physics/humanoid.py, PHC's), a little fuller on the torso so that it reads as one body."""

    sides: int = 8
    cap_rings: int = 2
    head_radius: float = 0.10
    hand_radius: float = 0.035
    hand_length: float = 0.08  # m beyond the wrist, along the forearm


# Radius (m, default body) of the capsule of the bone that ends at each joint (parent -> joint).
_BONE_RADIUS: dict[str, float] = {
    "left_hip": 0.07, "spine1": 0.09, "left_knee": 0.061, "spine2": 0.085, "left_ankle": 0.054,
    "spine3": 0.095, "left_foot": 0.04, "neck": 0.095, "left_collar": 0.06, "head": 0.045,
    "left_shoulder": 0.052, "left_elbow": 0.0524, "left_wrist": 0.0407,
}  # fmt: skip


def _bone_radius(name: str) -> float:
    return _BONE_RADIUS[name.replace("right_", "left_")]


def licence_text(tag: str) -> str:
    """The terms a licence tag ("NC", "SA", "NC,SA", "open" or "") stands for, in words."""
    parts = set(joined_licence_tag([tag]).split(","))
    terms = []
    if "NC" in parts:
        terms.append("non-commercial use only (NC: made from Bandai Namco's motions, CC BY-NC 4.0)")
    if "SA" in parts:
        terms.append("share-alike (SA: made from HDM05's motions, CC BY-SA 3.0)")
    return "; ".join(terms) or "no licence restriction known for the data it was made from (open)"


@dataclass(frozen=True)
class BodyMesh:
    """A skinned body in the bind (T-)pose.

    positions, normals: (V, 3) float32 world metres; joints: (V,) int, the one joint each vertex follows;
    indices: (F * 3,) uint16 counter-clockwise triangles (outward faces, spec 3.7.2.1).
    """

    positions: np.ndarray
    normals: np.ndarray
    joints: np.ndarray
    indices: np.ndarray


def _perpendicular(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors u, v with (u, v, axis) right-handed and orthonormal."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def _capsule(a: np.ndarray, b: np.ndarray, radius: float, cfg: BodyConfig) -> tuple[np.ndarray, ...]:
    """A capsule around segment a -> b: (positions (V, 3), normals (V, 3), triangles (F, 3) local indices).

    a == b gives a sphere. Rings go from the pole beyond a to the pole beyond b."""
    d = b - a
    length = float(np.linalg.norm(d))
    axis = d / length if length > 1e-9 else np.array([0.0, 1.0, 0.0])
    u, v = _perpendicular(axis)
    theta = 2 * np.pi * np.arange(cfg.sides) / cfg.sides
    radial = np.cos(theta)[:, None] * u + np.sin(theta)[:, None] * v  # (S, 3)
    lat = np.linspace(-np.pi / 2, 0, cfg.cap_rings + 1)[1:]  # rings of a's cap, the last on the equator
    rings = [(a, phi) for phi in lat] + [(b, -phi) for phi in lat[::-1]]
    pos = [a - radius * axis]
    nrm = [-axis]
    for centre, phi in rings:
        n = np.sin(phi) * axis + np.cos(phi) * radial
        pos.extend(centre + radius * n)
        nrm.extend(n)
    pos.append(b + radius * axis)
    nrm.append(axis)
    s, r = cfg.sides, len(rings)
    tris = []
    nxt = lambda k: (k + 1) % s  # noqa: E731
    for k in range(s):  # the fan around a's pole: looking from beyond a, counter-clockwise
        tris.append((0, 1 + nxt(k), 1 + k))
    for i in range(r - 1):
        lo, hi = 1 + i * s, 1 + (i + 1) * s
        for k in range(s):
            tris.append((lo + k, lo + nxt(k), hi + nxt(k)))
            tris.append((lo + k, hi + nxt(k), hi + k))
    top = 1 + r * s
    last = 1 + (r - 1) * s
    for k in range(s):
        tris.append((last + k, last + nxt(k), top))
    return np.array(pos), np.array(nrm), np.array(tris)


def body_mesh(offsets: np.ndarray, config: BodyConfig | None = None) -> BodyMesh:
    """The capsule body of a skeleton with rest ``offsets`` (22, 3), in its T-pose from :func:`rest_joints`.

    Each bone parent -> j is a capsule moved by the parent (whose rotation aims it); the head is a sphere
    on the head joint and each hand a short capsule beyond the wrist, moved by that joint."""
    cfg = BodyConfig() if config is None else config
    offsets = np.asarray(offsets, dtype=np.float64)
    rest = rest_joints(offsets)
    s = body_scale(offsets)
    parts: list[tuple[np.ndarray, np.ndarray, float, int]] = []  # (a, b, radius, joint)
    for j in range(1, NUM_JOINTS):
        parts.append((rest[PARENTS[j]], rest[j], _bone_radius(JOINT_NAMES[j]) * s, PARENTS[j]))
    head = JOINT_INDEX["head"]
    parts.append((rest[head], rest[head], cfg.head_radius * s, head))
    for side in ("left", "right"):
        w, e = JOINT_INDEX[f"{side}_wrist"], JOINT_INDEX[f"{side}_elbow"]
        along = (rest[w] - rest[e]) / np.linalg.norm(rest[w] - rest[e])
        parts.append((rest[w], rest[w] + cfg.hand_length * s * along, cfg.hand_radius * s, w))
    positions, normals, joints, indices = [], [], [], []
    base = 0
    for a, b, radius, joint in parts:
        pos, nrm, tris = _capsule(a, b, radius, cfg)
        positions.append(pos)
        normals.append(nrm)
        joints.append(np.full(len(pos), joint))
        indices.append(tris + base)
        base += len(pos)
    return BodyMesh(
        positions=np.concatenate(positions).astype(np.float32),
        normals=np.concatenate(normals).astype(np.float32),
        joints=np.concatenate(joints),
        indices=np.concatenate(indices).reshape(-1).astype(np.uint16),
    )


def _quaternions(rotations: np.ndarray) -> np.ndarray:
    """(T, 22, 3, 3) rotation matrices -> (T, 22, 4) unit quaternions (x, y, z, w), glTF's order (spec
    3.11), each frame's sign chosen nearest the previous frame's so that LINEAR interpolation takes the
    short way."""
    q = Rotation.from_matrix(rotations.reshape(-1, 3, 3)).as_quat().reshape(*rotations.shape[:2], 4)
    for t in range(1, len(q)):
        flip = np.sum(q[t] * q[t - 1], axis=-1) < 0
        q[t, flip] *= -1
    return q


class _Blob:
    """The binary chunk being built: each array appended 4-byte aligned, with its bufferView and accessor."""

    def __init__(self, gltf: gl.GLTF2) -> None:
        self.gltf = gltf
        self.data = bytearray()

    def add(self, array: np.ndarray, kind: str, component: int, *, target: int | None = None,
            bounds: bool = False) -> int:  # fmt: skip
        """Append ``array`` (rows are elements), return its accessor's index. bounds: write min and max
        (required for POSITION and animation inputs, spec 3.6.2.5 and 3.11)."""
        raw = np.ascontiguousarray(array).tobytes()
        self.data.extend(b"\0" * (-len(self.data) % 4))
        view = gl.BufferView(buffer=0, byteOffset=len(self.data), byteLength=len(raw), target=target)
        self.data.extend(raw)
        self.gltf.bufferViews.append(view)
        flat = array.reshape(len(array), -1)
        accessor = gl.Accessor(bufferView=len(self.gltf.bufferViews) - 1, componentType=component,
                               count=len(array), type=kind)  # fmt: skip
        if bounds:
            accessor.min = flat.min(axis=0).astype(float).tolist()
            accessor.max = flat.max(axis=0).astype(float).tolist()
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1


def motion_gltf(motion: Motion, config: BodyConfig | None = None) -> gl.GLTF2:
    """The glTF document of ``motion`` (see the module's docstring), its binary chunk set."""
    motion = motion.with_rotations()
    offsets = np.asarray(motion.offsets, dtype=np.float64)
    rotations = np.asarray(motion.rotations, dtype=np.float64)
    mesh = body_mesh(offsets, config)
    rest = rest_joints(offsets)
    tag = joined_licence_tag([motion.licence_tag])
    gltf = gl.GLTF2(
        asset=gl.Asset(version="2.0", generator="physmotion",
                       extras={"licence_tag": tag, "licence": licence_text(tag), "texts": list(motion.texts),
                               "source": motion.source}),
        scene=0, bufferViews=[], accessors=[],
    )  # fmt: skip
    blob = _Blob(gltf)
    # Nodes 0..21 are the joints in our order; node 22 holds the body mesh (a scene root, as a skinned mesh's
    # node should be: its own transform is ignored, spec 3.7.3).
    for j, name in enumerate(JOINT_NAMES):
        kids = [c for c, p in enumerate(PARENTS) if p == j]
        translation = rest[0] if j == 0 else offsets[j]
        gltf.nodes.append(gl.Node(name=name, translation=[float(x) for x in translation],
                                  children=kids or None))  # fmt: skip
    ibm = np.tile(np.eye(4, dtype=np.float32), (NUM_JOINTS, 1, 1))
    ibm[:, :3, 3] = -rest  # the bind pose has no rotation: its inverse is a translation
    # glTF matrices are column-major
    ibm_accessor = blob.add(np.swapaxes(ibm, 1, 2).copy(), gl.MAT4, gl.FLOAT)
    gltf.skins.append(gl.Skin(name="physmotion22", joints=list(range(NUM_JOINTS)), skeleton=0,
                              inverseBindMatrices=ibm_accessor))  # fmt: skip
    n_vert = len(mesh.positions)
    joints4 = np.zeros((n_vert, 4), dtype=np.uint8)
    joints4[:, 0] = mesh.joints
    weights4 = np.zeros((n_vert, 4), dtype=np.float32)
    weights4[:, 0] = 1.0
    attributes = gl.Attributes(
        POSITION=blob.add(mesh.positions, gl.VEC3, gl.FLOAT, target=gl.ARRAY_BUFFER, bounds=True),
        NORMAL=blob.add(mesh.normals, gl.VEC3, gl.FLOAT, target=gl.ARRAY_BUFFER),
        JOINTS_0=blob.add(joints4, gl.VEC4, gl.UNSIGNED_BYTE, target=gl.ARRAY_BUFFER),
        WEIGHTS_0=blob.add(weights4, gl.VEC4, gl.FLOAT, target=gl.ARRAY_BUFFER),
    )
    indices = blob.add(mesh.indices, gl.SCALAR, gl.UNSIGNED_SHORT, target=gl.ELEMENT_ARRAY_BUFFER)
    gltf.materials.append(gl.Material(name="body", pbrMetallicRoughness=gl.PbrMetallicRoughness(
        baseColorFactor=[0.55, 0.62, 0.75, 1.0], metallicFactor=0.0, roughnessFactor=0.8)))  # fmt: skip
    gltf.meshes.append(gl.Mesh(name="body", primitives=[gl.Primitive(attributes=attributes, indices=indices,
                                                                      material=0)]))  # fmt: skip
    gltf.nodes.append(gl.Node(name="body", mesh=0, skin=0))
    gltf.scenes.append(gl.Scene(name="physmotion", nodes=[0, NUM_JOINTS]))

    times = (np.arange(motion.num_frames) / motion.fps).astype(np.float32)
    time_accessor = blob.add(times[:, None], gl.SCALAR, gl.FLOAT, bounds=True)
    samplers, channels = [], []
    quats = _quaternions(rotations).astype(np.float32)
    for j in range(NUM_JOINTS):
        samplers.append(gl.AnimationSampler(input=time_accessor, interpolation=gl.ANIM_LINEAR,
                                            output=blob.add(quats[:, j], gl.VEC4, gl.FLOAT)))  # fmt: skip
        target = gl.AnimationChannelTarget(node=j, path=gl.ROTATION)
        channels.append(gl.AnimationChannel(sampler=j, target=target))
    root = np.asarray(motion.joints[:, 0], dtype=np.float32)
    samplers.append(gl.AnimationSampler(input=time_accessor, interpolation=gl.ANIM_LINEAR,
                                        output=blob.add(root, gl.VEC3, gl.FLOAT)))  # fmt: skip
    target = gl.AnimationChannelTarget(node=0, path=gl.TRANSLATION)
    channels.append(gl.AnimationChannel(sampler=NUM_JOINTS, target=target))
    name = motion.texts[0] if motion.texts else "motion"
    gltf.animations.append(gl.Animation(name=name, samplers=samplers, channels=channels))

    blob.data.extend(b"\0" * (-len(blob.data) % 4))
    gltf.buffers.append(gl.Buffer(byteLength=len(blob.data)))
    gltf.set_binary_blob(bytes(blob.data))
    return gltf


def glb_bytes(motion: Motion, config: BodyConfig | None = None) -> bytes:
    """The .glb file of ``motion`` as bytes (glTF 2.0 binary container, spec 4.4)."""
    return b"".join(motion_gltf(motion, config).save_to_bytes())


def save_glb(motion: Motion, path: str | Path, config: BodyConfig | None = None) -> None:
    """Write ``motion`` as a .glb (skeleton, skinned capsule body, animation), atomically."""
    payload = glb_bytes(motion, config)
    write_atomic(path, lambda f: f.write(payload))
