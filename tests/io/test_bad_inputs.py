"""Bad inputs fail with a PhysmotionError whose message is one line naming the file, and write nothing."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from physmotion.errors import MotionFormatError, PhysmotionError
from physmotion.io import import_clip
from physmotion.io.bvh import Latin1Warning


def _check(path: Path, match: str, **options: object) -> None:
    before = sorted(path.parent.iterdir()) if path.parent.is_dir() else []
    with pytest.raises(PhysmotionError) as info:
        import_clip(path, **options)
    message = str(info.value)
    assert "\n" not in message and str(path) in message, message
    assert match in message, message
    after = sorted(path.parent.iterdir()) if path.parent.is_dir() else []
    assert after == before  # no partial output


def _bvh_text(clip: Callable, clip_id: str = "cmubvh_131_01") -> str:
    return clip(clip_id).path.read_text()


def test_missing_file(tmp_path: Path) -> None:
    _check(tmp_path / "nope.bvh", "no such file", rig="bandai", fps=30)
    _check(tmp_path / "nope.amc", "no such file", asf=tmp_path / "nope.asf", fps=120)


def test_truncated_bvh_motion(clip, tmp_path: Path) -> None:
    text = _bvh_text(clip)
    path = tmp_path / "cut.bvh"
    path.write_text(text[: int(len(text) * 0.6)])
    _check(path, "truncated BVH: the header announces 994 frames", rig="cmu_bvh_cgspeed_max", fps=120)


@pytest.mark.parametrize("cut", ["MOTION", "Frames:", "JOINT LeftKnee"])
def test_truncated_bvh_header(clip, tmp_path: Path, cut: str) -> None:
    text = _bvh_text(clip)
    path = tmp_path / "cut.bvh"
    path.write_text(text[: text.index(cut)])
    _check(path, "truncated", rig="cmu_bvh_cgspeed_max", fps=120)


def test_text_file_that_is_not_bvh(mocap_dir: Path, tmp_path: Path) -> None:
    path = tmp_path / "readme.bvh"
    path.write_text((mocap_dir / "README.md").read_text())
    _check(path, "not a BVH file", rig="bandai", fps=30)


def test_zero_frames(clip, tmp_path: Path) -> None:
    text = _bvh_text(clip)
    path = tmp_path / "empty_motion.bvh"
    path.write_text(text[: text.index("MOTION")] + "MOTION\nFrames: 0\nFrame Time: 0.0083333\n")
    _check(path, "zero frames", rig="cmu_bvh_cgspeed_max", fps=120)


def test_nan_values(clip, tmp_path: Path) -> None:
    text = _bvh_text(clip)
    head, body = text.split("Frame Time: .0083333", 1)
    lines = body.split("\n")
    lines[5] = lines[5].replace("0.0000", "nan", 1)
    path = tmp_path / "nan.bvh"
    path.write_text(head + "Frame Time: .0083333" + "\n".join(lines))
    _check(path, "NaN", rig="cmu_bvh_cgspeed_max", fps=120)


def test_words_in_the_motion_block(clip, tmp_path: Path) -> None:
    text = _bvh_text(clip)
    path = tmp_path / "words.bvh"
    path.write_text(text.replace("5.2300", "five", 1))
    _check(path, "non-numeric", rig="cmu_bvh_cgspeed_max", fps=120)


def test_binary_and_non_utf8_junk(tmp_path: Path) -> None:
    junk = tmp_path / "junk.bvh"
    junk.write_bytes(bytes(range(128, 256)) * 40)
    with pytest.warns(Latin1Warning, match="read as Latin-1"):  # then read, and refused as what it is
        _check(junk, "not a BVH file", rig="bandai", fps=30)
    binary = tmp_path / "binary.bvh"
    binary.write_bytes(b"HIERARCHY\x00\x01\x02" * 100)
    _check(binary, "binary data", rig="bandai", fps=30)


def test_empty_file(mocap_dir: Path) -> None:
    """The iClone folder holds a real empty file (001_02.bvh, not in the manifest)."""
    path = mocap_dir / "cmu_iclone/subjects/001/001_02.bvh"
    assert path.stat().st_size == 0
    _check(path, "empty file", rig="cmu_iclone_cc_base", fps=60)


def test_truncated_and_bad_amc(clip, tmp_path: Path) -> None:
    info = clip("cmu_02_01")
    text = info.path.read_text()
    cut = tmp_path / "cut.amc"
    cut.write_text(text[: int(len(text) * 0.5)])
    _check(cut, "truncated", asf=info.skeleton, fps=120)
    nan = tmp_path / "nan.amc"
    nan.write_text(text.replace("lowerback 7.86573", "lowerback nan", 1))
    _check(nan, "NaN", asf=info.skeleton, fps=120)
    unknown = tmp_path / "unknown.amc"
    unknown.write_text(text.replace("lowerback", "tail"))
    _check(unknown, "does not define", asf=info.skeleton, fps=120)
    not_asf = tmp_path / "not.asf"
    not_asf.write_text("hello\n")
    _check(info.path, "not an ASF file", asf=not_asf, fps=120)


def test_unknown_format(tmp_path: Path) -> None:
    path = tmp_path / "motion.fbx"
    path.write_text("x")
    _check(path, "unknown motion format")


def test_errors_are_motion_format_errors(tmp_path: Path) -> None:
    with pytest.raises(MotionFormatError):
        import_clip(tmp_path / "nope.bvh", rig="bandai", fps=30)
