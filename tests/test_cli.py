"""The command line, run as a user runs it: its exit code, stdout/stderr and files. The commands run in
the test process (tests/cli_runner.py); tests/test_cli_process.py checks a real process agrees."""

import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from physmotion.motion import Motion
from tests.cli_runner import invoke

BANDAI_WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"


def run(*args: object) -> subprocess.CompletedProcess:
    """``physmotion ARGS...`` in this process (see tests/cli_runner.py)."""
    return invoke(*args)


def _bad_bvh_files(mocap_dir: Path, tmp: Path) -> dict[str, Path]:
    text = (mocap_dir / BANDAI_WALK).read_text()
    head, motion = text.split("MOTION", 1)
    lines = motion.strip().splitlines()
    files = {
        "missing": tmp / "does_not_exist.bvh",
        "truncated": tmp / "truncated.bvh",
        "not_bvh": tmp / "notes.bvh",
        "zero_frames": tmp / "zero.bvh",
        "nan": tmp / "nan.bvh",
    }
    files["truncated"].write_text(head + "MOTION\n" + "\n".join(lines[: len(lines) // 2]) + " 1.0 2.")
    files["not_bvh"].write_text("This is a shopping list.\nmilk\neggs\n")
    files["zero_frames"].write_text(head + "MOTION\nFrames: 0\nFrame Time: 0.0333333\n")
    body = lines[3].split()
    body[5] = "nan"
    files["nan"].write_text(head + "MOTION\n" + "\n".join(lines[:3] + [" ".join(body)] + lines[4:]) + "\n")
    return files


@pytest.mark.parametrize("case", ["missing", "truncated", "not_bvh", "zero_frames", "nan"])
def test_bad_input_is_one_line_no_traceback_no_output(case: str, mocap_dir: Path, tmp_path: Path) -> None:
    bad = _bad_bvh_files(mocap_dir, tmp_path)[case]
    out = tmp_path / "out" / "motion.npz"
    res = run("import", bad, "-o", out, "--rig", "bandai", "--fps", "30")
    assert res.returncode == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists()
    leftovers = list((tmp_path / "out").iterdir()) if (tmp_path / "out").exists() else []
    assert leftovers == []


def test_import_then_export_bvh_then_import_again(mocap_dir: Path, tmp_path: Path) -> None:
    npz, bvh, again = tmp_path / "walk.npz", tmp_path / "walk.bvh", tmp_path / "again.npz"
    assert run("import", mocap_dir / BANDAI_WALK, "-o", npz, "--rig", "bandai", "--fps", "30").returncode == 0
    res = run("export", npz, "-o", bvh)
    assert res.returncode == 0, res.stderr
    assert run("import", bvh, "-o", again, "--rig", "smpl22").returncode == 0
    a, b = Motion.load(npz), Motion.load(again)
    assert a.num_frames == b.num_frames
    err = np.linalg.norm(a.joints - b.joints, axis=-1)
    assert err.max() < 1e-3, err.max()


def test_data_build_and_stats(small_mocap_dir: Path, tmp_path: Path) -> None:
    """On the fast tier's few clips (tests/conftest.py SMALL_CLIPS): their CMU ones once NC is left out."""
    mocap_dir = small_mocap_dir
    out = tmp_path / "cmu"
    res = run("data", "build", "--source", mocap_dir, "--out", out, "--exclude-license", "NC")
    assert res.returncode == 0, res.stderr
    assert "built" in res.stdout and (out / "Mean.npy").is_file()
    capture, mirrored = (float(x) for x in re.search(
        r"([\d.]+) min of capture \(([\d.]+) min with mirrored copies\)", res.stdout).groups())  # fmt: skip
    assert mirrored == pytest.approx(2 * capture, abs=0.1)
    res = run("data", "stats", out)
    assert res.returncode == 0, res.stderr
    assert "train" in res.stdout and "vocabulary" in res.stdout and "walk" in res.stdout
    assert "mirrored copies (ids starting with M) included" in res.stdout
    total = float(next(line for line in res.stdout.splitlines() if "│ all" in line).split("│")[3])
    assert total == pytest.approx(mirrored, abs=0.1)  # stats' minutes are the build's with mirrors
    res = run("data", "build", "--source", mocap_dir, "--out", out, "--exclude-license", "NC")
    assert res.returncode == 1 and "--overwrite" in res.stderr  # an earlier build is kept unless asked


def test_data_stats_on_a_missing_folder(tmp_path: Path) -> None:
    res = run("data", "stats", tmp_path / "nothing")
    assert res.returncode == 1 and res.stderr.strip().count("\n") == 0
    assert "no such dataset folder" in res.stderr


def test_metrics_prints_a_table_and_refuses_bad_files(mocap_dir: Path, tmp_path: Path) -> None:
    npz = tmp_path / "walk.npz"
    assert run("import", mocap_dir / BANDAI_WALK, "-o", npz).returncode == 0
    lifted = Motion.load(npz)
    lifted.joints[:, :, 1] += 0.1
    lifted.save(tmp_path / "lifted.npz")
    res = run("metrics", npz, tmp_path / "lifted.npz")
    assert res.returncode == 0, res.stderr
    assert "penetrate" in res.stdout and "lifted.npz" in res.stdout and "PhysDiff" in res.stdout
    # A file that carries the simulated body (generate writes it for projected motions) is measured on
    # that body: here the default humanoid's, whose feet sit otherwise than the walk's fitted ones.
    from physmotion.skeleton import REST_OFFSETS

    walk = Motion.load(npz)
    walk.humanoid = REST_OFFSETS
    walk.save(tmp_path / "with_body.npz")
    res = run("metrics", npz, tmp_path / "with_body.npz")
    row = next(line for line in res.stdout.splitlines() if "penetrate" in line)
    estimated, given = (float(v) for v in re.findall(r"\d+\.\d+", row)[:2])
    assert estimated != given
    (tmp_path / "junk.npz").write_text("junk")
    res = run("metrics", tmp_path / "junk.npz")
    assert res.returncode == 1 and res.stderr.startswith("error: ") and res.stderr.count("\n") == 1


def test_project_writes_the_simulated_motion(mocap_dir: Path, tmp_path: Path) -> None:
    npz, out = tmp_path / "walk.npz", tmp_path / "projected.npz"
    assert run("import", mocap_dir / BANDAI_WALK, "-o", npz).returncode == 0
    short = Motion.load(npz)
    short.joints, short.rotations = short.joints[:60], short.rotations[:60]  # a file's arrays must agree
    short.save(npz)
    res = run("project", npz, "-o", out)
    assert res.returncode == 0, res.stderr
    assert "simulation kept" in res.stdout
    projected = Motion.load(out)
    assert projected.joints.shape == (60, 22, 3) and not np.array_equal(projected.joints, short.joints)
    assert projected.licence_tag == short.licence_tag
    assert projected.humanoid is not None and projected.humanoid.shape == (22, 3)  # for `metrics`
    # The root residual P applied is in the file, and `metrics` shows it (force in body weights).
    assert projected.residual is not None and projected.residual.shape == (60, 2)
    assert np.all(projected.residual >= 0.0) and projected.residual[:, 0].max() <= 0.3 + 1e-6
    res = run("metrics", out, "--json")
    shown = json.loads(res.stdout)["files"][0]["metrics"]
    assert shown["residual_force"] == pytest.approx(float(projected.residual[:, 0].mean()), rel=1e-5)
    assert shown["residual_force_p95"] >= shown["residual_force"]
    # The file records the plain preset's 0.2 W cap and the torque-limit flags: `metrics` gives both shares.
    assert projected.residual_cap == pytest.approx(0.2) and projected.over_limit.shape == (60,)
    # at a cap: any residual update of the frame held at the force, lift or torque cap (issue 62's "help in
    # full"), never fewer frames than the mean force's own cap shows
    assert shown["residual_at_cap"] == pytest.approx(float(projected.residual_at_cap.mean()))
    assert shown["residual_at_cap"] >= float(np.mean(projected.residual[:, 0] >= 0.99 * 0.2))
    assert shown["over_limit"] == pytest.approx(float(projected.over_limit.mean()))
    assert "residual_force" not in json.loads(run("metrics", npz, "--json").stdout)["files"][0]["metrics"]
    # Iterative learning control keeps the pass closest to the input: never further than the plain one.
    plain_mm = int(re.search(r"MPJPE mean (\d+) mm", run("project", npz, "-o", out, "--overwrite").stdout)[1])
    res = run("project", npz, "-o", tmp_path / "ilc.npz", "--ilc", "2")
    assert res.returncode == 0, res.stderr
    assert int(re.search(r"MPJPE mean (\d+) mm", res.stdout)[1]) <= plain_mm
    assert Motion.load(tmp_path / "ilc.npz").joints.shape == (60, 22, 3)
    # The finer simulation step is another simulation of the same motion, kept as the plain one is.
    res = run("project", npz, "-o", tmp_path / "fine.npz", "--fine-step")
    assert res.returncode == 0, res.stderr
    assert "simulation kept" in res.stdout
    fine = Motion.load(tmp_path / "fine.npz")
    assert fine.joints.shape == (60, 22, 3) and not np.array_equal(fine.joints, Motion.load(out).joints)
    res = run("project", npz, "-o", tmp_path / "bad.npz", "--ilc", "-1")
    assert res.returncode == 1 and res.stderr.startswith("error: --ilc ") and res.stderr.count("\n") == 1
    assert not (tmp_path / "bad.npz").exists()
    res = run("project", tmp_path / "missing.npz", "-o", tmp_path / "x.npz")
    assert res.returncode == 1 and res.stderr.startswith("error: ") and not (tmp_path / "x.npz").exists()


def test_project_with_the_search_uses_no_outside_help(mocap_dir: Path, tmp_path: Path) -> None:
    npz, out, teacher = tmp_path / "walk.npz", tmp_path / "searched.npz", tmp_path / "searched.teacher.npz"
    assert run("import", mocap_dir / BANDAI_WALK, "-o", npz).returncode == 0
    short = Motion.load(npz)
    short.joints, short.rotations = short.joints[:24], short.rotations[:24]
    short.save(npz)
    res = run("project", npz, "-o", out, "--controller", "search", "--effort", "fast", "--teacher")
    assert res.returncode == 0, res.stderr
    assert "simulation kept" in res.stdout and "no outside help" in res.stdout
    searched = Motion.load(out)
    assert searched.joints.shape == (24, 22, 3) and searched.licence_tag == short.licence_tag
    assert searched.residual_cap == 0.0 and not np.any(searched.residual) and not searched.over_limit.any()
    records = np.load(teacher)
    steps = records["observations"].shape[0]
    assert records["offsets"].shape == (steps, 63) and steps == 35  # 23 frames at 20 fps -> 1.15 s at 30 Hz
    assert str(records["licence_tag"]) == short.licence_tag
    # Bad requests: one line each, nothing written.
    res = run("project", npz, "-o", tmp_path / "x.npz", "--controller", "search", "--effort", "hardest")
    assert res.returncode == 1 and "unknown search effort" in res.stderr and res.stderr.count("\n") == 1
    res = run("project", npz, "-o", tmp_path / "y.npz", "--teacher")
    assert res.returncode == 1 and "--teacher needs --controller search" in res.stderr
    assert not any((tmp_path / n).exists() for n in ("x.npz", "y.npz", "y.teacher.npz"))


def _help_defaults(*command: str) -> dict[str, str]:
    """``--option -> default`` as the help of a command states them ("(default: X).")."""
    res = run(*command, "--help")
    assert res.returncode == 0, res.stderr
    found: dict[str, str] = {}
    for block in re.split(r"\n\s*(?=(?:-\w, )?--[a-z])", res.stdout):  # one block per option, unwrapped
        flat = " ".join(block.split())
        opt = re.match(r"(?:-\w, )?--([a-z0-9-]+)", flat)
        value = re.search(r"\(default: ([^)]+)\)\.", flat)
        if opt and value:
            found[opt.group(1)] = value.group(1)
    return found


def test_help_defaults_are_the_dataclasses() -> None:
    """Options default to None and the command fills in only what was given: the dataclasses hold every
    default, and the values the help quotes must be theirs."""
    from physmotion.nets.denoiser import DenoiserConfig
    from physmotion.diffusion.train import TrainConfig
    from physmotion.eval.table import EvaluateConfig
    from physmotion.generate import GenerateConfig

    from physmotion.diffusion.samplers import BIOMO_SAMPLER

    gen = GenerateConfig()
    # --seconds left out: each prompt's length is predicted from its text (GenerateConfig(seconds=None))
    expected = {"seconds": "predicted from the text", "physics": gen.physics, "num": gen.num, "seed": gen.seed,
                "sampler": gen.sampler.sampler, "steps": gen.sampler.steps, "eta": gen.sampler.eta,
                "cfg-scale": gen.sampler.cfg_scale, "phys-scale": BIOMO_SAMPLER.phys_scale,
                "speed": gen.sampler.speed, "search-fallback": "on" if gen.projection.fallback else "off",
                "recover": "on" if gen.projection.recover else "off",
                "rescue-flights": "on" if gen.projection.rescue_flight else "off"}  # fmt: skip
    stated = _help_defaults("generate")
    assert set(stated) == set(expected)
    for name, value in expected.items():
        assert stated[name] == (str(value) if not isinstance(value, float) else f"{value:g}"), name

    train, den = TrainConfig(data="", out=""), DenoiserConfig()
    expected = {"arch": den.arch, "d-model": den.d_model, "layers": den.layers, "heads": den.heads,
                "crop": train.crop, "max-length": train.max_length, "batch-size": train.batch_size,
                "steps": train.steps, "lr": train.lr,
                "device": train.device, "seed": train.seed, "checkpoint-minutes": train.checkpoint_minutes,
                "accel-weight": train.accel_weight, "phys-weight": train.phys_weight,
                "emg-weight": train.emg_weight, "phys-drop": train.phys_drop, "vel-weight": train.vel_weight,
                "warmup": train.warmup, "caption-aug": train.caption_aug}  # fmt: skip
    stated = _help_defaults("train", "denoiser")
    assert set(stated) == set(expected)
    for name, value in expected.items():
        assert stated[name] == str(value), name

    ev = EvaluateConfig()
    # the modes with a space after each mode's comma, so that the help wraps between modes, not inside one
    expected = {"split": ev.split, "physics": ", ".join(ev.modes), "repeats": ev.repeats,
                "steps": ev.base.sampler.steps, "seed": ev.seed, "sampler": ev.base.sampler.sampler,
                "eta": ev.base.sampler.eta, "cfg-scale": ev.base.sampler.cfg_scale,
                "search-fallback": "on" if ev.base.projection.fallback else "off",
                "recover": "on" if ev.base.projection.recover else "off",
                "rescue-flights": "on" if ev.base.projection.rescue_flight else "off"}  # fmt: skip
    assert _help_defaults("evaluate") == {k: f"{v:g}" if isinstance(v, float) else str(v)
                                          for k, v in expected.items()}  # fmt: skip


# --- BioMoDiffuse options: data build --features, train denoiser --arch biomo, generate --phys-scale/--speed ---


@pytest.mark.parametrize("option", [("--speed", "2"), ("--phys-scale", "0"), ("--phys-scale", "1.5")])
def test_generate_biomo_options_refused_for_the_default_model(tmp_path: Path, option: tuple[str, str]) -> None:
    out = tmp_path / "out"
    res = run("generate", "a person walks forward", "-o", out, "--no-preview", *option)
    assert res.returncode == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "biomo" in lines[0], res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists() or not list(out.iterdir())


def test_generate_with_a_biomo_model(tiny_biomo_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    common = ["generate", "a person walks forward", "-o", out, "--model", tiny_biomo_dir, "--physics", "none",
              "--no-preview", "--seconds", "2"]  # fmt: skip
    res = run(*common, "--speed", "1.5", "--phys-scale", "0.5")
    assert res.returncode == 0, res.stderr
    motion = Motion.load(next(out.glob("*.npz")))
    assert motion.joints.shape == (40, 22, 3) and np.all(np.isfinite(motion.joints))
    sampler = json.loads((out / "generate.json").read_text())["runs"][-1]["settings"]["sampler"]
    assert (sampler["sampler"], sampler["steps"]) == ("dpmpp-sde", 10)  # the biomo model's default sampler
    assert (sampler["phys_scale"], sampler["speed"]) == (0.5, 1.5)
    for bad in (("--speed", "0"), ("--phys-scale", "-1")):
        res = run(*common, "--overwrite", *bad)
        assert res.returncode == 1 and res.stderr.startswith("error: ") and res.stderr.count("\n") == 1, res.stderr
        assert res.stderr.startswith(f"error: {bad[0]} "), res.stderr  # the option as typed, not its field


def test_train_biomo_on_a_263_build_is_a_one_line_error(built_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    res = run("train", "denoiser", "--data", built_dir, "--out", out, "--arch", "biomo", "--steps", "2")
    assert res.returncode == 1 and "Traceback" not in res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "329" in lines[0], res.stderr
    assert not (out / "model.safetensors").exists()


def test_train_biomo_options(built329_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    res = run("train", "denoiser", "--data", built329_dir, "--out", out, "--arch", "biomo", "--d-model", "32",
              "--layers", "2", "--batch-size", "4", "--crop", "40", "--steps", "2", "--accel-weight", "0.5",
              "--phys-weight", "2", "--emg-weight", "3", "--phys-drop", "0.25")  # fmt: skip
    assert res.returncode == 0, res.stderr
    config = json.loads((out / "config.json").read_text())
    assert config["denoiser"]["arch"] == "biomo" and config["denoiser"]["feature_dim"] == 329
    train = config["info"]["train"]
    weights = (train["accel_weight"], train["phys_weight"], train["emg_weight"], train["phys_drop"])
    assert weights == (0.5, 2, 3, 0.25)
    assert (out / "loss.csv").read_text().splitlines()[0] == "step,loss,diffusion,accel,phys,emg"


def test_train_from_a_model_with_the_velocity_loss(built_dir: Path, tiny_model_dir: Path,
                                                  tmp_path: Path) -> None:  # fmt: skip
    """--init fine-tunes a model folder (its shape, its weights at step 0); --vel-weight logs the term."""
    out = tmp_path / "run"
    common = ["train", "denoiser", "--data", built_dir, "--out", out, "--init", tiny_model_dir]
    res = run(*common, "--layers", "2", "--steps", "2")
    assert res.returncode == 1 and res.stderr.startswith("error: --init") and res.stderr.count("\n") == 1
    assert not out.exists()
    res = run(*common, "--batch-size", "4", "--crop", "40", "--steps", "2", "--vel-weight", "0.5",
              "--warmup", "1")  # fmt: skip
    assert res.returncode == 0, res.stderr
    config = json.loads((out / "config.json").read_text())
    start = json.loads((tiny_model_dir / "config.json").read_text())
    assert config["denoiser"] == start["denoiser"]  # the starting model's shape, not the defaults
    assert config["info"]["init"] == {"model": str(tiny_model_dir), "steps": start["info"]["steps"]}
    assert (config["info"]["train"]["vel_weight"], config["info"]["train"]["warmup"]) == (0.5, 1)
    header, *rows = (out / "loss.csv").read_text().splitlines()
    assert header == "step,loss,diffusion,vel" and rows
    step, loss, diffusion, vel = map(float, rows[-1].split(","))
    assert loss == pytest.approx(diffusion + 0.5 * vel, abs=2e-6) and vel > 0  # loss.csv: 6 decimals


def test_data_build_refuses_other_feature_widths(mocap_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "data"
    res = run("data", "build", "--source", mocap_dir, "--out", out, "--features", "300")
    assert res.returncode == 1 and "Traceback" not in res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "263 or 329" in lines[0], res.stderr
    assert not out.exists() or not list(out.iterdir())


def test_long_work_reports_plain_progress_lines_when_not_on_a_terminal() -> None:
    """Under nohup or CI the bar is not drawn: a plain line a minute at most, none in the first minute."""
    import io

    from physmotion.cli._common import _PlainProgress

    now = [0.0]
    out = io.StringIO()
    tick = _PlainProgress("evaluating", clock=lambda: now[0], stream=out)
    for step, t in enumerate((10.0, 59.0, 61.0, 90.0, 3725.0), start=1):
        now[0] = t
        tick(step * 100, 1000)
    assert out.getvalue().splitlines() == [
        "evaluating: 300/1000, 1:01 elapsed, about 2:22 left",
        "evaluating: 500/1000, 1:02:05 elapsed, about 1:02:05 left",
    ]
