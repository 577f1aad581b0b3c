"""Export onto a user's rig (``export --rig-from``), in place and loop (issue 64), on a motion of the shipped
model and on real rigs: a Bandai Namco BVH with a user's mapping, CMU's ASF skeleton, a Mixamo-named rig."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from experiments.retarget_rigs import cmu_asf_bvh, mixamo_rig_bvh
from physmotion.io.bvh import read_bvh, read_bvh_rest, write_bvh
from physmotion.io.importer import import_clip
from physmotion.io.in_place import best_loop, horizontal_travel, in_place, trim_to_loop
from physmotion.io.retarget_rig import (
    RetargetConfig,
    error_at_our_proportions,
    load_target,
    retarget,
    save_retargeted_bvh,
)
from physmotion.metrics import physical_metrics
from physmotion.motion import Motion
from tests.cli_runner import invoke


@pytest.fixture(scope="module")
def walk() -> Motion:
    """The shipped model's walk, P applied (generate's default), 4 s, seed 0."""
    from physmotion.generate import GenerateConfig, generate

    return generate(["a person walks forward"], GenerateConfig(num=1, seed=0, seconds=4)).motions[0]


@pytest.fixture(scope="module")
def user_mapping(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """docs/examples/mapping_bandai.json without its fps (the file we write has the motion's 20 fps)."""
    data = json.loads(Path("docs/examples/mapping_bandai.json").read_text(encoding="utf-8"))
    data.pop("fps")
    path = tmp_path_factory.mktemp("map") / "bandai.json"
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def _bandai(mocap_dir: Path) -> Path:
    return sorted((mocap_dir / "bandai").glob("*/data/*.bvh"))[0]


def _surface_metrics(joints: np.ndarray) -> dict[str, float]:
    from physmotion.physics.surface import HumanoidSurface

    return physical_metrics(np.asarray(joints, dtype=np.float64), body=HumanoidSurface())


@pytest.mark.parametrize("rig", ["mixamo", "cmu_asf", "bandai_mapping"])
def test_round_trip_meets_issue_64(rig: str, walk: Motion, mocap_dir: Path, user_mapping: Path, tmp_path: Path) -> None:
    """Exported onto the rig and imported back with the same table or mapping: the mean joint error at our
    proportions <= 2 cm, Skate not above ours + 1 mm, Penetrate <= 2 mm."""
    kw: dict[str, object] = {}
    if rig == "mixamo":
        src = tmp_path / "mixamo.bvh"
        mixamo_rig_bvh(src)
        kw = {"rig": "mixamo"}
    elif rig == "cmu_asf":
        src = tmp_path / "cmu.bvh"
        subject = mocap_dir / "cmu_amc" / "subjects" / "01"
        cmu_asf_bvh(src, subject / "01_01.amc", subject / "01.asf")
        kw = {"rig": "cmu_asf", "units": "cm"}
    else:
        src, kw = _bandai(mocap_dir), {"mapping": user_mapping}
    out = tmp_path / "out.bvh"
    result = save_retargeted_bvh(walk, out, load_target(src, **kw))
    back = import_clip(out, **kw)
    assert back.num_frames == walk.num_frames
    error, _ = error_at_our_proportions(walk.joints, back.joints, result.leg_ratio)
    assert error <= 0.02
    ours, theirs = _surface_metrics(walk.joints), _surface_metrics(back.joints)
    assert theirs["skate"] <= ours["skate"] + 1.0
    assert theirs["penetrate"] <= 2.0


def test_pinning_removes_the_sliding_direction_matching_adds(walk: Motion, mocap_dir: Path, user_mapping: Path,
                                                              tmp_path: Path) -> None:  # fmt: skip
    """Without the two-bone IK pass the planted feet of the other body slide; with it Skate falls to under a
    fifth (and under ours + 1 mm)."""
    target = load_target(_bandai(mocap_dir), mapping=user_mapping)
    skates = []
    for pin in (False, True):
        path = tmp_path / f"{pin}.bvh"
        write_bvh(path, retarget(walk, target, RetargetConfig(pin_feet=pin)).rig, walk.fps)
        skates.append(_surface_metrics(import_clip(path, mapping=user_mapping).joints)["skate"])
    ours = _surface_metrics(walk.joints)["skate"]
    assert skates[1] <= ours + 1.0 and skates[1] < 0.2 * skates[0]


def test_their_skeleton_is_kept(walk: Motion, tmp_path: Path) -> None:
    """The output has their hierarchy and OFFSETs (bone lengths) and channels on every joint; joints we lack
    (fingers, twist, end joints) keep their rest rotation relative to their parent."""
    src, out = tmp_path / "mixamo.bvh", tmp_path / "out.bvh"
    mixamo_rig_bvh(src)
    save_retargeted_bvh(walk, out, load_target(src, rig="mixamo"))
    rest, got = read_bvh_rest(src), read_bvh_rest(out)
    assert got.names == rest.names and np.array_equal(got.parents, rest.parents)
    np.testing.assert_allclose(got.translations[0, 1:], rest.translations[0, 1:], atol=1e-5)
    motion = read_bvh(out)
    assert motion.num_frames == walk.num_frames
    lacking = [j for j, n in enumerate(motion.names) if any(k in n for k in ("Thumb", "Index", "Middle", "Twist", "Top"))]
    assert len(lacking) >= 20
    np.testing.assert_allclose(motion.rotations[:, lacking], np.broadcast_to(np.eye(3), motion.rotations[:, lacking].shape),
                               atol=1e-5)  # fmt: skip
    knee = motion.names.index("mixamorig:LeftLeg")
    assert np.ptp(motion.rotations[:, knee], axis=0).max() > 0.3  # the mapped joints do move


def test_in_place_and_loop(walk: Motion) -> None:
    """In place: the root's horizontal travel <= 1 cm (a walk of metres); heading and height kept. The loop
    of a walk: start in the first, end in the last 30 %, and its end pose closer to its start than frame 0's
    pose is to the last frame's."""
    assert horizontal_travel(walk.joints) > 1.0
    still = in_place(walk)
    assert horizontal_travel(still.joints) <= 0.01
    np.testing.assert_allclose(still.joints[..., 1], walk.joints[..., 1])
    loop = best_loop(walk.joints)
    n = walk.num_frames
    assert 0 <= loop.start < 0.3 * n + 1 and n - 0.3 * n - 1 <= loop.end < n
    assert loop.distance < best_loop(walk.joints, share=1 / n).distance  # frame 0 against the last frame
    assert trim_to_loop(walk, loop).num_frames == loop.end - loop.start


def test_cli_export_rig_from_in_place_and_errors(walk: Motion, tmp_path: Path) -> None:
    """`export --rig-from --rig --in-place` writes their skeleton with the root over the origin; options that
    need --rig-from without it, or a rig the file does not fit, are one error line and no output."""
    src, npz, out = tmp_path / "mixamo.bvh", tmp_path / "walk.npz", tmp_path / "out.bvh"
    mixamo_rig_bvh(src)
    walk.save(npz)
    done = invoke("export", npz, "-o", out, "--rig-from", src, "--rig", "mixamo", "--in-place", "--loop")
    assert done.returncode == 0, done.stderr
    assert "loop: frames" in done.stdout
    back = import_clip(out, rig="mixamo")
    assert horizontal_travel(back.joints) <= 0.01
    for args, words in (
        (("--mapping", "x.json"), "need --rig-from"),
        (("--rig-from", src, "--rig", "bandai"), "lacks"),
        (("--rig-from", src, "--rig", "cmu_asf"), "lacks"),
    ):
        bad = tmp_path / "bad.bvh"
        fail = invoke("export", npz, "-o", bad, *args)
        assert fail.returncode != 0 and words in fail.stderr and "Traceback" not in fail.stderr
        assert len(fail.stderr.strip().splitlines()) == 1 and not bad.exists()


def test_generate_in_place(tmp_path: Path) -> None:
    """generate's in_place option (``generate --in-place``): the written motion's root travels <= 1 cm."""
    from physmotion.generate import GenerateConfig, generate

    motion = generate(["a person walks forward"], GenerateConfig(num=1, seed=0, seconds=2, physics="none", in_place=True)).motions[0]
    assert horizontal_travel(motion.joints) <= 0.01


def test_export_file_is_what_the_command_runs(walk: Motion, tmp_path: Path) -> None:
    """The library function behind `export`: options checked before the motion is read (a missing source
    is not reached), the loop reported, the travel removed, the retarget onto their rig written."""
    from physmotion.errors import PhysmotionError
    from physmotion.io.export import export_file

    with pytest.raises(PhysmotionError, match="need --rig-from"):
        export_file(tmp_path / "missing.npz", tmp_path / "x.bvh", rig="mixamo")
    with pytest.raises(PhysmotionError, match="writes a .bvh"):
        export_file(tmp_path / "missing.npz", tmp_path / "x.glb", rig_from=tmp_path / "rig.bvh")
    src, rig = tmp_path / "walk.npz", tmp_path / "mixamo.bvh"
    walk.save(src)
    mixamo_rig_bvh(rig)
    lines = export_file(src, tmp_path / "out.bvh", rig_from=rig, rig="mixamo", in_place=True, loop=True)
    assert lines[0].startswith("loop: frames ") and "joints of mixamo.bvh" in lines[-1]
    assert read_bvh(tmp_path / "out.bvh").names == read_bvh_rest(rig).names
    plain = export_file(src, tmp_path / "plain.npz", in_place=True)
    assert plain == [f"wrote {tmp_path / 'plain.npz'}"]
    assert horizontal_travel(Motion.load(tmp_path / "plain.npz").joints) <= 0.01
