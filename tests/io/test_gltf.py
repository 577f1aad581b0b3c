"""glTF export (.glb): the Khronos validator finds no error; the file read back (pygltflib) and posed by its
own node transforms gives the motion's joints within 1 mm; the skinned body sits on the bones; the CLI."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pygltflib as gl
import pytest
from scipy.spatial.transform import Rotation

from physmotion.io import import_clip
from physmotion.io.gltf import body_mesh, glb_bytes
from physmotion.motion import Motion
from physmotion.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS
from tests.cli_runner import invoke

ROOT = Path(__file__).resolve().parents[2]
VALIDATOR = ROOT / ".cache" / "node" / "node_modules" / "gltf-validator"  # `make gltf-validator`
WALK = "bandai2_dataset-2_walk_normal_001"  # Bandai: licence tag NC
CMU_WALK = "cmu_02_01"


def validate(path: Path) -> dict:
    """The Khronos glTF validator's report on ``path`` (fails, not skips, without node or the validator)."""
    node = shutil.which("node")
    if node is None:
        pytest.fail("node is not installed: `make test` installs it (make gltf-validator)")
    if not (VALIDATOR / "package.json").is_file():
        pytest.fail(f"the glTF validator is not installed at {VALIDATOR}: run `make gltf-validator`")
    res = subprocess.run([node, str(Path(__file__).with_name("gltf_validate.js")), str(VALIDATOR), str(path)],
                         capture_output=True, text=True, timeout=120, check=False)  # fmt: skip
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def _read(gltf: gl.GLTF2, accessor: int) -> np.ndarray:
    """An accessor's data as (count, components) float64 (FLOAT / UNSIGNED_BYTE / UNSIGNED_SHORT only)."""
    acc = gltf.accessors[accessor]
    view = gltf.bufferViews[acc.bufferView]
    dtypes = {gl.FLOAT: np.float32, gl.UNSIGNED_BYTE: np.uint8, gl.UNSIGNED_SHORT: np.uint16}
    dtype = dtypes[acc.componentType]
    width = {gl.SCALAR: 1, gl.VEC3: 3, gl.VEC4: 4, gl.MAT4: 16}[acc.type]
    start = view.byteOffset + (acc.byteOffset or 0)
    raw = np.frombuffer(gltf.binary_blob(), dtype=dtype, count=acc.count * width, offset=start)
    return raw.reshape(acc.count, width).astype(np.float64)


def _trs(translation: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(quat_xyzw).as_matrix()
    m[:3, 3] = translation
    return m


def _world(gltf: gl.GLTF2, frame: int) -> dict[int, np.ndarray]:
    """World matrix of every joint node at keyframe ``frame``: the file's own node tree (children lists) and
    rest translations, with the animation's channels replacing what they target (glTF 2.0 spec 3.11)."""
    anim = gltf.animations[0]
    values: dict[tuple[int, str], np.ndarray] = {}
    for ch in anim.channels:
        values[(ch.target.node, ch.target.path)] = _read(gltf, anim.samplers[ch.sampler].output)[frame]
    world: dict[int, np.ndarray] = {}

    def visit(node: int, parent: np.ndarray) -> None:
        n = gltf.nodes[node]
        t = values.get((node, gl.TRANSLATION), np.array(n.translation or [0.0, 0.0, 0.0]))
        r = values.get((node, gl.ROTATION), np.array(n.rotation or [0.0, 0.0, 0.0, 1.0]))
        world[node] = parent @ _trs(t, r)
        for c in n.children or []:
            visit(c, world[node])

    for root in gltf.scenes[gltf.scene].nodes:
        visit(root, np.eye(4))
    return world


@pytest.fixture(scope="module")
def walk(clip) -> Motion:
    return import_clip(clip(WALK))


@pytest.fixture(scope="module")
def walk_glb(walk: Motion, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("glb") / "walk.glb"
    path.write_bytes(glb_bytes(walk))
    return path


@pytest.mark.slow  # runs node and the Khronos validator, installed by `make test` (make gltf-validator)
@pytest.mark.parametrize("source", ["imported", "joints only"])
def test_glb_passes_the_khronos_validator(source: str, walk: Motion, clip, tmp_path: Path) -> None:
    # "joints only": a motion with no rotations (as a model's output), solved by IK on export
    motion = walk if source == "imported" else Motion(joints=import_clip(clip(CMU_WALK)).joints, fps=20.0)
    path = tmp_path / "m.glb"
    path.write_bytes(glb_bytes(motion))
    report = validate(path)
    issues = report["issues"]
    assert issues["numErrors"] == 0, issues["messages"]
    assert issues["numWarnings"] == 0, issues["messages"]
    info = report["info"]
    assert info["hasSkins"] and info["animationCount"] == 1 and info["version"] == "2.0"
    assert info["totalVertexCount"] == len(body_mesh(motion.with_rotations().offsets).positions)


@pytest.mark.slow  # node and the validator, as above
def test_a_broken_file_is_caught_by_the_validator_check(walk: Motion, tmp_path: Path) -> None:
    """The validator test can fail: a quaternion that is not unit length is an error it reports."""
    gltf = gl.GLTF2().load_from_bytes(glb_bytes(walk))
    acc = gltf.accessors[gltf.animations[0].samplers[0].output]
    blob = bytearray(gltf.binary_blob())
    start = gltf.bufferViews[acc.bufferView].byteOffset
    blob[start : start + 16] = np.array([0.0, 0.0, 0.0, 2.0], dtype=np.float32).tobytes()
    gltf.set_binary_blob(bytes(blob))
    path = tmp_path / "broken.glb"
    path.write_bytes(b"".join(gltf.save_to_bytes()))
    report = validate(path)
    codes = {m["code"] for m in report["issues"]["messages"]}
    assert report["issues"]["numErrors"] >= 1, report["issues"]
    assert "ACCESSOR_ANIMATION_SAMPLER_OUTPUT_NON_NORMALIZED_QUATERNION" in codes, codes


def test_read_back_the_nodes_reproduce_the_joints_within_1mm(walk: Motion, walk_glb: Path) -> None:
    gltf = gl.GLTF2().load(str(walk_glb))
    names = [n.name for n in gltf.nodes[:NUM_JOINTS]]
    assert names == list(JOINT_NAMES)
    for j, p in enumerate(PARENTS[1:], start=1):
        assert j in gltf.nodes[p].children
    times = _read(gltf, gltf.animations[0].samplers[0].input)[:, 0]
    assert len(times) == walk.num_frames and np.allclose(np.diff(times), 1 / walk.fps, atol=1e-6)
    errors = []
    for frame in (0, 1, walk.num_frames // 2, walk.num_frames - 1):
        world = _world(gltf, frame)
        pos = np.array([world[j][:3, 3] for j in range(NUM_JOINTS)])
        errors.append(np.linalg.norm(pos - walk.joints[frame], axis=-1).max())
    assert max(errors) < 1e-3, [f"{1000 * e:.3f} mm" for e in errors]
    # Y up, metres, facing +Z (no axis change): the head is ~1.5 m above the toes, the walk goes toward +Z
    world = _world(gltf, 0)
    assert 1.2 < world[15][1, 3] - world[10][1, 3] < 1.8
    assert walk.joints[-1, 0, 2] - walk.joints[0, 0, 2] > 1.0


def test_the_skinned_body_sits_on_the_bones(walk: Motion, walk_glb: Path) -> None:
    """Skinning each capsule with the file's joints, weights and inverse bind matrices puts it between the
    motion's joints: a capsule's vertex centroid is its bone's midpoint (the capsule is symmetric)."""
    gltf = gl.GLTF2().load(str(walk_glb))
    prim = gltf.meshes[0].primitives[0]
    verts = _read(gltf, prim.attributes.POSITION)
    joints = _read(gltf, prim.attributes.JOINTS_0).astype(int)
    weights = _read(gltf, prim.attributes.WEIGHTS_0)
    assert np.allclose(weights.sum(axis=1), 1.0)
    ibm = _read(gltf, gltf.skins[0].inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)  # column-major
    frame = walk.num_frames // 2
    world = _world(gltf, frame)
    skin = np.stack([world[n] for n in gltf.skins[0].joints]) @ ibm  # (22, 4, 4)
    homog = np.concatenate([verts, np.ones((len(verts), 1))], axis=1)
    posed = np.einsum("vk,vkij,vj->vi", weights, skin[joints], homog)[:, :3]
    per_capsule = len(verts) // (NUM_JOINTS - 1 + 3)  # a capsule per bone, the head, two hands
    for j in range(1, NUM_JOINTS):
        part = posed[(j - 1) * per_capsule : j * per_capsule]
        middle = (walk.joints[frame, PARENTS[j]] + walk.joints[frame, j]) / 2
        assert np.linalg.norm(part.mean(axis=0) - middle) < 1e-3, JOINT_NAMES[j]
    # every triangle faces outward (or is degenerate: the head sphere's zero-height equator band)
    idx = _read(gltf, prim.indices).astype(int).reshape(-1, 3)
    normals = _read(gltf, prim.attributes.NORMAL)
    tri = verts[idx]
    face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(face, axis=1)
    outward = np.sum(face * normals[idx].sum(axis=1), axis=1) > 0
    assert np.all(outward | (area < 1e-9))


def test_licence_and_captions_travel_in_asset_extras(walk: Motion, walk_glb: Path) -> None:
    gltf = gl.GLTF2().load(str(walk_glb))
    extras = gltf.asset.extras
    assert walk.licence_tag == "NC"
    assert extras["licence_tag"] == "NC" and "non-commercial" in extras["licence"]
    assert extras["texts"] == walk.texts


def test_export_cli_writes_a_glb(walk: Motion, tmp_path: Path) -> None:
    src = tmp_path / "walk.npz"
    walk.save(src)
    out = tmp_path / "walk.glb"
    res = invoke("export", src, "-o", out)
    assert res.returncode == 0, res.stderr
    data = out.read_bytes()
    assert data[:4] == b"glTF" and int.from_bytes(data[4:8], "little") == 2  # GLB header: magic, version 2
    assert data == glb_bytes(Motion.load(src))  # deterministic, the library function's bytes


def test_export_glb_of_a_bad_motion_is_one_line_and_writes_nothing(tmp_path: Path) -> None:
    bad = tmp_path / "bad.npz"
    np.savez(bad, joints=np.zeros((5, 3, 3)), fps=np.float32(20))
    out = tmp_path / "out.glb"
    res = invoke("export", bad, "-o", out)
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "joints" in lines[0] and "Traceback" not in res.stderr, res.stderr
    assert not out.exists()
