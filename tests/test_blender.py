"""Blender opens what ``physmotion export`` writes (issue 64, item 5): headless Blender (Debian's
``blender``, installed by ``make test``'s ``blender`` target) imports the file, and its bone count, frame
count, frame rate and the feet's positions at a few frames are checked against the motion we exported.

Each format is one entry of :data:`FORMATS`: the ``export`` options that write it, the Python that
imports it in Blender, and what Blender should then hold. A retargeted BVH (``export --rig-from``) or a
``.glb`` is one more entry (its importer ``bpy.ops.import_scene.gltf(filepath=path)``, after setting
``bpy.context.scene.render.fps`` to the motion's rate: glTF keeps times in seconds, Blender's importer
places keys at the scene's rate).
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

    export: options of ``physmotion export`` after ``-o FILE``; importer: Python run in Blender with
    ``bpy`` and ``path``; bones: the armature's bone count; feet: bone name -> our joint (index into the
    motion's joints) at that bone's head; same_skeleton: the bones have our lengths, so the whole head
    position is checked (else only its height: another rig's proportions)."""

    suffix: str
    export: tuple[str, ...]
    importer: str
    bones: int
    feet: dict[str, int]
    same_skeleton: bool = True


# Our BVH is Y up, facing +Z (physmotion.io.export.save_bvh): the importer's axis_forward -Z, axis_up Y turn
# it to Blender's Z up; update_scene_fps sets the scene to the file's frame time, one key a BVH frame
# (io_anim_bvh/import_bvh.py, load: with it use_fps_scale is turned off).
BVH_IMPORT = ("bpy.ops.import_anim.bvh(filepath=path, axis_forward='-Z', axis_up='Y', global_scale=1.0, "
              "update_scene_fps=True, update_scene_duration=True)")  # fmt: skip
FORMATS = [
    pytest.param(Format(".bvh", (), BVH_IMPORT, 22, {"left_foot": 10, "right_foot": 11}), id="bvh"),
    # the retargeted BVH (export --rig-from) and the .glb go here, one entry each
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


@pytest.mark.parametrize("source", ["captured", "generated"])
@pytest.mark.parametrize("fmt", FORMATS)
def test_blender_opens_the_export(fmt: Format, source: str, request: pytest.FixtureRequest, tmp_path: Path) -> None:
    npz = request.getfixturevalue(source)
    motion = Motion.load(npz)
    out = tmp_path / f"motion{fmt.suffix}"
    res = invoke("export", npz, "-o", out, *fmt.export)
    assert res.returncode == 0, res.stderr
    n = motion.num_frames
    frames = [0, n // 3, n // 2, n - 1]
    got = blender({"path": str(out), "importer": fmt.importer, "bones": list(fmt.feet), "frames": frames},
                  tmp_path)  # fmt: skip
    assert got["bones"] == fmt.bones
    assert got["fps"] == pytest.approx(motion.fps)
    first, last = got["frame_range"]
    assert (first, last - first + 1, got["keyframes"]) == (1, n, n)  # one key per frame, from frame 1
    for bone, joint in fmt.feet.items():
        ours = motion.joints[frames, joint]
        theirs = np.asarray(got["heads"][bone])
        error_cm = 100 * (np.linalg.norm(theirs - ours, axis=-1) if fmt.same_skeleton else
                          np.abs(theirs[:, 1] - ours[:, 1]))  # fmt: skip
        assert error_cm.max() <= FOOT_CM, (bone, error_cm)
        assert np.abs(theirs[:, 1] - ours[:, 1]).max() * 100 <= FOOT_CM  # the height, in any case


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
