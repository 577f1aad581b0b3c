"""GIF previews beside the outputs of ``import``, ``project`` and ``refine`` (issue 64, item 4): written
after the motion file, atomically, both or neither; ``--no-preview`` skips them; ``project`` and
``refine`` show input and output side by side, the frames P did not simulate marked."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from physmotion.motion import Motion
from physmotion.physics.files import project_file, project_files
from physmotion.physics.projection import ProjectionConfig
from physmotion.render import PREVIEW_SIZE, RESET_COLOUR, preview_path, save_preview
from tests.cli_runner import invoke

BANDAI_WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"
BANDAI_RUN = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_run_normal_001.bvh"


def _gif(path: Path) -> tuple[int, tuple[int, int]]:
    """(frames, (width, height)) of a GIF."""
    with Image.open(path) as im:
        return im.n_frames, im.size


@pytest.fixture(scope="module")
def short_npz(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """A real walk and run imported by the CLI (with their previews: <name>_full.npz), cut to 1 s (20
    frames) as <name>.npz."""
    folder = tmp_path_factory.mktemp("short")
    paths = []
    for name, clip in (("walk", BANDAI_WALK), ("run", BANDAI_RUN)):
        full = folder / f"{name}_full.npz"
        res = invoke("import", mocap_dir / clip, "-o", full, "--rig", "bandai", "--fps", "30")
        assert res.returncode == 0, res.stderr
        motion = Motion.load(full)
        assert _gif(preview_path(full)) == (motion.num_frames, (PREVIEW_SIZE, PREVIEW_SIZE))  # one panel
        replace(motion, joints=motion.joints[:20], rotations=None).save(folder / f"{name}.npz")
        paths.append(folder / f"{name}.npz")
    return paths


def test_import_preview_is_skipped_refused_and_never_half_written(mocap_dir: Path, tmp_path: Path) -> None:
    src = mocap_dir / BANDAI_WALK
    out = tmp_path / "walk.npz"
    res = invoke("import", src, "-o", out, "--no-preview")
    assert res.returncode == 0, res.stderr
    assert out.is_file() and not preview_path(out).exists()
    # A GIF of that name is not clobbered without --overwrite, with or without a preview asked for.
    preview_path(out).write_bytes(b"someone's gif")
    res = invoke("import", src, "-o", tmp_path / "walk.bvh")
    assert res.returncode == 1 and res.stderr.strip() == f"error: {tmp_path / 'walk.gif'} exists; pass --overwrite to replace it"
    assert not (tmp_path / "walk.bvh").exists()
    # --overwrite --no-preview replaces the motion and removes the stale preview of the old one.
    assert invoke("import", src, "-o", out, "--no-preview", "--overwrite").returncode == 0
    assert not preview_path(out).exists()
    # The preview cannot be written (a folder of its name, made after the checks): no motion file either.
    from physmotion.render import save_with_preview

    motion = Motion.load(out)
    preview_path(tmp_path / "x.npz").mkdir()
    with pytest.raises(OSError):
        save_with_preview(motion, tmp_path / "x.npz")
    assert not (tmp_path / "x.npz").exists() and not list(tmp_path.glob(".*.tmp"))


def test_project_preview_shows_input_and_output(short_npz: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "p.npz"
    res = invoke("project", short_npz[0], "-o", out)
    assert res.returncode == 0, res.stderr
    assert f"its preview {preview_path(out)}" in res.stdout
    assert _gif(preview_path(out)) == (20, (2 * PREVIEW_SIZE, PREVIEW_SIZE))  # input | output
    res = invoke("project", short_npz[0], "-o", tmp_path / "q.bvh", "--no-preview")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "q.bvh").is_file() and not (tmp_path / "q.gif").exists()


def test_project_preview_failure_leaves_no_files(short_npz: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "p.npz"
    preview_path(out).mkdir()  # the GIF's rename fails after the motion file is written
    with pytest.raises(OSError):
        project_file(short_npz[0], out, ProjectionConfig(), preview=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.gif"]


def test_project_folder_writes_a_preview_per_output_and_resumes(short_npz: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "projected"
    res = invoke("project", *short_npz, "-o", out, "--workers", "1")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["run.gif", "run.npz", "walk.gif", "walk.npz"]
    walk_npz = (out / "walk.npz").read_bytes()
    # An output whose preview is missing (a run with --no-preview, or killed between the two) gets its
    # preview drawn, not its projection redone.
    (out / "walk.gif").unlink()
    (out / "run.npz").unlink()
    again = project_files(short_npz, out, ProjectionConfig(), workers=1, preview=True)
    assert [r.skipped for r in again] == [True, False]
    assert "its missing preview drawn" in again[0].summary
    assert (out / "walk.npz").read_bytes() == walk_npz
    assert _gif(out / "walk.gif") == (20, (2 * PREVIEW_SIZE, PREVIEW_SIZE))
    assert _gif(out / "run.gif") == (20, (2 * PREVIEW_SIZE, PREVIEW_SIZE))
    # A finished run: nothing left to do.
    assert all(r.skipped and "preview" not in r.summary
               for r in project_files(short_npz, out, ProjectionConfig(), workers=1, preview=True))  # fmt: skip
    assert not list(out.glob(".*.tmp"))


def test_refine_preview_shows_input_and_output(short_npz: list[Path], tmp_path: Path) -> None:
    run = short_npz[1].with_name("run_full.npz")  # refine takes 2 s or more
    out = tmp_path / "r.npz"
    res = invoke("refine", run, "-o", out, "--strength", "0")
    assert res.returncode == 0, res.stderr
    frames = Motion.load(out).num_frames
    assert _gif(preview_path(out)) == (frames, (2 * PREVIEW_SIZE, PREVIEW_SIZE))
    res = invoke("refine", run, "-o", tmp_path / "s.npz", "--strength", "0", "--no-preview")
    assert res.returncode == 0 and not (tmp_path / "s.gif").exists()


def _reset_pixels(frame: Image.Image, panel: int) -> int:
    """Pixels of RESET_COLOUR's words in the top-right corner of panel ``panel`` of a preview frame."""
    rgb = np.asarray(frame.convert("RGB"), dtype=int)
    corner = rgb[: PREVIEW_SIZE // 8, (panel + 1) * PREVIEW_SIZE - PREVIEW_SIZE // 2 : (panel + 1) * PREVIEW_SIZE]
    return int((np.abs(corner - RESET_COLOUR).sum(axis=-1) < 40).sum())


def test_two_motion_preview_marks_the_frames_p_did_not_simulate(short_npz: list[Path], tmp_path: Path) -> None:
    before = Motion.load(short_npz[0])
    marked = np.zeros(before.num_frames, dtype=bool)
    marked[5:9] = True
    after = replace(before, reset_frames=marked)
    save_preview(tmp_path / "p.gif", [before, after], ("input", "output"))
    with Image.open(tmp_path / "p.gif") as gif:
        counts = []
        for k in range(gif.n_frames):
            gif.seek(k)
            counts.append((_reset_pixels(gif, 0), _reset_pixels(gif, 1)))
    assert all(c[0] == 0 for c in counts)  # the input panel has no reset
    assert all((c[1] > 20) == marked[k] for k, c in enumerate(counts)), counts
