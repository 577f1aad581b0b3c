"""`physmotion render` as a user runs it: GIF / MP4 / PNG of imported motions, side by side or overlaid."""

import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from physmotion.motion import Motion
from physmotion.render import CONTACT_COLOUR, RESET_COLOUR, motion_contacts, short_labels
from tests.cli_runner import invoke

BANDAI_WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"


def run(*args: object) -> subprocess.CompletedProcess:
    """``physmotion ARGS...`` in this process (see tests/cli_runner.py)."""
    return invoke(*args)


@pytest.fixture(scope="module")
def walk(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The Bandai walk imported at its true 30 fps (stored at 20 fps), as a user would."""
    out = tmp_path_factory.mktemp("render") / "walk.npz"
    res = run("import", mocap_dir / BANDAI_WALK, "-o", out, "--rig", "bandai", "--fps", "30")
    assert res.returncode == 0, res.stderr
    return out


def _contact_pixels(path: Path, above: int) -> int:
    """Pixels of the contact colour in the rows above ``above``."""
    pixels = np.asarray(Image.open(path).convert("RGB"))[:above]
    return int(np.all(pixels == CONTACT_COLOUR, axis=-1).sum())


def test_gif_side_by_side_resamples_to_the_highest_rate_and_holds_the_shorter(
    walk: Path, tmp_path: Path
) -> None:
    motion = Motion.load(walk)
    short = motion.joints[:40]  # 2 s at 20 fps
    # The same 2 s at 30 fps (linear interpolation), saved as another file of another rate.
    t30 = np.arange(0, 39 / 20 + 1e-9, 1 / 30) * 20
    lo = np.floor(t30).astype(int)
    w = (t30 - lo)[:, None, None]
    joints30 = (1 - w) * short[lo] + w * short[np.minimum(lo + 1, 39)]
    Motion(joints=joints30, fps=30.0).save(tmp_path / "a" / "walk.npz")
    Motion(joints=short[:20], fps=20.0).save(tmp_path / "b" / "walk.npz")  # 1 s: holds its last frame
    out = tmp_path / "cmp.gif"
    res = run("render", tmp_path / "a" / "walk.npz", tmp_path / "b" / "walk.npz", "-o", out)
    assert res.returncode == 0, res.stderr
    gif = Image.open(out)
    assert gif.size == (960, 480)
    assert gif.n_frames == len(joints30) == 59  # 30 fps over the longer motion's 1.95 s
    assert abs(gif.info["duration"] - 1000 / 30) < 5  # GIF keeps hundredths of a second: 30 ms
    assert "59 frame(s) at 30 fps, 960x480 px" in res.stdout
    # The 1 s motion stops moving after its last frame: its panel's last two frames are the same picture.
    gif.seek(57)
    before = np.asarray(gif.convert("RGB"))[:, 480:]
    gif.seek(58)
    after = np.asarray(gif.convert("RGB"))[:, 480:]
    moving = np.asarray(gif.convert("RGB"))[:, :480]
    gif.seek(57)
    assert np.array_equal(before[40:440], after[40:440])  # the counter line at the bottom differs
    assert not np.array_equal(np.asarray(gif.convert("RGB"))[40:440, :480], moving[40:440])


def test_contacts_are_marked_on_contact_frames_only(walk: Path, tmp_path: Path) -> None:
    motion = Motion.load(walk)
    joints = motion.joints[:60].copy()
    joints[:20, :, 1] += 0.5  # a jump: the whole body half a metre up for the first second
    lifted = tmp_path / "lifted.npz"
    Motion(joints=joints, fps=motion.fps).save(lifted)
    contacts = motion_contacts(Motion.load(lifted))
    # the lifted second: no contact at all; on the floor: a foot down in nearly every frame (the import floor,
    # least Penetrate + Float, leaves a few frames' soles just over the contact band)
    assert not contacts[:20].any() and contacts[20:].any(axis=1).mean() > 0.9
    down = 20 + int(np.flatnonzero(contacts[20:].any(axis=1))[10])  # a frame with a foot down
    for frame, expect in ((10, False), (down, True)):
        out = tmp_path / f"f{frame}.png"
        res = run("render", lifted, "--frame", frame, "-o", out)
        assert res.returncode == 0, res.stderr
        assert Image.open(out).size == (480, 480)
        dots = _contact_pixels(out, above=450)  # the key at the bottom shows a dot on every frame
        assert (dots > 100) == expect and (dots == 0) != expect, (frame, dots, contacts[frame])


def test_frames_p_did_not_simulate_are_marked(walk: Path, tmp_path: Path) -> None:
    """A motion whose record marks frames 10-15 as not simulated (a reset and its cross-fade): those
    frames carry the words in the reset colour, the others do not, side by side and overlaid."""
    motion = Motion.load(walk)
    marked = np.zeros(motion.num_frames, dtype=bool)
    marked[10:16] = True
    reset = tmp_path / "reset.npz"
    replace(motion, reset_frames=marked).save(reset)
    for layout in ("side", "overlay"):
        for frame, expect in ((12, True), (30, False)):
            out = tmp_path / f"{layout}{frame}.png"
            res = run("render", reset, walk, "--layout", layout, "--frame", frame, "-o", out)
            assert res.returncode == 0, res.stderr
            red = int(np.all(np.asarray(Image.open(out).convert("RGB")) == RESET_COLOUR, axis=-1).sum())
            assert (red > 30) == expect and (red == 0) != expect, (layout, frame, red)


def test_overlay_png_of_a_bvh_imported_on_the_fly(mocap_dir: Path, walk: Path, tmp_path: Path) -> None:
    out = tmp_path / "overlay.png"
    res = run("render", mocap_dir / BANDAI_WALK, walk, "--layout", "overlay", "--frame", "0", "-o", out,
              "--rig", "bandai", "--fps", "30")  # fmt: skip
    assert res.returncode == 0, res.stderr
    image = np.asarray(Image.open(out).convert("RGB"))
    assert image.shape == (480, 480, 3)
    # The same motion twice: the second colour (blue) is drawn over the first, and both legend swatches show.
    assert np.all(image == (60, 90, 200), axis=-1).sum() > 500
    assert np.all(image[:80, :40] == (200, 60, 60), axis=-1).sum() > 50


def test_mp4_has_every_frame(walk: Path, tmp_path: Path) -> None:
    import av

    short = tmp_path / "short.npz"
    motion = Motion.load(walk)
    replace(motion, joints=motion.joints[:30], rotations=None, offsets=None).save(short)
    out = tmp_path / "clip.mp4"
    res = run("render", short, short, "-o", out, "--size", "320")
    assert res.returncode == 0, res.stderr
    with av.open(str(out)) as container:
        frames = [f for f in container.decode(video=0)]
    assert len(frames) == 30
    assert (frames[0].width, frames[0].height) == (640, 320)


def _bad_inputs(tmp: Path, walk: Path) -> dict[str, Path]:
    nan = Motion.load(walk).joints.copy()
    nan[3, 5, 1] = np.nan
    np.savez(tmp / "nan.npz", joints=nan, fps=np.float32(20))
    (tmp / "notes.npz").write_text("not a zip file")
    (tmp / "walk.txt").write_text("a person walks")
    return {"missing": tmp / "missing.npz", "not_npz": tmp / "notes.npz", "nan": tmp / "nan.npz",
            "wrong_suffix": tmp / "walk.txt"}  # fmt: skip


@pytest.mark.parametrize("case", ["missing", "not_npz", "nan", "wrong_suffix", "bad_output", "png_without_frame",
                                  "frame_out_of_range", "bad_layout"])  # fmt: skip
def test_bad_input_is_one_line_and_writes_nothing(case: str, walk: Path, tmp_path: Path) -> None:
    bad = _bad_inputs(tmp_path, walk)
    out_dir = tmp_path / "out"
    args: list[object] = {
        "bad_output": [walk, "-o", out_dir / "x.jpg"],
        "png_without_frame": [walk, "-o", out_dir / "x.png"],
        "frame_out_of_range": [walk, "--frame", "100000", "-o", out_dir / "x.png"],
        "bad_layout": [walk, "--layout", "grid", "-o", out_dir / "x.gif"],
    }.get(case, [walk, bad.get(case), "-o", out_dir / "x.gif"])
    res = run("render", *args)
    assert res.returncode == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    assert not out_dir.exists() or list(out_dir.iterdir()) == []


def test_labels_are_the_shortest_unique_path_suffix() -> None:
    assert short_labels(["x/a/walk.npz", "x/b/walk.npz", "run.npz"]) == [
        "a/walk.npz",
        "b/walk.npz",
        "run.npz",
    ]
    assert short_labels(["p/q/m.npz", "r/q/m.npz"]) == ["p/q/m.npz", "r/q/m.npz"]


def test_generate_preview_keeps_one_frame_per_motion_frame(walk: Path, tmp_path: Path) -> None:
    from physmotion.render import save_gif

    joints = Motion.load(walk).joints[:25]
    save_gif(tmp_path / "p.gif", joints, 20.0, title="a person walks forward")
    gif = Image.open(tmp_path / "p.gif")
    assert gif.n_frames == 25 and gif.size == (320, 320)


def test_existing_output_is_refused_without_overwrite(walk: Path, tmp_path: Path) -> None:
    out = tmp_path / "still.png"
    assert run("render", walk, "--frame", "0", "-o", out).returncode == 0
    before = out.read_bytes()
    res = run("render", walk, "--frame", "5", "-o", out)
    assert res.returncode == 1 and res.stderr.strip().startswith("error:") and "--overwrite" in res.stderr
    assert out.read_bytes() == before
    res = run("render", walk, "--frame", "5", "-o", out, "--overwrite")
    assert res.returncode == 0, res.stderr
    assert out.read_bytes() != before
