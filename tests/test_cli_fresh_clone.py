"""What a new user met on a fresh clone (issue 62, item 7), run through the console script's ``main`` in
this process (tests/cli_runner.py): outputs written by suffix or refused, unwritable outputs refused before
any work, load errors that name the file, user text printed as typed (no emoji, no markup), options named
as typed, a bounded --cfg-scale, and -o folders not named like files."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from physmotion.diffusion.samplers import SamplerConfig
from physmotion.errors import PhysmotionError
from physmotion.io.importer import import_clip
from physmotion.motion import Motion
from tests.cli_runner import invoke

BANDAI_WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"
CHEAP = ("--seconds", "2", "--steps", "5", "--physics", "none", "--no-preview")


def one_line_error(res: subprocess.CompletedProcess) -> str:
    """The single ``error: ...`` line of a refused command (exit 1, no traceback)."""
    assert res.returncode == 1, (res.stdout, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    return lines[0]


def _boom(*args: object, **kwargs: object) -> None:
    raise AssertionError("the work started before the output was checked")


@pytest.fixture(scope="module")
def walk_npz(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real Bandai walk (182 frames at 20 fps) imported through the CLI."""
    out = tmp_path_factory.mktemp("walk") / "walk.npz"
    res = invoke("import", mocap_dir / BANDAI_WALK, "-o", out)
    assert res.returncode == 0, res.stderr
    return out


# ------------------------------------------------------------------------------------------------
# a. project writes by suffix, as export does; unknown suffixes are refused before any work


def test_project_to_bvh_writes_a_bvh(walk_npz: Path, tmp_path: Path) -> None:
    out = tmp_path / "walk_p.bvh"
    res = invoke("project", walk_npz, "-o", out)
    assert res.returncode == 0, res.stderr
    assert out.read_text().startswith("HIERARCHY")  # a BVH, not an .npz under a .bvh name
    back = import_clip(out, rig="smpl22")
    assert back.num_frames == Motion.load(walk_npz).num_frames
    assert np.all(np.isfinite(back.joints))


WORK = {"project": "physmotion.physics.files.project_file", "export": "physmotion.motion.Motion.load",
        "import": "physmotion.io.importer.import_clip", "refine": "physmotion.diffusion.model.MotionDiffusion.load"}


@pytest.mark.parametrize("command", list(WORK))
def test_unknown_output_suffix_is_refused_before_work(command: str, walk_npz: Path, mocap_dir: Path,
                                                      tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(WORK[command], _boom)
    source = mocap_dir / BANDAI_WALK if command == "import" else walk_npz
    out = tmp_path / "walk.txt"
    line = one_line_error(invoke(command, source, "-o", out))
    assert line == f"error: {out}: unknown output format '.txt': use .bvh or .glb or .npz"
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------------------------
# b. an output nobody can write is refused in one line, before any work, with nothing left behind


# (command's arguments with {src}, {bvh}, {out}; output suffix or "" for a folder; the work to trap)
UNWRITABLE = {
    "generate": (("generate", "a person walks forward", *CHEAP, "-o", "{out}"), "",
                 "physmotion.diffusion.model.MotionDiffusion.load"),
    "project": (("project", "{src}", "-o", "{out}"), ".npz", "physmotion.physics.files.project_file"),
    "export": (("export", "{src}", "-o", "{out}"), ".bvh", "physmotion.motion.Motion.load"),
    "render": (("render", "{src}", "-o", "{out}"), ".gif", "physmotion.render.render_files"),
    "view": (("view", "{src}", "-o", "{out}"), ".html", "physmotion.viewer.view_files"),
    "metrics": (("metrics", "{src}", "-o", "{out}"), ".json", "physmotion.render.load_motion"),
    "import": (("import", "{bvh}", "-o", "{out}"), ".npz", "physmotion.io.importer.import_clip"),
    "refine": (("refine", "{src}", "-o", "{out}"), ".npz", "physmotion.diffusion.model.MotionDiffusion.load"),
}  # fmt: skip


@pytest.mark.parametrize("where", ["/proc/physmotion_test/out", "/sys/x"])
@pytest.mark.parametrize("command", list(UNWRITABLE))
def test_unwritable_output_is_refused_before_work(command: str, where: str, walk_npz: Path, mocap_dir: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:  # fmt: skip
    args, suffix, work = UNWRITABLE[command]
    monkeypatch.setattr(work, _boom)
    out = where + suffix
    given = [a.format(src=walk_npz, bvh=mocap_dir / BANDAI_WALK, out=out) for a in args]
    line = one_line_error(invoke(*given))
    assert line.startswith(f"error: cannot write {out}") and "is not writable" in line, line
    assert not Path(out).exists()


# ------------------------------------------------------------------------------------------------
# c, e. a file that is not a motion .npz, or one with NaN or no frames: one line naming the file


@pytest.mark.parametrize("name", ["notes.txt", "clip.gif", "walk.bvh"])
def test_non_npz_input_names_the_file_without_pickle_advice(name: str, mocap_dir: Path, tmp_path: Path) -> None:
    src = tmp_path / name
    if name == "walk.bvh":
        src.write_bytes((mocap_dir / BANDAI_WALK).read_bytes())
    elif name == "clip.gif":
        src.write_bytes(b"GIF89a" + bytes(range(256)) * 4)
    else:
        src.write_text("a person walks forward\n")
    line = one_line_error(invoke("project", src, "-o", tmp_path / "out.npz"))
    assert line.startswith(f"error: {src}: not a motion .npz"), line
    assert "pickle" not in line
    assert ("physmotion import" in line) == (name == "walk.bvh")
    assert not (tmp_path / "out.npz").exists()


@pytest.mark.parametrize("case", ["nan", "zero_frames", "zero_fps"])
def test_bad_npz_errors_name_the_file(case: str, walk_npz: Path, tmp_path: Path) -> None:
    joints = Motion.load(walk_npz).joints.copy()
    fps = 20.0
    if case == "nan":
        joints[5, 3, 1] = np.nan
    elif case == "zero_frames":
        joints = joints[:0]
    else:
        fps = 0.0
    src = tmp_path / f"{case}.npz"
    np.savez(src, joints=joints, fps=np.float32(fps))
    for args in (("export", src, "-o", tmp_path / "x.bvh"), ("metrics", src)):
        line = one_line_error(invoke(*args))
        assert line.startswith(f"error: {src}: "), line
    assert not (tmp_path / "x.bvh").exists()


# ------------------------------------------------------------------------------------------------
# d. user text and paths are printed as typed: rich reads neither emoji codes nor markup in them


def test_paths_print_as_typed(walk_npz: Path, tmp_path: Path) -> None:
    for name in ("run:fire:1/m.npz", "[bold]b[/bold].npz", "end:end:.npz"):
        out = tmp_path / name
        res = invoke("export", walk_npz, "-o", out)
        assert res.returncode == 0, res.stderr
        assert res.stdout.strip() == f"wrote {out}", res.stdout
    res = invoke("metrics", tmp_path / "run:fire:1/m.npz", tmp_path / "end:end:.npz", "--surface", "joints")
    assert res.returncode == 0, res.stderr
    assert "m.npz" in res.stdout and "end:end:.npz" in res.stdout
    assert "\U0001f51a" not in res.stdout and "\U0001f525" not in res.stdout  # rich's :end: and :fire:


# ------------------------------------------------------------------------------------------------
# f. range errors name the option as typed, not the config field behind it


@pytest.mark.parametrize(
    "args, option",
    [
        (("project", "{src}", "-o", "{tmp}/p.npz", "--ilc", "-1"), "--ilc"),
        (("project", "{src}", "-o", "{tmp}/p.npz", "--controller", "bogus"), "--controller"),
        (("project", "{src}", "-o", "{tmp}/p.npz", "--preset", "sampling", "--ilc", "2"), "--ilc"),
        (("refine", "{src}", "-o", "{tmp}/r.npz", "--smooth-hz", "30"), "--smooth-hz"),
        (("refine", "{src}", "-o", "{tmp}/r.npz", "--anchor-hz", "30"), "--anchor-hz"),
        (("refine", "{src}", "-o", "{tmp}/r.npz", "--strength", "3"), "--strength"),
        (("generate", "walk", "-o", "{tmp}/g", "--eta", "3"), "--eta"),
        (("generate", "walk", "-o", "{tmp}/g", "--steps", "0"), "--steps"),
        (("generate", "walk", "-o", "{tmp}/g", "--phys-scale", "-1"), "--phys-scale"),
        (("generate", "walk", "-o", "{tmp}/g", "--speed", "9"), "--speed"),
        (("morph", "synth", "--data", "{tmp}", "-o", "{tmp}/s", "--ilc", "-1"), "--ilc"),
        (("morph", "run", "--model", "base", "--data", "{tmp}", "-o", "{tmp}/m", "--rounds", "1", "--ilc", "-1"),
         "--ilc"),
    ],
)  # fmt: skip
def test_range_errors_name_the_option(args: tuple[str, ...], option: str, walk_npz: Path, tmp_path: Path) -> None:
    line = one_line_error(invoke(*(a.format(src=walk_npz, tmp=tmp_path) for a in args)))
    assert line.startswith(f"error: {option} "), line
    assert "_" not in line.split(" must")[0], line  # no field name (ilc_passes, smooth_hz) before "must"
    assert "reset_on_fail" not in line and "ilc_passes" not in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------------------------
# g. --cfg-scale within 0..10


@pytest.mark.parametrize("scale", ["-100", "-0.5", "10.5", "nan"])
@pytest.mark.parametrize("command", ["generate", "evaluate"])
def test_cfg_scale_out_of_range_is_refused(command: str, scale: str, tmp_path: Path) -> None:
    args = (("generate", "walk", "-o", tmp_path / "g") if command == "generate"
            else ("evaluate", "--data", tmp_path, "-o", tmp_path / "ev"))  # fmt: skip
    line = one_line_error(invoke(*args, "--cfg-scale", scale))
    assert line.startswith("error: --cfg-scale must be between 0 and 10"), line
    assert list(tmp_path.iterdir()) == []


def test_sampler_config_bounds_cfg_scale() -> None:
    for ok in (0.0, 1.0, 2.5, 10.0):
        SamplerConfig(cfg_scale=ok).check()
    for bad in (-100.0, -1e-3, 10.001, float("inf")):
        with pytest.raises(PhysmotionError, match="cfg_scale must be between 0 and 10"):
            SamplerConfig(cfg_scale=bad).check()


# ------------------------------------------------------------------------------------------------
# h. an -o that is a folder, named like a file, is refused and not made


@pytest.mark.parametrize("name", ["foo.npz", "foo.bvh", "foo.json", "foo.gif"])
def test_generate_out_named_like_a_file_is_refused(name: str, tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:  # fmt: skip
    from physmotion.diffusion.model import MotionDiffusion

    monkeypatch.setattr(MotionDiffusion, "load", _boom)
    out = tmp_path / name
    line = one_line_error(invoke("generate", "a person walks forward", *CHEAP, "-o", out))
    assert line == f"error: {out}: -o names a folder here, not a {out.suffix} file; give a folder name"
    assert not out.exists()


def test_folder_outputs_named_like_files_are_refused(walk_npz: Path, small_mocap_dir: Path, tmp_path: Path) -> None:
    """The same for every -o that is a folder: project with several inputs, data build."""
    walk2 = tmp_path / "in" / "walk2.npz"
    Motion.load(walk_npz).save(walk2)
    for args in (("project", walk_npz, walk2, "-o", tmp_path / "both.npz"),
                 ("data", "build", "--source", small_mocap_dir, "-o", tmp_path / "data.json")):  # fmt: skip
        line = one_line_error(invoke(*args))
        assert "-o names a folder here" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_existing_folder_with_a_dot_and_cfg_scale_ends_work(tmp_path: Path) -> None:
    """Only a *new* folder named like a file is refused: one the user made keeps working. And the ends
    of --cfg-scale's range are accepted."""
    out = tmp_path / "run.json"
    out.mkdir()
    res = invoke("generate", "a person walks forward", *CHEAP, "--cfg-scale", "10", "-o", out)
    assert res.returncode == 0, res.stderr
    assert (out / "generate.json").is_file() and len(list(out.glob("*.npz"))) == 1
