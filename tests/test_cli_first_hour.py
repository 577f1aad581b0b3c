"""A user's first hour with the command line (issue 24, part A), run through the console script's ``main``
in this process (tests/cli_runner.py; tests/test_cli_process.py checks the installed script agrees):
metrics of same-named files, unknown-word warnings, output paths checked before any work, run folders that
never clobber, and the small things (--version, -h, -o, limits in the help, warnings)."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from physmotion.conventions import FPS, MAX_FRAMES, MAX_TEXT_TOKENS, MIN_FRAMES
from physmotion.errors import PhysmotionWarning
from physmotion.metrics.report import check_npz, fit_table, path_labels, table_width, to_csv, to_json
from physmotion.motion import Motion
from physmotion.paths import OutputPathError, check_output
from tests.cli_runner import invoke

PHYSMOTION = Path(sys.executable).parent / "physmotion"
BANDAI_WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"
CHEAP = ("--seconds", "2", "--steps", "5", "--physics", "none")


def cli(*args: object, timeout: int = 600, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """The console script's ``main`` as a user types it, in this process with its output captured (so
    rich sees an 80-column non-terminal, as in a pipe); see tests/cli_runner.py. ``timeout`` is kept
    for the callers' sake: an in-process call has none."""
    return invoke(*args, cwd=cwd)


def one_line_error(res: subprocess.CompletedProcess) -> str:
    assert res.returncode == 1, (res.stdout, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    return lines[0]


@pytest.fixture(scope="module")
def walk_npz(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real Bandai walk imported through the CLI."""
    out = tmp_path_factory.mktemp("walk") / "walk.npz"
    res = cli("import", mocap_dir / BANDAI_WALK, "-o", out)
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def three_x(walk_npz: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """a/x.npz and b/x.npz (the walk), c/x.npz (the walk lifted 10 cm): three files of one name."""
    root = tmp_path_factory.mktemp("three")
    walk = Motion.load(walk_npz)
    for name, lift in (("a", 0.0), ("b", 0.0), ("c", 0.1)):
        m = Motion.load(walk_npz)
        m.joints = walk.joints + np.array([0, lift, 0], dtype=np.float32)
        m.save(root / name / "x.npz")
    return root


# ------------------------------------------------------------------------------------------------
# 1. metrics: one column per argument, labelled apart; --json, --csv, -o; .npz only


def test_path_labels_are_the_shortest_unique_suffix() -> None:
    assert path_labels(["a/x.npz", "b/x.npz", "c/x.npz"]) == ["a/x.npz", "b/x.npz", "c/x.npz"]
    assert path_labels(["runs/a/x.npz", "runs/b/x.npz", "y.npz"]) == ["a/x.npz", "b/x.npz", "y.npz"]
    assert path_labels(["p/q/x.npz", "r/q/x.npz"]) == ["p/q/x.npz", "r/q/x.npz"]
    assert path_labels(["x.npz", "./x.npz"]) == ["x.npz", "x.npz#2"]  # the same file twice: two columns
    assert path_labels(["/data/cmu_01_01.npz"]) == ["cmu_01_01.npz"]


def test_check_npz_names_the_file_and_the_fix() -> None:
    assert check_npz("a/x.npz") == Path("a/x.npz")
    with pytest.raises(Exception, match=r"^x\.bvh: metrics expects \.npz; run `physmotion import` first$"):
        check_npz("x.bvh")


def test_fit_table_numbers_columns_only_where_the_labels_do_not_fit() -> None:
    results = {label: {"penetrate": 1.0, "phys_err": 2.5} for label in ("runs/cmu_01_01.npz", "b/cmu_01_01.npz")}
    wide, legend = fit_table(results, "t", 200)
    assert legend == [] and [c.header for c in wide.columns][3:] == list(results)
    numbered, legend = fit_table(results, "t", table_width(wide) - 1)
    assert [c.header for c in numbered.columns] == ["metric", "unit", "paper", "#1", "#2"]
    assert legend == ["#1  runs/cmu_01_01.npz", "#2  b/cmu_01_01.npz"]
    narrow, legend = fit_table(results, "t", table_width(numbered) - 1)
    assert [c.header for c in narrow.columns] == ["metric", "unit", "#1", "#2"]  # no room for the papers
    assert len(legend) == 2 and table_width(narrow) < table_width(numbered) < table_width(wide)


def test_json_and_csv_keep_every_file(three_x: Path) -> None:
    paths = [three_x / n / "x.npz" for n in "abc"]
    from physmotion.metrics import physical_metrics

    results = {label: physical_metrics(Motion.load(p).joints) for p, label in zip(paths, path_labels(paths))}
    data = json.loads(to_json(results, paths, "joints"))
    assert [f["label"] for f in data["files"]] == ["a/x.npz", "b/x.npz", "c/x.npz"]
    assert data["units"]["penetrate"] == "mm" and data["surface"] == "joints"
    rows = list(csv.DictReader(io.StringIO(to_csv(results, paths))))
    assert [r["label"] for r in rows] == ["a/x.npz", "b/x.npz", "c/x.npz"]
    assert float(rows[2]["float"]) > float(rows[0]["float"]) + 50  # lifted 10 cm: floats


def test_cli_metrics_same_named_files_stay_apart(three_x: Path) -> None:
    res = cli("metrics", "a/x.npz", "b/x.npz", "c/x.npz", cwd=three_x)
    assert res.returncode == 0, res.stderr
    out = res.stdout
    assert "…" not in out and max(len(line) for line in out.splitlines()) <= 80  # fits the pipe's 80 columns
    for k, name in enumerate("abc", 1):
        assert f"#{k}  {name}/x.npz" in out  # each file named whole in the legend
    float_row = next(line for line in out.splitlines() if line.startswith("│ float "))
    values = [float(v) for v in float_row.split("│")[3:6]]  # metric, unit, then the three files
    assert values[0] == values[1] < 1.0 and values[2] > 50  # three columns, c's lifted

    res = cli("metrics", *(three_x / n / "x.npz" for n in "abc"), "--json")
    assert res.returncode == 0, res.stderr
    files = json.loads(res.stdout)["files"]
    assert [f["label"] for f in files] == ["a/x.npz", "b/x.npz", "c/x.npz"]

    res = cli("metrics", three_x / "a/x.npz", three_x / "c/x.npz", "--csv")
    assert res.returncode == 0, res.stderr
    assert [r["label"] for r in csv.DictReader(io.StringIO(res.stdout))] == ["a/x.npz", "c/x.npz"]

    target = three_x / "m.csv"
    res = cli("metrics", three_x / "a/x.npz", three_x / "c/x.npz", "-o", target)
    assert res.returncode == 0 and target.read_text().startswith("label,path,penetrate"), res.stderr
    one_line_error(cli("metrics", three_x / "a/x.npz", "-o", target))  # exists, no --overwrite
    assert cli("metrics", three_x / "a/x.npz", "-o", target, "--overwrite").returncode == 0
    assert len(target.read_text().splitlines()) == 2


def test_cli_metrics_takes_a_bvh_and_refuses_other_files_in_one_line(mocap_dir: Path, walk_npz: Path) -> None:
    """A .bvh is imported on the fly, as render does (tests/test_cli_import.py compares the figures); any
    other file is refused before the work, in one line that says what to do."""
    bvh = mocap_dir / BANDAI_WALK
    res = cli("metrics", walk_npz, bvh)
    assert res.returncode == 0 and "penetrate" in res.stdout, res.stderr
    amc = mocap_dir / "cmu_amc" / "subjects" / "02" / "02_01.amc"
    line = one_line_error(cli("metrics", walk_npz, amc))
    assert line == f"error: {amc}: metrics reads .npz or .bvh; run `physmotion import` on other formats"
    assert "allow_pickle" not in line


# ------------------------------------------------------------------------------------------------
# 2. words the model never saw; falls in plain words


def test_vocabulary_words_and_unknown_words() -> None:
    from physmotion.text.vocabulary import stem, unknown_words, words

    assert words("A person's walk, then 2 kicks!") == ["a", "person's", "walk", "then", "kicks"]
    assert words("人が歩く") == ["人が歩く"] and words("una persona camina") == ["una", "persona", "camina"]
    assert stem("walking") == stem("walks") == stem("walk") and stem("waving") == stem("waves") == stem("wave")
    assert stem("running") == stem("runs")
    vocab = {"a", "person", "walks", "waves", "runs", "kick"}
    assert unknown_words("A man is walking and waving", vocab) == []  # stop-words, inflections
    assert unknown_words("a person does a Cartwheel, cartwheel", vocab) == ["does", "cartwheel"]
    assert unknown_words("una persona camina", vocab) == ["una", "persona", "camina"]


def test_shipped_vocabulary_is_the_training_captions(built_all_dir: Path) -> None:
    """vocabulary.txt is what experiments/model_vocabulary.py derives from the build the base model trained
    on (mocap and HDM05, every train window); the default, Morph-tuned from it, has the same words."""
    from physmotion.diffusion.model import BASE_MODEL_DIR, DEFAULT_MODEL_DIR, MotionDiffusion
    from physmotion.text.vocabulary import load_vocabulary, training_vocabulary

    base = MotionDiffusion.load(BASE_MODEL_DIR)
    counts, motions = training_vocabulary(built_all_dir, max_frames=base.trained_max_length)
    assert motions == base.info["train_items"]
    shipped = load_vocabulary(BASE_MODEL_DIR)
    assert load_vocabulary(DEFAULT_MODEL_DIR) == shipped
    assert shipped == set(counts) and "juggles" not in shipped
    assert {"walk", "kick", "wave", "jump", "squat", "hop", "lie", "throw"} <= shipped  # HDM05's verbs too
    assert '"*/*.txt"' in (Path(__file__).parents[1] / "pyproject.toml").read_text()  # installed with the model
    assert all("vocabulary.txt" in (d / "README.md").read_text() for d in (BASE_MODEL_DIR, DEFAULT_MODEL_DIR))


def test_cli_generate_warns_about_unseen_words_and_records_them(tmp_path: Path) -> None:
    out = tmp_path / "gen"
    res = cli("generate", "a person juggles", *CHEAP, "-o", out)  # the shipped model
    assert res.returncode == 0, res.stderr
    warning = [line for line in res.stderr.splitlines() if line.startswith("warning:")]
    assert warning == ["warning: the model never saw 'juggles' in training; expect a generic motion"]
    (run,) = json.loads((out / "generate.json").read_text())["runs"]
    assert run["unknown_words"] == {"a person juggles": ["juggles"]}
    res = cli("generate", "a person walks forward", *CHEAP, "-o", out)
    assert res.returncode == 0 and "warning" not in res.stderr, res.stderr


def test_cli_no_vocabulary_file_no_warning(tiny_model_dir: Path, tmp_path: Path) -> None:
    assert not (tiny_model_dir / "vocabulary.txt").exists()
    res = cli("generate", "a person juggles", *CHEAP, "--model", tiny_model_dir, "-o", tmp_path / "g")
    assert res.returncode == 0 and "warning" not in res.stderr, res.stderr
    assert "vocabulary.txt" in cli("generate", "--help").stdout


def test_cli_generate_explains_falls(tiny_model_dir: Path, tmp_path: Path) -> None:
    """The untrained tiny model's motions make the humanoid fall: the summary says what a reset is."""
    res = cli("generate", "a person walks", "--seconds", "2", "--steps", "5", "--physics", "post:1",
              "--no-recover", "--model", tiny_model_dir, "-o", tmp_path / "g")  # fmt: skip
    assert res.returncode == 0, res.stderr
    line = next(line for line in res.stdout.splitlines() if line.startswith("physics:"))
    assert "fell in 1 of 1 projections" in line and "put back onto the motion" in line, line
    assert "cross-faded" in line and "not simulated" in line
    (run,) = json.loads((tmp_path / "g" / "generate.json").read_text())["runs"]
    resets = run["motions"][0]["resets"]
    assert resets >= 1 and f"{resets} time(s) in all, in 1 of 1 motions" in line
    assert "root residual force mean" in line and "torque mean" in line  # the external help, always reported


def test_physics_summary_without_falls() -> None:
    from physmotion.diffusion.physdiff import ProjectionLog
    from physmotion.generate import GenerateResult, physics_summary

    log = ProjectionLog(calls=2, selected=[True, True], tracked=[True, True], resets=[0, 0])
    ok = GenerateResult(motions=[], features=[], projections=log, resets=[0, 0])
    assert physics_summary(ok) == "the simulated humanoid followed the motion without falling in all 2 projections"
    assert physics_summary(GenerateResult(motions=[], features=[], projections=ProjectionLog())) == ""


# ------------------------------------------------------------------------------------------------
# 3. output paths checked before any work


def test_check_output_cases(tmp_path: Path) -> None:
    afile, adir, full = tmp_path / "f.npz", tmp_path / "d", tmp_path / "full"
    afile.write_text("x")
    adir.mkdir()
    full.mkdir()
    (full / "kept.txt").write_text("x")
    assert check_output(tmp_path / "new" / "deeper" / "m.npz") == tmp_path / "new" / "deeper" / "m.npz"
    assert not (tmp_path / "new").exists()  # checks create nothing
    assert check_output(adir, "folder") == adir  # empty folder: fine
    assert check_output(afile, overwrite=True) == afile
    assert check_output(full, "folder", overwrite=True) == full
    cases = [
        (dict(path=afile), "exists; pass --overwrite"),
        (dict(path=adir), "is a folder; give a file name"),
        (dict(path=afile, kind="folder"), "is a file, not a folder"),
        (dict(path=full, kind="folder"), "not empty"),
        (dict(path=afile / "m.npz"), "is a file, not a folder"),
        (dict(path=afile / "sub" / "m.npz", overwrite=True), "is a file, not a folder"),
        (dict(path=afile, hint="use -o"), "exists; use -o"),
    ]
    for kwargs, message in cases:
        with pytest.raises(OutputPathError, match=message):
            check_output(**kwargs)
    # Folders that refuse new files whoever asks (root ignores chmod, and os.access says yes in /proc and /sys).
    for unwritable in ("/proc/physmotion_test/new.npz", "/sys/new.bvh"):
        with pytest.raises(OutputPathError, match="is not writable"):
            check_output(unwritable)
    assert (full / "kept.txt").read_text() == "x" and afile.read_text() == "x"


def test_cli_every_writer_checks_its_output_first(walk_npz: Path, mocap_dir: Path, tmp_path: Path) -> None:
    afile = tmp_path / "file.txt"
    afile.write_text("keep me")
    full = tmp_path / "full"
    full.mkdir()
    (full / "kept.txt").write_text("keep me")
    existing = tmp_path / "existing.npz"
    existing.write_bytes(walk_npz.read_bytes())
    build = mocap_dir  # never reached: the check comes first
    cases = {
        "generate -o file": (["generate", "walk", *CHEAP, "-o", afile], "is a file, not a folder"),
        "evaluate -o under a file": (["evaluate", "--data", build, "--quick", "-o", afile / "r"], "is a file"),
        "import existing": (["import", mocap_dir / BANDAI_WALK, "-o", existing], "exists; pass --overwrite"),
        "export existing": (["export", walk_npz, "-o", existing], "exists; pass --overwrite"),
        "export to a folder": (["export", walk_npz, "-o", full], "is a folder"),
        "project existing": (["project", walk_npz, "-o", existing], "exists; pass --overwrite"),
        "train denoiser non-empty": (["train", "denoiser", "--data", build, "-o", full], "pass --resume"),
        "train denoiser file": (["train", "denoiser", "--data", build, "-o", afile], "is a file"),
        "train evaluator non-empty": (["train", "evaluator", "--data", build, "-o", full], "not empty"),
        "data build non-empty": (["data", "build", "--source", build, "-o", full], "pass --overwrite"),
        "data build under a file": (["data", "build", "--source", build, "-o", afile / "b"], "is a file"),
    }
    for name, (args, message) in cases.items():
        line = one_line_error(cli(*args, timeout=60))
        assert message in line, (name, line)
    assert afile.read_text() == "keep me" and (full / "kept.txt").read_text() == "keep me"
    assert sorted(p.name for p in full.iterdir()) == ["kept.txt"]
    assert existing.read_bytes() == walk_npz.read_bytes()


# ------------------------------------------------------------------------------------------------
# 4. run folders that never clobber


def test_slug_keeps_letters_of_any_script(monkeypatch: pytest.MonkeyPatch) -> None:
    from physmotion.generate import slug

    assert slug("A person walks forward.") == "a_person_walks_forward" and slug("!!!") == "motion"
    assert slug("una persona camina") == "una_persona_camina" and slug("人が歩く") == "人が歩く"
    assert slug("Une personne saute, puis s'arrête") == "une_personne_saute_puis_s_arrête"
    assert slug("walk " + "forward " * 20) == "walk_forward_forward_forward_forward"  # cut at a word end
    monkeypatch.setattr(sys, "getfilesystemencoding", lambda: "ascii")  # a file system that refuses them
    assert slug("s'arrête, café") == "s_arrete_cafe" and slug("人が歩く") == "motion"


def test_output_stems() -> None:
    from physmotion.generate import GenerateConfig, output_stems

    assert output_stems(["a person walks", "wave"], GenerateConfig(num=2, seed=7)) == [
        "a_person_walks_s7_0", "a_person_walks_s7_1", "wave_s7_0", "wave_s7_1"]  # fmt: skip
    assert output_stems(["walk", "walk"], GenerateConfig()) == ["walk_s0_0", "walk_s0_1"]


def test_cli_run_folder_never_clobbers(tiny_model_dir: Path, tmp_path: Path) -> None:
    out, model = tmp_path / "run", ("--model", tiny_model_dir)
    assert cli("generate", "a person walks", *CHEAP, *model, "-o", out).returncode == 0
    first = {p.name: p.read_bytes() for p in out.iterdir() if p.name != "generate.json"}
    assert sorted(first) == ["a_person_walks_s0_0.bvh", "a_person_walks_s0_0.gif", "a_person_walks_s0_0.npz"]
    line = one_line_error(cli("generate", "a person walks", *CHEAP, *model, "-o", out))
    assert "a_person_walks_s0_0.npz exists" in line and "--overwrite" in line
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name != "generate.json"} == first

    res = cli("generate", "a person walks", "人が歩く", *CHEAP, *model, "--seed", "1", "-o", out)
    assert res.returncode == 0, res.stderr
    assert (out / "a_person_walks_s1_0.npz").is_file() and (out / "人が歩く_s1_0.npz").is_file()
    assert Motion.load(out / "人が歩く_s1_0.npz").texts == ["人が歩く"]

    res = cli("generate", "a person walks", *CHEAP, *model, "--steps", "6", "--no-preview", "--overwrite", "-o", out)
    assert res.returncode == 0, res.stderr
    assert not (out / "a_person_walks_s0_0.gif").exists()  # no stale preview of the replaced motion
    assert (out / "a_person_walks_s0_0.npz").read_bytes() != first["a_person_walks_s0_0.npz"]

    runs = json.loads((out / "generate.json").read_text(encoding="utf-8"))["runs"]
    assert [r["prompts"] for r in runs] == [["a person walks"], ["a person walks", "人が歩く"], ["a person walks"]]
    assert [r["seed"] for r in runs] == [0, 1, 0] and runs[2]["settings"]["sampler"]["steps"] == 6
    assert runs[1]["files"] == [f"{s}_s1_0.{e}" for s in ("a_person_walks", "人が歩く") for e in ("npz", "bvh", "gif")]
    assert runs[2]["files"] == ["a_person_walks_s0_0.npz", "a_person_walks_s0_0.bvh"] and not runs[2]["preview"]
    assert runs[0]["model"] == str(tiny_model_dir) and runs[0]["unknown_words"] == {}


# ------------------------------------------------------------------------------------------------
# 5. --version, -h, -o, limits in the help, truncation and fps warnings, build minutes


def test_cli_version_and_short_help() -> None:
    from importlib.metadata import version

    res = cli("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"physmotion {version('physmotion')}"
    for command in ([], ["data"], ["train"], ["data", "build"], ["train", "evaluator"], ["generate"]):
        short, long = cli(*command, "-h"), cli(*command, "--help")
        assert short.returncode == 0 and short.stdout == long.stdout and "-h, --help" in short.stdout, command
    for command in (["data", "build"], ["train", "denoiser"], ["train", "evaluator"]):
        assert "-o, --out" in cli(*command, "-h").stdout, command


def test_generate_help_states_the_limits_from_the_constants() -> None:
    flat = " ".join(cli("generate", "--help").stdout.split())
    assert f"{MIN_FRAMES / FPS:g} to {MAX_FRAMES / FPS:g}" in flat and "2 to 9.8" in flat
    assert f"first {MAX_TEXT_TOKENS} tokens" in flat and "--overwrite" in flat


def test_cli_long_prompt_is_truncated_with_a_warning(tiny_model_dir: Path, tmp_path: Path) -> None:
    from physmotion.generate import long_prompts

    text = "a person walks forward " + "and then turns around " * 12
    res = cli("generate", text, *CHEAP, "--model", tiny_model_dir, "-o", tmp_path / "g")
    assert res.returncode == 0, res.stderr
    warnings_ = [line for line in res.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings_) == 1 and f"reads only the first {MAX_TEXT_TOKENS}" in warnings_[0]
    from physmotion.diffusion.model import MotionDiffusion

    model = MotionDiffusion.load(tiny_model_dir)
    assert long_prompts(["a person walks forward"], model) == {}
    assert list(long_prompts([text], model).values())[0] > MAX_TEXT_TOKENS


def test_npz_without_fps_warns_once(walk_npz: Path, tmp_path: Path) -> None:
    bare = tmp_path / "bare.npz"
    np.savez(bare, joints=Motion.load(walk_npz).joints)
    with pytest.warns(PhysmotionWarning, match=f"bare.npz has no 'fps' array; assuming {FPS} fps"):
        assert Motion.load(bare).fps == FPS
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Motion.load(walk_npz)  # a file with fps: no warning
    res = cli("metrics", bare, "--surface", "joints")
    assert res.returncode == 0, res.stderr
    assert res.stderr.strip().splitlines() == [f"warning: {bare} has no 'fps' array; assuming {FPS} fps"]


def test_build_report_counts_mirrored_minutes(built) -> None:
    assert built.minutes > 30 and built.minutes_with_mirrors == pytest.approx(2 * built.minutes, rel=0.01)
