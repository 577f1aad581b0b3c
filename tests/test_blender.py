"""Blender opens what ``physmotion export`` writes (issue 64, item 5): headless Blender (Debian's
``blender``, installed by ``make test``'s ``blender`` target) imports the file, and its bone count, frame
count, frame rate and the feet's positions at a few frames are checked against the motion we exported.

Each format is one entry of :data:`FORMATS`: the ``export`` options that write it, the Python that
imports it in Blender, and what Blender should then hold: our BVH, a BVH retargeted onto a Mixamo-named
rig of other proportions (``export --rig-from``) and the ``.glb`` (glTF keeps times in seconds; Blender's
importer places one key a frame at the scene's rate, set to the motion's first, from frame 0).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from physmotion.motion import Motion
from tests.cli_runner import invoke

pytestmark = pytest.mark.slow(reason="starts Blender (about 2 s a file) and generates with the shipped model")

BANDAI_WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"
SCRIPT = Path(__file__).with_name("blender_open.py")
FOOT_CM = 1.0  # Blender's foot positions against ours, in cm


@dataclass(frozen=True)
class Format:
    """An export format as Blender opens it.

    export: options of ``physmotion export`` after ``-o FILE`` ("{rig}": the Mixamo-named rig's BVH);
    importer: Python run in Blender with ``bpy`` and ``path`` ("{fps}": the motion's rate); bones: the
    armature's bone count (None: the rig file's joints); feet: bone name -> our joint (index into the
    motion's joints) at that bone's head; same_skeleton: the bones have our lengths, so the head is
    checked against our joint (else, on another rig's proportions, against that bone's position in the
    file as physmotion's own BVH reader computes it, in metres); first: the action's first frame."""

    suffix: str
    export: tuple[str, ...]
    importer: str
    bones: int | None
    feet: dict[str, int]
    same_skeleton: bool = True
    first: int = 1


# Our BVH is Y up, facing +Z (physmotion.io.export.save_bvh): the importer's axis_forward -Z, axis_up Y turn
# it to Blender's Z up; update_scene_fps sets the scene to the file's frame time, one key a BVH frame
# (io_anim_bvh/import_bvh.py, load: with it use_fps_scale is turned off).
BVH_IMPORT = ("bpy.ops.import_anim.bvh(filepath=path, axis_forward='-Z', axis_up='Y', global_scale=1.0, "
              "update_scene_fps=True, update_scene_duration=True)")  # fmt: skip
GLB_IMPORT = "bpy.context.scene.render.fps = {fps}\nbpy.ops.import_scene.gltf(filepath=path)"
FEET = {"left_foot": 10, "right_foot": 11}
FORMATS = [
    pytest.param(Format(".bvh", (), BVH_IMPORT, 22, FEET), id="bvh"),
    # the rig's BVH is in centimetres, as Mixamo's: Blender scales it to metres on import
    pytest.param(Format(".bvh", ("--rig-from", "{rig}", "--rig", "mixamo"),
                        BVH_IMPORT.replace("global_scale=1.0", "global_scale=0.01"), None,
                        {"mixamorig:LeftToeBase": 10, "mixamorig:RightToeBase": 11}, same_skeleton=False),
                 id="bvh-on-a-mixamo-rig"),
    pytest.param(Format(".glb", (), GLB_IMPORT, 22, FEET, first=0), id="glb"),
]


def blender(request: dict, tmp_path: Path) -> dict:
    """Run tests/blender_open.py in headless Blender on ``request`` and return its answer."""
    exe = shutil.which("blender")
    if exe is None:
        pytest.fail("blender is not installed: `make test` installs it (apt-get install blender)")
    request = dict(request, out=str(tmp_path / "answer.json"))
    (tmp_path / "request.json").write_text(json.dumps(request), encoding="utf-8")
    command = [exe, "--background", "--factory-startup", "--python-exit-code", "1", "--python", str(SCRIPT),
               "--", str(tmp_path / "request.json")]  # fmt: skip
    res = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return json.loads((tmp_path / "answer.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def captured(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real Bandai walk (182 frames at 20 fps) imported by the CLI."""
    out = tmp_path_factory.mktemp("captured") / "walk.npz"
    res = invoke("import", mocap_dir / BANDAI_WALK, "-o", out, "--no-preview")
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s walk from the shipped model, with generate's default physics."""
    folder = tmp_path_factory.mktemp("generated")
    res = invoke("generate", "a person walks forward", "--seconds", "3", "--no-preview", "-o", folder)
    assert res.returncode == 0, res.stderr
    return next(folder.glob("*.npz"))


@pytest.fixture(scope="module")
def mixamo_rig(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A Mixamo-named rig of other proportions, T-pose rest, in cm (experiments/retarget_rigs.py's)."""
    from experiments.retarget_rigs import mixamo_rig_bvh

    path = tmp_path_factory.mktemp("rig") / "mixamo.bvh"
    mixamo_rig_bvh(path)
    return path


@pytest.mark.parametrize("source", ["captured", "generated"])
@pytest.mark.parametrize("fmt", FORMATS)
def test_blender_opens_the_export(fmt: Format, source: str, request: pytest.FixtureRequest, tmp_path: Path) -> None:
    npz = request.getfixturevalue(source)
    motion = Motion.load(npz)
    out = tmp_path / f"motion{fmt.suffix}"
    rig = request.getfixturevalue("mixamo_rig") if "{rig}" in fmt.export else None
    res = invoke("export", npz, "-o", out, *(str(rig) if a == "{rig}" else a for a in fmt.export))
    assert res.returncode == 0, res.stderr
    n = motion.num_frames
    frames = list(range(0, n, 5))
    importer = fmt.importer.replace("{fps}", str(int(round(motion.fps))))  # Blender's fps is an int
    got = blender({"path": str(out), "importer": importer, "bones": list(fmt.feet), "frames": frames}, tmp_path)
    bones = fmt.bones if fmt.bones is not None else sum(
        line.split()[0] in ("ROOT", "JOINT") for line in out.read_text().splitlines())  # fmt: skip
    assert got["bones"] == bones
    assert got["fps"] == pytest.approx(motion.fps)
    first, last = got["frame_range"]
    assert (first, last - first + 1, got["keyframes"]) == (fmt.first, n, n)  # one key per frame
    for bone, joint in fmt.feet.items():
        ours = motion.joints[frames, joint]
        theirs = np.asarray(got["heads"][bone])
        if not fmt.same_skeleton:  # the retargeted file's own bone, by our reader (centimetres, Y up)
            from physmotion.io.bvh import read_bvh

            rig = read_bvh(out)
            ours = 0.01 * rig.forward_kinematics()[frames, rig.index(bone)]
        error_cm = 100 * np.linalg.norm(theirs - ours, axis=-1)
        assert error_cm.max() <= FOOT_CM, (bone, error_cm)


def test_blender_plays_the_bvh_at_its_frame_time(captured: Path, tmp_path: Path) -> None:
    """Without update_scene_fps, use_fps_scale spreads the file's frames over Blender's default 24 fps
    scene by its frame time: 9.05 s of motion stay 9.05 s."""
    motion = Motion.load(captured)
    out = tmp_path / "walk.bvh"
    assert invoke("export", captured, "-o", out).returncode == 0
    importer = "bpy.ops.import_anim.bvh(filepath=path, use_fps_scale=True)"
    got = blender({"path": str(out), "importer": importer, "bones": [], "frames": []}, tmp_path)
    assert got["fps"] == 24 != motion.fps
    first, last = got["frame_range"]
    assert (last - first) / got["fps"] == pytest.approx((motion.num_frames - 1) / motion.fps, abs=1e-3)
