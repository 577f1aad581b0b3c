"""The commands that read motion files, as a user runs them: ``import --overwrite``, ``--mapping`` wherever a
.bvh is accepted, ``metrics`` on what ``render`` takes, shipped model names for ``--model``."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from physmotion.motion import Motion

REPO = Path(__file__).resolve().parents[1]
BANDAI_WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"
MAPPING = REPO / "docs" / "examples" / "mapping_bandai.json"
BVH_COMMANDS = ("import", "metrics", "render", "view", "refine")


def run(*args: object) -> subprocess.CompletedProcess:
    """``physmotion ARGS...`` in this process through the console script's ``main`` (errors as one line)."""
    from physmotion.cli import main

    out, err = io.StringIO(), io.StringIO()
    argv, shown = sys.argv, warnings.showwarning
    sys.argv = ["physmotion", *map(str, args)]
    code = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
            try:
                main()
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        sys.argv, warnings.showwarning = argv, shown
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


@pytest.mark.parametrize("command", BVH_COMMANDS)
def test_every_command_that_reads_a_bvh_takes_a_mapping(command: str) -> None:
    res = run(command, "--help")
    assert res.returncode == 0 and "--mapping" in res.stdout and "--rig" in res.stdout, res.stdout


def test_import_refuses_to_overwrite_without_the_flag(mocap_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "walk.npz"
    assert run("import", mocap_dir / BANDAI_WALK, "-o", out, "--rig", "bandai", "--fps", "30").returncode == 0
    before, frames = out.read_bytes(), Motion.load(out).num_frames
    res = run("import", mocap_dir / BANDAI_WALK, "-o", out, "--rig", "bandai", "--fps", "15")
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 1 and len(lines) == 1 and "--overwrite" in lines[0], res.stderr
    assert out.read_bytes() == before
    res = run("import", mocap_dir / BANDAI_WALK, "-o", out, "--rig", "bandai", "--fps", "15", "--overwrite")
    assert res.returncode == 0, res.stderr
    assert abs(Motion.load(out).num_frames - 2 * frames) <= 2  # replaced by the import at half the rate


def test_import_says_where_it_levelled_a_tilted_floor(mocap_dir: Path, tmp_path: Path) -> None:
    """CMU subject 7's floor rises 1.9 cm a metre (docs/decisions/data.md, "a tilted capture floor
    levelled"): the summary line says it was levelled; a Bandai walk's floor is level and says nothing."""
    walk = mocap_dir / "cmu_iclone/subjects/007/007_04.bvh"
    res = run("import", walk, "-o", tmp_path / "a.npz", "--no-preview")
    assert res.returncode == 0 and "its capture floor, tilted 1.1 degrees, levelled" in res.stdout, res.stderr
    res = run("import", mocap_dir / BANDAI_WALK, "-o", tmp_path / "b.npz", "--no-preview")
    assert res.returncode == 0 and "wrote" in res.stdout and "tilted" not in res.stdout, res.stderr


def test_metrics_takes_a_bvh_as_render_does(mocap_dir: Path, tmp_path: Path) -> None:
    """A .bvh with --rig/--fps, or --mapping, gives the metrics of its import; a fresh import has
    Penetrate under 2 mm by the metrics' own measure."""
    npz = tmp_path / "walk.npz"
    assert run("import", mocap_dir / BANDAI_WALK, "-o", npz, "--rig", "bandai", "--fps", "30").returncode == 0
    results = {}
    for name, extra in {"npz": [npz], "rig": [mocap_dir / BANDAI_WALK, "--rig", "bandai", "--fps", "30"],
                        "mapping": [mocap_dir / BANDAI_WALK, "--mapping", MAPPING]}.items():  # fmt: skip
        res = run("metrics", *extra, "--json")
        assert res.returncode == 0, res.stderr
        results[name] = json.loads(res.stdout)["files"][0]["metrics"]
    for name in ("rig", "mapping"):
        for key, value in results["npz"].items():
            assert results[name][key] == pytest.approx(value, rel=1e-4, abs=1e-4), (name, key)
    assert results["npz"]["penetrate"] < 2.0
    res = run("metrics", tmp_path / "missing.bvh")
    assert res.returncode == 1 and res.stderr.count("\n") == 1 and "no such file" in res.stderr


def test_render_view_refine_take_a_mapping(mocap_dir: Path, tmp_path: Path) -> None:
    walk = mocap_dir / BANDAI_WALK
    res = run("render", walk, "--mapping", MAPPING, "--frame", "10", "--size", "128", "-o", tmp_path / "w.png")
    assert res.returncode == 0 and (tmp_path / "w.png").stat().st_size > 0, res.stderr
    res = run("view", walk, "--mapping", MAPPING, "-o", tmp_path / "w.html")
    assert res.returncode == 0 and (tmp_path / "w.html").stat().st_size > 0, res.stderr
    res = run("refine", walk, "--mapping", MAPPING, "--strength", "0", "-o", tmp_path / "r.npz")
    assert res.returncode == 0, res.stderr
    refined = Motion.load(tmp_path / "r.npz")
    assert refined.licence_tag == "NC,SA"  # the Bandai clip's NC travels, and the model's NC and SA
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    for command, extra in (("render", ["-o", tmp_path / "x.gif"]), ("view", ["-o", tmp_path / "x.html"]),
                           ("refine", ["-o", tmp_path / "x.npz"]), ("metrics", [])):  # fmt: skip
        res = run(command, walk, "--mapping", bad, *extra)
        lines = res.stderr.strip().splitlines()
        assert res.returncode == 1 and len(lines) == 1 and "mapping" in lines[0], (command, res.stderr)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("x.")]


def test_shipped_models_by_name_from_any_folder(mocap_dir: Path, tmp_path: Path, monkeypatch) -> None:
    """``--model base`` (the shipped base model's name) works outside the repository, as ``morph`` and
    ``default`` (both the default model) do."""
    monkeypatch.chdir(tmp_path)
    res = run("generate", "a person walks forward", "--model", "base", "--seconds", "2", "--physics", "none",
              "--steps", "2", "--no-preview", "-o", "out")  # fmt: skip
    assert res.returncode == 0, res.stderr
    log = json.loads((tmp_path / "out" / "generate.json").read_text())
    assert "weights/base" in log["runs"][-1]["model"]
    walk = mocap_dir / BANDAI_WALK
    res = run("refine", walk, "--rig", "bandai", "--fps", "30", "--model", "base", "--strength", "0", "-o", "r.npz")
    assert res.returncode == 0, res.stderr
    res = run("generate", "a person walks", "--model", "no_such_model", "--no-preview", "-o", "out2")
    assert res.returncode == 1 and res.stderr.count("\n") == 1 and "no_such_model" in res.stderr
    assert np.isfinite(Motion.load(tmp_path / "r.npz").joints).all()


def test_refine_keeps_every_licence_tag(tmp_path: Path) -> None:
    """An HDM05 clip (SA) refined by the shipped model (trained on NC data): both tags travel."""
    from physmotion.io import import_clip, load_manifest

    hdm05 = REPO / ".." / "shared" / "data" / "hdm05"
    info = next(c for c in load_manifest(hdm05) if "lieDownFloor" in c.clip)  # long enough to refine
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import_clip(info).save(tmp_path / "lie.npz")
    assert Motion.load(tmp_path / "lie.npz").licence_tag == "SA"
    res = run("refine", tmp_path / "lie.npz", "--strength", "0", "-o", tmp_path / "r.npz")
    assert res.returncode == 0, res.stderr
    assert Motion.load(tmp_path / "r.npz").licence_tag == "NC,SA"
