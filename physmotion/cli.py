"""The ``physmotion`` command line: thin commands over the library's public functions.

Any :class:`~physmotion.errors.PhysmotionError` becomes one line on stderr and exit code 1.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from physmotion.conventions import FLOOR_JOINTS, FLOOR_SURFACE, FPS, MAX_FRAMES, MAX_TEXT_TOKENS, MIN_FRAMES
from physmotion.errors import PhysmotionError, PhysmotionWarning
from physmotion.paths import DEFAULT_MODEL, MOTION_SUFFIXES, WEIGHTS_DIR

# The rig tables' names for `import --rig`'s help (physmotion.io.rigs.RIGS, which imports scipy: not
# imported for --help; tests/test_cli_cold.py checks the two agree).
RIG_NAMES = ("bandai", "cmu_bvh_cgspeed_max", "cmu_bvh_cgspeed_max_scaled_m", "cmu_asf", "cmu_iclone_cc_base",
             "mixamo", "mixamo_plain", "smpl22")  # fmt: skip

HELP = {"help_option_names": ["-h", "--help"]}  # -h everywhere, on the app and every sub-app

app = typer.Typer(
    help="Text-to-motion generation that obeys physics.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,  # help is plain text: "physdiff:end:4" must not become an emoji
    context_settings=HELP,
)
data_app = typer.Typer(help="Build and inspect HumanML3D-layout datasets.", no_args_is_help=True,
                       context_settings=HELP)  # fmt: skip
app.add_typer(data_app, name="data")
# User text (captions, paths, physics modes) goes into these lines: rich must neither turn ":end:" or
# ":fire:" into emoji nor read "[...]" as markup (rich docs, Console: emoji=, markup=). A line that wants
# markup asks for it (markup=True) and escapes the user's text in it (rich.markup.escape).
console = Console(soft_wrap=True, emoji=False, markup=False, highlight=False)
OVERWRITE_HELP = "Replace existing output instead of refusing."
SAMPLER_HELP = ("ddim, ddpm, dpmpp (DPM-Solver++ 2M, Karras) or dpmpp-sde (its SDE variant; a BioMoDiffuse "
                "model's default, with 10 steps) (default: dpmpp).")
ETA_HELP = "DDIM eta: 0 deterministic, 1 ancestral (DDPM-like) (default: 0)."
CFG_HELP = ("Classifier-free guidance scale, 0 to 10: 0 ignores the text, 1 follows it plainly, more follows it "
            "harder (MDM's 2.5) (default: 2.5).")
# SamplerConfig's fields as the options that set them, for its errors (_as_options).
SAMPLER_OPTIONS = {"steps": "--steps", "eta": "--eta", "cfg_scale": "--cfg-scale", "phys_scale": "--phys-scale",
                   "speed": "--speed"}  # fmt: skip


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import version

        print(f"physmotion {version('physmotion')}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the installed version and exit."),  # fmt: skip
) -> None:
    """Text-to-motion generation that obeys physics."""


def _check_out(out: Path, overwrite: bool | None = None, suffixes: tuple[str, ...] | None = None) -> None:
    """Refuse, before any work, an output file that exists (unless ``overwrite``), cannot be written, or
    (where ``suffixes`` are given) is of a format the command cannot write.

    overwrite None: the command has no --overwrite, so the message does not offer one."""
    from physmotion.paths import check_output

    hint = "delete it or choose another -o" if overwrite is None else "pass --overwrite to replace it"
    check_output(out, "file", overwrite=bool(overwrite), hint=hint, suffixes=suffixes)


@contextmanager
def _as_options(**options: str) -> Iterator[None]:
    """Errors of the library's config checks name a field (``ilc_passes must be ...``); on the command line
    they name the option the user typed (``--ilc must be ...``). ``options`` maps field to option."""
    try:
        yield
    except PhysmotionError as exc:
        message = str(exc)
        for name, option in options.items():
            if message.startswith(f"{name} "):
                raise PhysmotionError(option + message[len(name):]) from None
        raise


def _warn(message: str) -> None:
    """One ``warning: ...`` line on stderr: the CLI's voice for what does not stop the work."""
    print(f"warning: {message}", file=sys.stderr)


# The options of every command that reads a .bvh (import's own help says more).
BVH_RIG_HELP = "Rig of .bvh input, as for `import` (guessed if left out)."
BVH_FPS_HELP = "True frame rate of .bvh input, as for `import`."
MODEL_HELP = ("Model folder, or a shipped model's name: morph (the default, used if left out) or base (the model "
              "Morph fine-tuned it from).")
BVH_MAPPING_HELP = ("JSON file naming the .bvh's joint (or End Site, '<parent>_end') for each of our 22 joints, "
                    "as for `import` (docs/examples/mapping_bandai.json).")




def _model_dir(model: Path | None) -> Path | None:
    """A --model as given, or a shipped model's folder where a bare name (``base``, ``morph``, or
    ``default`` for the one used without --model) names one and no folder of that name exists here: model
    names work from any directory."""
    if model is None or model.exists() or len(model.parts) != 1:
        return model
    name = DEFAULT_MODEL if model.name == "default" else model.name
    shipped = WEIGHTS_DIR / name  # diffusion.model.DEFAULT_MODEL_DIR's folder, without torch
    return shipped if (shipped / "config.json").is_file() else model


@data_app.command("build")
def data_build(
    source: list[Path] = typer.Option(..., help="Mocap folder with manifest.csv (e.g. ../shared/data/mocap); "
                                      "repeat it to build several into one dataset (their manifests in the same "
                                      "columns, clip ids unique)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output folder (HumanML3D layout). An earlier build "
                             "there is replaced only with --overwrite."),
    exclude_license: list[str] = typer.Option([], "--exclude-license", help="Leave out clips with this licence tag, e.g. NC."),
    seed: int = typer.Option(0, help="Salt of the take -> split assignment."),
    mirror: bool = typer.Option(True, help="Add left/right mirrored copies, as HumanML3D does."),
    pad_short: bool = typer.Option(True, help="Hold a clip shorter than 2 s still at both ends up to 2 s "
                                   "(HumanML3D's shortest motion) instead of skipping it; --no-pad-short skips "
                                   "them, as the shipped models' data was built."),
    jobs: int = typer.Option(0, help="Worker processes (0: one per core)."),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    activations: bool = typer.Option(False, "--activations", help="Also cache muscle-activation stand-ins "
                                     "(inverse-dynamics joint effort, 8 channels) in activations/."),
    features: int = typer.Option(263, help="263 (HumanML3D) or 329 (BioMoDiffuse: + joint accelerations; "
                                 "what `train denoiser --arch biomo` needs, with --activations)."),
) -> None:
    """Import every clip of one or more mocap collections into a HumanML3D-layout dataset."""
    from physmotion.data.build import BuildConfig, build_dataset
    from physmotion.paths import check_output

    check_output(out, "folder", overwrite=overwrite)
    config = BuildConfig(exclude_licences=tuple(exclude_license), seed=seed, mirror=mirror, jobs=jobs,
                         features=features, pad_short=pad_short)
    report = build_dataset(source, out, config, progress=sys.stderr.isatty())
    for clip, reason in sorted(report.skipped.items()):
        console.print(f"[yellow]skipped[/] {escape(clip)}: {escape(reason)}", markup=True)
    items = ", ".join(f"{k} {v}" for k, v in report.num_items.items())
    console.print(
        f"built {out}: {report.num_clips - len(report.skipped)}/{report.num_clips} clips, "
        f"{report.minutes:.1f} min of capture ({report.minutes_with_mirrors:.1f} min with mirrored copies); "
        f"items: {items}",
        highlight=False,
    )
    for name, src in report.sources.items():
        licences = "; ".join(f"{tag or 'open'} ({', '.join(names)})" for tag, names in src.licences.items())
        console.print(f"  {name}: {src.built}/{src.clips} clips, {src.minutes:.1f} min; {licences}",
                      highlight=False)  # fmt: skip
    latin1 = {name: src.latin1 for name, src in report.sources.items() if src.latin1}
    if latin1:
        _warn(f"{sum(latin1.values())} clips' files are not UTF-8 and were read as Latin-1 ("
              + ", ".join(f"{name} {n}" for name, n in latin1.items()) + ")")
    if activations:
        data_activations(out, jobs)


@data_app.command("activations")
def data_activations(
    root: Path = typer.Argument(..., help="A folder written by `physmotion data build`."),
    jobs: int = typer.Option(0, help="Worker processes (0: one per core)."),
) -> None:
    """Cache muscle-activation stand-ins (T, 8) per motion in ROOT/activations (replaces an earlier cache)."""
    from physmotion.data.build import build_activations

    n = build_activations(root, progress=sys.stderr.isatty(), jobs=jobs)
    console.print(f"activations for {n} motions in {root / 'activations'}", highlight=False)


@data_app.command("stats")
def data_stats(root: Path = typer.Argument(..., help="A HumanML3D-layout folder.")) -> None:
    """Print counts, minutes and the caption vocabulary of a dataset."""
    from physmotion.data.stats import dataset_stats

    stats = dataset_stats(root)
    table = Table(title=f"dataset {root}")
    table.add_column("split")
    table.add_column("motions", justify="right")
    table.add_column("minutes*", justify="right")
    for split, n in stats.items.items():
        table.add_row(split, str(n), f"{stats.minutes[split]:.1f}")
    table.add_row("all", str(sum(stats.items.values())), f"{stats.total_minutes:.1f}")
    console.print(table)
    console.print("* minutes count every motion listed, mirrored copies (ids starting with M) included",
                  highlight=False)
    if stats.licences:
        console.print("licences: " + ", ".join(f"{k} {v}" for k, v in stats.licences.items()))
    top = ", ".join(f"{w} {c}" for w, c in stats.vocabulary.most_common(30))
    console.print(f"captions: {stats.captions}; vocabulary: {len(stats.vocabulary)} words; most common: {top}")


@app.command("import")
def import_motion(
    path: Path | None = typer.Argument(None, help="A .bvh or .amc file (an .amc needs --asf)."),
    out: Path | None = typer.Option(None, "-o", "--out", help="Output .npz (or .bvh)."),
    rig: str | None = typer.Option(
        None, help=f"Rig table: {', '.join(RIG_NAMES)}; guessed if left out. '--rig list' describes them."
    ),
    mapping: Path | None = typer.Option(
        None, help="JSON file naming the file's joint for each of our 22 joints, plus optional units, "
        "up_axis and fps, for a rig without a table (docs/examples/mapping_bandai.json); an End Site is "
        "named '<parent>_end'. Flags override it."),
    asf: Path | None = typer.Option(None, help="The skeleton (.asf) of an .amc file."),
    fps: float | None = typer.Option(None, help="True frame rate, where the header is wrong or absent."),
    up_axis: str | None = typer.Option(None, help="Y or Z, overriding the rig's or mapping's."),
    units: str | None = typer.Option(None, help="cm, m, inch or a factor to metres, overriding the rig's or mapping's."),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Import one mocap file to the 22-joint skeleton at 20 fps, Y up, facing +Z, its stance soles on the
    floor (y = 0)."""
    from physmotion.io.rigs import RIGS, describe_rig

    if rig == "list":
        for name, table in RIGS.items():
            console.print(f"{name}: {describe_rig(table)}", highlight=False)
        return
    if path is None or out is None:
        raise PhysmotionError("import needs a FILE and -o OUT (or --rig list to see the rig tables)")
    _check_out(out, overwrite, MOTION_SUFFIXES)
    from physmotion.io.export import save_motion
    from physmotion.io.importer import import_clip

    motion = import_clip(path, rig=rig, mapping=mapping, asf=asf, fps=fps, up_axis=up_axis, units=units)
    save_motion(motion, out)
    console.print(f"wrote {out}: {motion.num_frames} frames, {motion.seconds:.1f} s", highlight=False)


@app.command("export")
def export_motion(
    path: Path = typer.Argument(..., help="A motion .npz."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .bvh or .npz."),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Write a motion to BVH (metres, Y up, the 22-joint rig) or .npz."""
    from physmotion.io.export import save_motion
    from physmotion.motion import Motion

    _check_out(out, overwrite, MOTION_SUFFIXES)
    save_motion(Motion.load(path), out)
    console.print(f"wrote {out}", highlight=False)


CONTROLLER_HELP = ("Who drives the simulated humanoid: 'tracker' (the model-based tracker, with a bounded outside "
                   "hand on the pelvis), 'policy' (the learned imitation policy over it, physmotion train "
                   "imitator) or 'search' (no outside hand at all: the body's own joint targets searched; "
                   "seconds of CPU per second of motion).")
EFFORT_HELP = ("With --controller search: 'fast', 'default' or 'best' (more candidates, a longer lookahead; "
               "costs in results/search_quality.md).")
POLICY_HELP = "With --controller policy: the policy folder (the shipped one if left out)."


def _opt_str(path: Path | None) -> str | None:
    return None if path is None else str(path)


@app.command("project")
def project_motion(
    paths: list[Path] = typer.Argument(..., help="Motion .npz files (joints at any fps)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .npz with the projected motion (or .bvh: the motion "
                             "alone, without the simulation's records, as `export` writes); with several "
                             "inputs, a folder that receives <stem>.npz per input (those already there are "
                             "skipped, so an interrupted run resumes)."),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    ilc: int = typer.Option(0, "--ilc", help="Iterative learning control: simulate this many more times, "
                            "each time with the root's error of the last fed forward into the reference, and "
                            "keep the simulation closest to the input (0: off; 2: captured runs 50 -> 43 mm "
                            "and Float 15.0 -> 12.5 mm, for 3x the time; results/projection_dynamic.md)."),
    fine_step: bool = typer.Option(False, "--fine-step", help="Simulate at 1/720 s instead of 1/360 s: "
                                   "fast motion lands and pushes off better (captured runs' Float 15.0 -> "
                                   "9.7 mm), for twice the simulation steps; results/projection_dynamic.md."),
    controller: str = typer.Option("tracker", help=CONTROLLER_HELP),
    policy: Path | None = typer.Option(None, help=POLICY_HELP),
    effort: str = typer.Option("default", help=EFFORT_HELP),
    seed: int = typer.Option(0, help="With --controller search: the seed of its random candidates."),
    teacher: bool = typer.Option(False, "--teacher", help="With --controller search: also write the search's "
                                 "teacher records beside each output, <stem>.teacher.npz (per control step, the "
                                 "observation a policy sees and the joint-target offsets chosen)."),
    workers: int = typer.Option(0, help="With several inputs: local worker processes, one motion each "
                                "(0: one per core)."),
    ray: str | None = typer.Option(None, help="With several inputs: run one Ray task per motion instead of "
                                   "local processes, on the Ray cluster at this address, or 'local' to start "
                                   "one on this machine (needs pip install 'physmotion[ray]'; docs/cluster.md)."),
    preset_name: str = typer.Option("plain", "--preset", help="P's preset by name (physmotion/physics/presets.py; "
                                    "docs/cli.md lists them): 'plain' keeps the input where the imitation fails, "
                                    "'sampling' is generation's P; --ilc and --fine-step apply on top."),
) -> None:
    """Physics projection (PhysDiff's P): imitate the motion with the simulated humanoid."""
    from dataclasses import replace

    from physmotion.physics.files import project_file, project_files, teacher_path
    from physmotion.physics.presets import preset
    from physmotion.physics.search import effort as search_effort

    if teacher and controller != "search":
        raise PhysmotionError("--teacher needs --controller search: only the search makes teacher records")
    search = search_effort(effort, seed) if controller == "search" else None
    with _as_options(ilc_passes="--ilc", controller="--controller"):
        config = preset(preset_name).with_controller(controller, _opt_str(policy), search)
        config = replace(config, ilc_passes=ilc) if ilc else config
    config = config.at_fine_step() if fine_step else config
    if len(paths) == 1 and ray is None:
        _check_out(out, overwrite, MOTION_SUFFIXES)  # written by suffix, as `export` writes
        if teacher:
            _check_out(teacher_path(out), overwrite)
        with _step_bar(f"projecting {paths[0].name} ({controller}), control steps") as tick:
            result = project_file(paths[0], out, config, teacher, on_step=tick)
        console.print(f"wrote {out} ({controller}): {result.summary}", highlight=False)
        return
    missing = [p for p in paths if not p.is_file()]
    if missing:
        raise PhysmotionError(f"{missing[0]}: no such file")
    if out.exists() and not out.is_dir():
        raise PhysmotionError(f"{out} is a file: with several inputs, -o names a folder")
    from physmotion.paths import check_output

    check_output(out, "folder", overwrite=True)  # its files are checked one by one: an earlier run resumes
    if overwrite:  # re-project everything: the outputs of an earlier run are not skipped
        from physmotion.physics.files import outputs_for

        for o in outputs_for(paths, out):
            for f in (o, teacher_path(o)):
                f.unlink(missing_ok=True)
    with _step_bar(f"projecting {len(paths)} motions ({controller})") as tick:
        done = []

        def report(r) -> None:
            done.append(r)
            tick(len(done), len(paths))
            console.print(f"{r.source.name} -> {r.out}: {r.summary}", highlight=False)

        results = project_files(paths, out, config, teacher, workers=workers, ray=ray, on_done=report)
    kept = sum(r.selected for r in results if not r.skipped)
    skipped = sum(r.skipped for r in results)
    console.print(f"wrote {len(results) - skipped} motions to {out} ({controller}): {kept} simulations kept"
                  + (f"; {skipped} already there, skipped" if skipped else ""), highlight=False)


@app.command("metrics")
def metrics(
    paths: list[Path] = typer.Argument(
        ..., help="Motion files: .npz (joints, fps), or .bvh (imported on the fly, as render does)."),
    surface: str = typer.Option(
        "humanoid", help="Body surface for Penetrate/Float/Skate: 'humanoid' (MuJoCo geometry posed on "
        "the joints: the simulated body where the file carries it, as generate writes for projected "
        "motions) or 'joints' (a light model built from the joints alone)."),
    as_json: bool = typer.Option(False, "--json", help="JSON instead of the table: units and, per file, "
                                 "its label, path and metrics."),
    as_csv: bool = typer.Option(False, "--csv", help="CSV instead of the table: one row per file (label, "
                                "path, one column per metric)."),
    out: Path | None = typer.Option(
        None, "-o", "--out", help="Write the JSON or CSV to this file (atomically) instead of stdout; its "
        "suffix (.json, .csv) picks the format if neither flag is given."),
    rig: str | None = typer.Option(None, help=BVH_RIG_HELP),
    fps: float | None = typer.Option(None, help=BVH_FPS_HELP),
    mapping: Path | None = typer.Option(None, help=BVH_MAPPING_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Print the physical metrics (PhysDiff, EDGE/Morph, BioMoDiffuse) of one or more motions.

    One column per file, labelled by the shortest end of its path that tells it from the others
    (a/x.npz and b/x.npz stay apart). Where the table is wider than the terminal the columns are
    numbered and a legend names the files."""
    from physmotion.metrics import physical_metrics
    from physmotion.metrics.report import (fit_table, path_labels, residual_summary, table_width, to_csv,
                                           to_json)
    from physmotion.motion import write_atomic

    if surface not in ("humanoid", "joints"):
        raise PhysmotionError(f"--surface must be 'humanoid' or 'joints', got {surface!r}")
    if as_json and as_csv:
        raise PhysmotionError("give --json or --csv, not both")
    fmt = "json" if as_json else "csv" if as_csv else None
    if out is not None:
        fmt = fmt or {".json": "json", ".csv": "csv"}.get(out.suffix.lower())
        if fmt is None:
            raise PhysmotionError(f"{out}: give --json or --csv (or an -o ending in .json or .csv)")
        _check_out(out, overwrite)
    from physmotion.render import load_motion

    for path in paths:  # every file checked before any work
        if path.suffix.lower() not in (".npz", ".bvh"):
            raise PhysmotionError(f"{path}: metrics reads .npz or .bvh; run `physmotion import` on other formats")
        if not path.is_file():
            raise PhysmotionError(f"{path}: no such file")
    results = {}
    for path, label in zip(paths, path_labels(paths)):
        motion = load_motion(path, rig=rig, fps=fps, mapping=mapping)  # an .npz as saved, a .bvh imported
        body = None
        if surface == "humanoid":
            from physmotion.physics.surface import HumanoidSurface

            body = HumanoidSurface(motion.humanoid)  # P's body where the file has it, else estimated
        results[label] = physical_metrics(motion.joints, fps=motion.fps, body=body) | residual_summary(motion)
    if fmt is None:
        table, legend = fit_table(results, f"physical metrics ({surface} surface)", console.width)
        # A table that still does not fit prints whole (wider than the terminal) rather than with cut cells.
        Console(width=max(console.width, table_width(table)), emoji=False, markup=False).print(table)
        for line in legend:
            console.print(line, highlight=False, markup=False)
        return
    text = to_json(results, paths, surface) if fmt == "json" else to_csv(results, paths)
    if out is None:
        sys.stdout.write(text)
    else:
        data = text.encode("utf-8")
        write_atomic(out, lambda f: f.write(data))
        console.print(f"wrote {out}", highlight=False)


@app.command("refine")
def refine_cmd(
    path: Path = typer.Argument(..., help="A motion .npz or .bvh (e.g. a pose estimator's output)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output motion .npz or .bvh (20 fps)."),
    strength: float = typer.Option(0.3, help="Share of the diffusion steps to invert, in [0, 1] (0 returns "
                                   "the input on the dataset's skeleton)."),
    text: str = typer.Option("", help="Caption to condition on (default: none)."),
    model_dir: Path | None = typer.Option(None, "--model", help=MODEL_HELP),
    steps: int = typer.Option(50, help="DDIM steps of the full schedule."),
    phys_scale: float | None = typer.Option(None, help="BioMoDiffuse models only: physics guidance weight "
                                            "(default: 1)."),
    smooth_hz: float = typer.Option(4.0, help="Low-pass the input at this cut-off (Hz) before inversion and "
                                    "fuse the result with it; 0: the paper's plain inversion."),
    anchor_hz: float = typer.Option(1.0, help="Plain inversion only: heading and root path slower than this "
                                    "(Hz) follow the input; 0: one yaw + shift for the whole clip."),
    rig: str | None = typer.Option(None, help=BVH_RIG_HELP),
    fps: float | None = typer.Option(None, help=BVH_FPS_HELP),
    mapping: Path | None = typer.Option(None, help=BVH_MAPPING_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Refine a motion by DDIM inversion and denoising (BioMoDiffuse Sec. 3.5; physics guidance with a
    BioMoDiffuse model)."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.refine import RefineConfig
    from physmotion.motion import Motion
    from physmotion.pipelines.refine import RefinePipeline

    config = RefineConfig(strength=strength, steps=steps, text=text, phys_scale=phys_scale,
                          smooth_hz=smooth_hz or None, anchor_hz=anchor_hz or None)
    with _as_options(strength="--strength", steps="--steps", phys_scale="--phys-scale", smooth_hz="--smooth-hz",
                     anchor_hz="--anchor-hz"):  # fmt: skip
        config.check()
    if not path.is_file():
        raise PhysmotionError(f"{path}: no such file")
    if path.suffix.lower() not in (".npz", ".bvh"):
        raise PhysmotionError(f"{path}: refine reads .npz or .bvh")
    _check_out(out, overwrite, MOTION_SUFFIXES)
    if path.suffix.lower() == ".bvh":
        from physmotion.io.importer import import_clip

        motion = import_clip(path, rig=rig, fps=fps, mapping=mapping)
    else:
        motion = Motion.load(path)
    pipeline = RefinePipeline(MotionDiffusion.load(_model_dir(model_dir)), config)
    pipeline.check(motion)  # length and NaN before the work
    refined = pipeline(motion).motion
    from physmotion.io.export import save_motion

    save_motion(refined, out)
    console.print(f"wrote {out}: {len(refined.joints)} frames, strength {strength:g}", highlight=False)


@app.command("generate")
def generate_cmd(
    texts: list[str] | None = typer.Argument(
        None, show_default=False, help="One or more captions, e.g. \"a person walks forward\" (or --prompts FILE). "
        "The text encoder reads the first "
        f"{MAX_TEXT_TOKENS} tokens of each (special tokens included): a longer caption is cut there, with "
        "a warning. Words the model never saw in its training captions get a warning too (only for a "
        "model folder with a vocabulary.txt, as the shipped model has)."),
    out: Path = typer.Option(Path("out"), "-o", "--out", help="Output folder: each motion becomes "
                             "<caption>_s<seed>_<k>.npz, .bvh and .gif (k: sample of that caption), and "
                             "the run is appended to generate.json there. A new folder named like a file (foo.npz, foo.gif) is "
                             "refused."),
    prompts: Path | None = typer.Option(
        None, "--prompts", help="A UTF-8 file of prompts, one a line, generated in one batch by one process: "
        "'a person jumps | 3.5' (or a tab before the number) gives that motion's seconds; blank lines and "
        "lines starting with # are skipped. A line without seconds takes --seconds, or its length is "
        "predicted from its text; --seconds, when given, applies to every line."),
    seconds: float | None = typer.Option(
        None, help=f"Length of each motion in seconds, {MIN_FRAMES / FPS:g} to {MAX_FRAMES / FPS:g} (the "
        "model's range: another model may allow less); left out, each prompt's length is predicted from its "
        "text by the length model (physmotion/weights/length), printed and recorded in generate.json "
        "(default: predicted from the text)."),
    physics: str | None = typer.Option(
        None, help="none, none+floor (plain sampling, shifted onto the floor as well as a constant "
        "shift can), post[:K] (K projections after sampling), physdiff[:SCHEDULE] (projection "
        "inside sampling; SCHEDULE uniform:N, start:M,end:N or end:N,space:S) or morph (one projection "
        "after sampling that keeps the sampled motion where the humanoid fails to imitate it, Morph's "
        "inference) (default: physdiff:end:2,space:1)."),
    num: int | None = typer.Option(None, help="Samples per caption (default: 1)."),
    seed: int | None = typer.Option(None, help="Random seed; the same seed gives the same motions (default: 0)."),
    sampler: str | None = typer.Option(None, help=SAMPLER_HELP),
    steps: int | None = typer.Option(None, help="Sampling steps (default: 10)."),
    eta: float | None = typer.Option(None, help=ETA_HELP),
    cfg_scale: float | None = typer.Option(None, help=CFG_HELP),
    phys_scale: float | None = typer.Option(None, help="BioMoDiffuse models only: physics guidance weight, "
                                            "0 = without the physical network (default: 1)."),
    speed: float | None = typer.Option(None, help="BioMoDiffuse models only: speed control signal, scales "
                                       "the physical network's accelerations (default: 1)."),
    model: Path | None = typer.Option(None, help=MODEL_HELP),
    fine_step: bool = typer.Option(False, "--fine-step", help="Simulate the projection at 1/720 s instead "
                                   "of 1/360 s: PhysDiff on unseen prompts 12.5 -> 11.2 mm Phys-Err, for "
                                   "1.3-1.4x PhysDiff's time (experiments/generate_speed.py)."),
    controller: str = typer.Option("tracker", help=CONTROLLER_HELP),
    policy: Path | None = typer.Option(None, help=POLICY_HELP),
    preview: bool = typer.Option(True, help="Write a GIF preview per motion."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace files of the same names instead of "
                                   "refusing (with --no-preview, an old GIF of the same name is removed)."),
) -> None:
    """Generate motions from text: .npz, .bvh and a GIF preview per sample.

    Unset options take GenerateConfig's and the model's sampler defaults (the values the help quotes)."""
    prompt_file = None
    if prompts is not None:
        if texts:
            raise PhysmotionError("give prompts as arguments or in --prompts FILE, not both")
        from physmotion.text.prompts import read_prompts

        prompt_file = read_prompts(prompts)
        texts = [p.text for p in prompt_file]
    elif not texts:
        raise PhysmotionError("give a prompt, e.g. physmotion generate \"a person walks forward\", or --prompts FILE")
    model = _model_dir(model)
    _check_generate_early(texts, model, prompt_file, prompts, seconds=seconds, num=num, physics=physics,
                          sampler=sampler, steps=steps, eta=eta, cfg_scale=cfg_scale, phys_scale=phys_scale,
                          speed=speed)  # fmt: skip
    from physmotion.diffusion.model import DEFAULT_MODEL_DIR, MotionDiffusion
    from physmotion.diffusion.samplers import default_sampler
    from physmotion.generate import (
        GenerateConfig,
        check_outputs,
        check_request,
        chosen_lengths,
        generate,
        long_prompts,
        physics_summary,  # fmt: skip
        unknown_prompt_words,
        write_outputs,
    )

    cfg = _with(GenerateConfig(), num=num, physics=physics, seed=seed)
    cfg.seconds = seconds  # None: each prompt's length predicted from its text
    cfg = cfg.at_fine_step() if fine_step else cfg
    cfg = cfg.with_controller(controller, _opt_str(policy))
    check_outputs(texts, out, cfg, overwrite)
    net = MotionDiffusion.load(model)
    cfg.sampler = _with(default_sampler(net), sampler=sampler, steps=steps, eta=eta, cfg_scale=cfg_scale,
                        phys_scale=phys_scale, speed=speed)  # fmt: skip
    cfg.sampler.check_model(net)
    with _as_options(**SAMPLER_OPTIONS):
        check_request(texts, cfg, net)
    for text, tokens in long_prompts(texts, net).items():
        _warn(f"{_quote(text)} is {tokens} tokens long; the text encoder reads only the first "
              f"{MAX_TEXT_TOKENS}, the rest is ignored")  # fmt: skip
    unknown = unknown_prompt_words(texts, model or DEFAULT_MODEL_DIR)
    for text, words in unknown.items():
        where = f" (in {_quote(text)})" if len(texts) > 1 else ""
        _warn(f"the model never saw {', '.join(repr(w) for w in words)} in training{where}; "
              "expect a generic motion")  # fmt: skip
    lengths = sources = None
    own = [p for p in prompt_file or () if p.seconds is not None]
    if own and seconds is not None:
        _warn(f"--seconds {seconds:g} applies to every prompt, also to the {len(own)} line(s) of {prompts} that "
              "give their own seconds")  # fmt: skip
    elif own:  # each line's own seconds; the others predicted from their text
        rest = [p.text for p in prompt_file if p.seconds is None]
        predicted = iter(chosen_lengths(rest, cfg, net)) if rest else iter(())
        chosen = [(round(p.seconds * FPS), "given") if p.seconds is not None else next(predicted) for p in prompt_file]
        lengths, sources = [n for n, _ in chosen], [s for _, s in chosen]
    if seconds is None:
        chosen = zip(lengths, sources) if lengths is not None else chosen_lengths(texts, cfg, net)
        for text, (frames, source) in dict(zip(texts, chosen)).items():
            if source == "predicted":
                console.print(f"length: {frames / FPS:.2f} s for {_quote(text)} (predicted from the text; "
                              "--seconds sets it)", highlight=False)  # fmt: skip
    with _step_bar("generating") as tick:
        result = generate(texts, cfg, net, on_step=tick, lengths=lengths, length_source=sources)
    paths = write_outputs(result, out, cfg, preview=preview, overwrite=overwrite, model=model,
                          unknown=unknown)
    console.print(f"wrote {len(result.motions)} motion(s) to {out} ({len(paths)} files, run logged in "
                  f"generate.json)", highlight=False)  # fmt: skip
    phys = physics_summary(result)
    if phys:
        console.print(f"physics: {phys}", highlight=False)


def _check_generate_early(texts, model, prompt_file, prompts, *, seconds, num, physics, sampler, steps, eta,
                          cfg_scale, phys_scale, speed) -> None:
    """generate's argument checks that need neither torch nor the model's weights (its config.json only),
    so that a mistake is told in a fraction of a second. The same checks run again, with the loaded
    model, in check_request and SamplerConfig.check: this only finds errors sooner, with the same words."""
    import json
    import math

    from physmotion.pipelines.modes import PhysicsMode

    if any(not t.strip() for t in texts):
        raise PhysmotionError("text is empty: describe a motion, e.g. 'a person walks forward'")
    mode = PhysicsMode.parse(physics) if physics is not None else None
    if sampler is not None:
        from physmotion.diffusion.schedule import SAMPLERS

        if sampler not in SAMPLERS:
            raise PhysmotionError(f"unknown sampler {sampler!r}: choose one of {', '.join(SAMPLERS)}")
    _check_sampler_options(steps=steps, eta=eta, cfg_scale=cfg_scale)
    if steps is not None and mode is not None:
        mode.hook_steps(steps)
    if phys_scale is not None and not (math.isfinite(phys_scale) and phys_scale >= 0):
        raise PhysmotionError(f"--phys-scale must be a number >= 0, got {phys_scale}")
    if speed is not None and not (math.isfinite(speed) and 0.0 < speed <= 4.0):
        raise PhysmotionError(f"--speed must be in (0, 4], got {speed}")
    if num is not None and not 1 <= num <= 256:
        raise PhysmotionError(f"--num must be between 1 and 256, got {num}")
    try:
        config = json.loads(((model or WEIGHTS_DIR / DEFAULT_MODEL) / "config.json").read_text(encoding="utf-8"))
        den = config["denoiser"]
        max_frames, arch = int(den.get("max_frames", MAX_FRAMES)), den.get("arch", "transformer")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return  # loading the model names what is wrong with it
    lo, hi = MIN_FRAMES / FPS, max_frames / FPS
    if seconds is not None and (not math.isfinite(seconds) or not lo <= seconds <= hi):
        raise PhysmotionError(f"--seconds must be between {lo:g} and {hi:g} (the model's range), got {seconds:g}")
    if prompt_file is not None and seconds is None:
        from physmotion.text.prompts import check_seconds

        check_seconds(prompt_file, lo, hi, str(prompts))
    if arch != "biomo" and (phys_scale is not None or (speed is not None and speed != 1.0)):
        raise PhysmotionError(f"--phys-scale and --speed need a BioMoDiffuse model (arch biomo); this one is a {arch}")


def _check_sampler_options(*, steps: int | None, eta: float | None, cfg_scale: float | None) -> None:
    """The sampler options of generate and evaluate, checked before torch loads, named as typed. The
    same bounds as SamplerConfig.check, which runs again on the model's sampler."""
    import math

    from physmotion.conventions import CFG_SCALE_RANGE

    if steps is not None and not 1 <= steps <= 1000:
        raise PhysmotionError(f"--steps must be between 1 and 1000, got {steps}")
    if eta is not None and not (math.isfinite(eta) and 0.0 <= eta <= 1.0):
        raise PhysmotionError(f"--eta must be between 0 and 1, got {eta:g}")
    lo, hi = CFG_SCALE_RANGE
    if cfg_scale is not None and not (math.isfinite(cfg_scale) and lo <= cfg_scale <= hi):
        raise PhysmotionError(f"--cfg-scale must be between {lo:g} and {hi:g} (MDM's default: 2.5), "
                              f"got {cfg_scale:g}")  # fmt: skip


def _quote(text: str, limit: int = 40) -> str:
    """A prompt for a one-line message: quoted, cut to ``limit`` characters."""
    return repr(text if len(text) <= limit else text[: limit - 3] + "...")


def _with(config, **given):
    """``config`` with the options the user gave (not None) replaced: the dataclass holds every default."""
    from dataclasses import replace

    return replace(config, **{k: v for k, v in given.items() if v is not None})


def _step_bar(label: str):
    """A context manager yielding tick(done, total) that drives a rich progress bar (silent if not a TTY)."""
    from contextlib import contextmanager

    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    @contextmanager
    def bar():
        # The label (a file name) is the task's description, not the column's format string: a "{" in a
        # path would break str.format, and "[..]" or ":fire:" would be read as markup or emoji.
        progress = Progress(TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(),
                            TimeElapsedColumn(), TimeRemainingColumn(),
                            console=Console(stderr=True, emoji=False, markup=False),
                            disable=not sys.stderr.isatty())  # fmt: skip
        with progress:
            task = progress.add_task(label, total=None)
            yield lambda done, total: progress.update(task, completed=done, total=total)

    return bar()


train_app = typer.Typer(help="Train models.", no_args_is_help=True, context_settings=HELP)
app.add_typer(train_app, name="train")


@train_app.command("denoiser")
def train_denoiser_cmd(
    data: Path = typer.Option(..., help="HumanML3D-layout folder (our build or a real HumanML3D)."),
    out: Path = typer.Option(..., "-o", "--out", help="Run folder: model, train_state.pt, loss.csv. Must be "
                             "new or empty, unless --resume continues the run in it."),
    arch: str | None = typer.Option(
        None, help="transformer (MDM), unet (BioMoDiffuse's 1D UNet) or biomo (the UNet with BioMoDiffuse's "
        "physical network; needs `data build --features 329 --activations`) (default: transformer)."),
    d_model: int | None = typer.Option(None, help="Width (default: 256)."),
    layers: int | None = typer.Option(None, help="Transformer layers, or UNet levels (default: 4)."),
    heads: int | None = typer.Option(None, help="Attention heads (default: 4)."),
    crop: int | None = typer.Option(
        None, help="Training windows are cropped to at most this many frames (default: 196)."),
    max_length: int | None = typer.Option(
        None, help="Leave out motions of this many frames + 4 or more (HumanML3D's filter; the default "
        "model saw those under 124) (default: 196)."),
    batch_size: int | None = typer.Option(None, help="Batch size (default: 32)."),
    steps: int | None = typer.Option(None, help="Total optimiser steps (default: 10000)."),
    lr: float | None = typer.Option(None, help="AdamW learning rate (default: 0.0002)."),
    bf16: bool | None = typer.Option(None, "--bf16/--no-bf16", help="bf16 autocast; default: where the "
                                     "hardware has bf16 natively (a CPU without it is ~20x slower)."),
    device: str | None = typer.Option(
        None, help="cpu or cuda (multi-GPU: run under `accelerate launch`) (default: cpu)."),
    seed: int | None = typer.Option(None, help="Seed of data order, noise and initialisation (default: 0)."),
    checkpoint_minutes: float | None = typer.Option(
        None, help="Minutes between atomic checkpoints (default: 5.0)."),
    accel_weight: float | None = typer.Option(None, help="329-d data: weight of L_accel, the output's joint "
                                              "accelerations (default: 0.1)."),
    phys_weight: float | None = typer.Option(None, help="biomo: weight of L_phys, the physical network's "
                                             "accelerations (default: 1.0)."),
    emg_weight: float | None = typer.Option(None, help="biomo: weight of its muscle-activation loss "
                                            "(default: 1.0)."),
    phys_drop: float | None = typer.Option(None, help="biomo: probability P_c of dropping the physical "
                                           "network, for physics guidance (default: 0.1)."),
    vel_weight: float | None = typer.Option(None, help="Weight of the velocity loss, the x0 error's "
                                            "frame-to-frame differences (MDM's lambda_vel) (default: 0.0)."),
    warmup: int | None = typer.Option(None, help="Steps of linear learning-rate warm-up (default: 200)."),
    caption_aug: float | None = typer.Option(
        None, help="Probability of each caption rewrite: another subject ('someone', 'a man'), a shorter "
        "clause ('a person kicks' for 'a person kicks forward with the left leg') (default: 0.0)."),
    init: Path | None = typer.Option(None, help="Start from this model folder's weights (fine-tuning); its "
                                     "shape replaces --arch, --d-model, --layers and --heads."),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in --out where it stopped."),
) -> None:
    """Train a text-to-motion denoiser (DDPM, x0 prediction, EMA, classifier-free text dropout).

    Unset options take TrainConfig's and DenoiserConfig's defaults (the values the help quotes)."""
    from physmotion.nets.denoiser import DenoiserConfig
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.train import TrainConfig, train_denoiser
    from physmotion.paths import check_output

    if init is not None and any(v is not None for v in (arch, d_model, layers, heads)):
        raise PhysmotionError("--init takes the starting model's shape: leave out --arch, --d-model, "
                              "--layers and --heads")  # fmt: skip
    # A run folder is never replaced: a finished or interrupted run is hours of work (no --overwrite).
    check_output(out, "folder", overwrite=resume,
                 hint="pass --resume to continue its run, or choose another -o")
    start = MotionDiffusion.load(init) if init is not None else None

    den = _with(DenoiserConfig(), arch=arch, d_model=d_model, layers=layers, heads=heads)
    cfg = _with(TrainConfig(data=str(data), out=str(out), denoiser=den), crop=crop, max_length=max_length,
                batch_size=batch_size, steps=steps, lr=lr, bf16=bf16, device=device, seed=seed,
                checkpoint_minutes=checkpoint_minutes, accel_weight=accel_weight, phys_weight=phys_weight,
                emg_weight=emg_weight, phys_drop=phys_drop, vel_weight=vel_weight, warmup=warmup,
                caption_aug=caption_aug)  # fmt: skip
    info = {"init": {"model": str(init), "steps": start.info.get("steps")}} if start is not None else None
    result = train_denoiser(cfg, resume=resume, progress=sys.stderr.isatty(), init=start, info=info)
    last = f", last loss {result.losses[-1][1]:.4f}" if result.losses else ""
    console.print(f"trained to step {result.step} in {result.seconds / 60:.1f} min{last}; model in {out}",
                  highlight=False)


@train_app.command("imitator")
def train_imitator_cmd(
    data: list[Path] = typer.Option([], help="Built dataset folder(s) (`data build`): their train split, "
                                    "mirrored copies included, is imitated; repeat for several."),
    motions: list[Path] = typer.Option([], help="Folder(s) of generated .npz motions (`generate --physics "
                                       "none`) to imitate as well: what P is asked to project."),
    out: Path = typer.Option(..., "-o", "--out", help="Run folder: checkpoint.pt, log.csv, eval.csv, "
                             "curves.png, policy/. Must be new or empty, unless --resume continues it."),
    minutes: float | None = typer.Option(None, help="Stop after this many minutes (at a checkpoint)."),
    iterations: int | None = typer.Option(None, help="Stop after this many more PPO iterations."),
    envs: int | None = typer.Option(None, help="Parallel episodes (default: 16)."),
    workers: int | None = typer.Option(None, help="Environment processes, 0: one per core (default: 0)."),
    device: str = typer.Option("cpu", help="Where the networks train: cpu or cuda (the simulation is on "
                               "the CPU either way)."),
    seed: int | None = typer.Option(None, help="Seed (default: 0)."),
    eval_clips: int = typer.Option(16, "--eval-clips", help="Evaluation set: this many clips, shared "
                                   "between the sources: the datasets' test splits (unmirrored) and every 8th "
                                   "motion of --motions (left out of training)."),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in --out where it stopped."),
) -> None:
    """Train the imitation policy P can use (PPO, rsl-rl), in resumable chunks."""
    from physmotion.imitator.clips import training_sets
    from physmotion.imitator.train import ImitatorTrainConfig, train_imitator

    clips, evals = training_sets(data, motions, eval_clips)
    cfg = _with(ImitatorTrainConfig(), num_envs=envs, workers=workers, seed=seed)
    policy_dir = train_imitator(out, clips, evals, iterations=iterations, minutes=minutes,
                                resume=resume, config=cfg, device=device,
                                sources=[str(p) for p in [*data, *motions]], log=console.print)  # fmt: skip
    console.print(f"policy in {policy_dir}; use it with --controller policy --policy {policy_dir}",
                  highlight=False)


@train_app.command("evaluator")
def train_evaluator_cmd(
    data: Path = typer.Option(..., help="HumanML3D-layout folder with train (and val, test) splits."),
    out: Path = typer.Option(..., "-o", "--out", help="Output evaluator folder; must be new or empty."),
    epochs: int = typer.Option(150, help="Epochs over the train split; the best on val is kept."),
    batch_size: int = typer.Option(32, help="Batch size (contrastive negatives per caption)."),
    lr: float = typer.Option(1e-4, help="AdamW learning rate."),
    latent_dim: int = typer.Option(64, help="Embedding width."),
    device: str = typer.Option("cpu", help="cpu or cuda."),
    seed: int = typer.Option(0, help="Seed of data order, crops and initialisation."),
) -> None:
    """Train the text-motion evaluator (TMR-style contrastive retrieval) used by `physmotion evaluate`."""
    from physmotion.eval.evaluator import EvaluatorConfig
    from physmotion.eval.train import EvaluatorTrainConfig, train_evaluator
    from physmotion.paths import check_output

    check_output(out, "folder", hint="choose another -o (a trained evaluator is never replaced)")

    cfg = EvaluatorTrainConfig(data=str(data), out=str(out), evaluator=EvaluatorConfig(latent_dim=latent_dim),
                               epochs=epochs, batch_size=batch_size, lr=lr, device=device, seed=seed)  # fmt: skip
    result = train_evaluator(cfg, progress=sys.stderr.isatty())
    test = result.test["own_captions"] if result.test else None
    score = f"; test R@1 {test['R@1']['mean']:.3f}, R@3 {test['R@3']['mean']:.3f}" if test else ""
    console.print(f"trained in {result.seconds / 60:.1f} min, kept epoch {result.best_epoch}{score}; "
                  f"evaluator in {out}", highlight=False)  # fmt: skip


@train_app.command("length")
def train_length_cmd(
    data: Path = typer.Option(..., help="Built dataset folder (`data build`): its captions and clip lengths."),
    out: Path = typer.Option(..., "-o", "--out", help="Output folder: model.safetensors, card.json, README.md "
                             "(the shipped one is physmotion/weights/length)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace a length model already in --out."),
) -> None:
    """Train the length model `generate` asks when --seconds is not given (seconds from the caption)."""
    from physmotion.paths import check_output
    from physmotion.text.length import train_length

    check_output(out, "folder", overwrite=overwrite)
    r = train_length(data, out)
    console.print(f"test MAE {r.test_mae:.2f} s (constant 6 s: {r.test_mae_const6:.2f} s, the train mean "
                  f"{r.train_mean:.2f} s: {r.test_mae_mean:.2f} s); ridge {r.alpha:g}; model in {out}",
                  highlight=False)  # fmt: skip


@app.command("evaluate")
def evaluate_cmd(
    data: Path = typer.Option(..., help="HumanML3D-layout folder to evaluate on."),
    model: Path | None = typer.Option(None, help=MODEL_HELP),
    evaluator: Path | None = typer.Option(None, help="Evaluator folder; the shipped one if left out."),
    split: str | None = typer.Option(None, help="Split to evaluate on (default: test)."),
    physics: str | None = typer.Option(
        None, help="Comma-separated modes: none, none+floor, post:K, physdiff:<schedule>, morph "
        "(default: none,none+floor,post:1,post:4,physdiff:end:2,space:1)."),
    repeats: int | None = typer.Option(
        None, help="Repeated generation runs (95% intervals over them) (default: 3)."),
    steps: int | None = typer.Option(None, help="Sampling steps of the model's sampler; a BioMoDiffuse model "
                                     "samples 10 SDE DPM-Solver++ steps (default: 10)."),
    sampler: str | None = typer.Option(None, help=SAMPLER_HELP),
    eta: float | None = typer.Option(None, help=ETA_HELP),
    cfg_scale: float | None = typer.Option(None, help=CFG_HELP),
    seed: int | None = typer.Option(None, help="Random seed (default: 0)."),
    quick: bool = typer.Option(False, "--quick", help="Smoke run: 32 motions, 2 repeats, 10 steps."),
    controller: str = typer.Option("tracker", help=CONTROLLER_HELP),
    policy: Path | None = typer.Option(None, help=POLICY_HELP),
    out: Path = typer.Option(Path("results/evaluate"), "-o", "--out", help="Writes <out>.md and <out>.json."),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Generation metrics (our evaluator) and physical metrics per physics mode, as the papers' tables.

    Unset options take EvaluateConfig's defaults (the values the help quotes)."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.samplers import default_sampler
    from physmotion.eval.evaluator import Evaluator
    from physmotion.eval.table import EvaluateConfig, evaluate, table_paths
    from physmotion.pipelines.modes import parse_modes

    for written in table_paths(out):  # EvalTable.write's names
        _check_out(written, overwrite)
    _check_sampler_options(steps=steps, eta=eta, cfg_scale=cfg_scale)  # before the model loads
    modes = tuple(str(m) for m in parse_modes(physics)) if physics is not None else None
    cfg = _with(EvaluateConfig.quick() if quick else EvaluateConfig(), modes=modes, split=split, seed=seed,
                repeats=None if quick else repeats)
    net, judge = MotionDiffusion.load(_model_dir(model)), Evaluator.load(evaluator)
    cfg.base.sampler = _with(default_sampler(net), steps=cfg.base.sampler.steps if quick else steps,
                             sampler=sampler, eta=eta, cfg_scale=cfg_scale)
    cfg.base = cfg.base.with_controller(controller, _opt_str(policy))
    with _step_bar("evaluating") as tick, _as_options(**SAMPLER_OPTIONS):
        table = evaluate(net, judge, data, cfg, on_progress=tick)
    paths = table.write(out)
    console.print(table.to_markdown(), highlight=False, markup=False, emoji=False)
    console.print("wrote " + ", ".join(str(p) for p in paths), highlight=False)


@app.command("render")
def render_cmd(
    paths: list[Path] = typer.Argument(..., help="Motion files: .npz, or .bvh (imported on the fly)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .gif or .mp4 (mp4 needs the 'video' extra), "
                             "or .png with --frame."),
    layout: str = typer.Option("side", help="side (one panel per motion) or overlay (one panel, a colour "
                               "per motion, with a legend)."),
    frame: int | None = typer.Option(None, help="Write only this frame (0-based, at the common rate) as a .png."),
    size: int = typer.Option(480, help="Pixels per panel (square)."),
    rig: str | None = typer.Option(None, help=BVH_RIG_HELP),
    fps: float | None = typer.Option(None, help=BVH_FPS_HELP),
    mapping: Path | None = typer.Option(None, help=BVH_MAPPING_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Draw motions side by side or overlaid: floor grid with a 1 m bar, frame/time counter, foot contacts.

    Motions at different rates are resampled to the highest; a shorter motion holds its last frame."""
    from physmotion.render import render_files

    _check_out(out, overwrite)
    done = render_files(paths, out, layout=layout, size=size, frame=frame, rig=rig, fps=fps,  # type: ignore[arg-type]
                        mapping=mapping)
    console.print(f"wrote {out}: {done.frames} frame(s) at {done.fps:g} fps, {done.width}x{done.height} px",
                  highlight=False)


@app.command("view")
def view_cmd(
    paths: list[Path] = typer.Argument(..., help="Motion files: .npz, or .bvh (imported on the fly)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .html: one self-contained page, no network."),
    rig: str | None = typer.Option(None, help=BVH_RIG_HELP),
    fps: float | None = typer.Option(None, help=BVH_FPS_HELP),
    mapping: Path | None = typer.Option(None, help=BVH_MAPPING_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Write a 3-D viewer page (WebGL): orbit camera, play/pause, scrub slider, foot contacts, floor grid."""
    from physmotion.viewer import view_files

    _check_out(out, overwrite)
    done = view_files(paths, out, rig=rig, fps=fps, mapping=mapping)
    console.print(f"wrote {out}: {done.frames} frames at {done.fps:g} fps, {done.bytes / 1e6:.1f} MB; "
                  "open it in a browser", highlight=False)  # fmt: skip


@app.command("serve")
def serve_cmd(
    host: str = typer.Option("127.0.0.1", help="Address to listen on; only this machine reaches 127.0.0.1."),
    port: int = typer.Option(8000, help="Port to listen on (0: any free port; the address is printed)."),
    model: Path | None = typer.Option(None, help=MODEL_HELP),
    physics: str = typer.Option("physdiff", help="The page's and the JSON endpoint's default physics mode "
                                "(any of generate's; a request may name another)."),
    seconds: float | None = typer.Option(None, help="The page's and the JSON endpoint's default length in "
                                         "seconds (default: predicted from each prompt; a request may give "
                                         "its own)."),
    allow_host: list[str] = typer.Option([], "--allow-host", help="A Host name (or address) to answer besides "
                                         "localhost, 127.0.0.1, [::1] and --host, e.g. this machine's name on "
                                         "the network when --host is 0.0.0.0; '*.example.org' for its "
                                         "subdomains, '*' for any (no DNS rebinding guard). Repeatable."),
    waiting: int = typer.Option(4, help="Requests that may wait behind the one being generated; past that the "
                                "server answers 503 (busy) at once."),
    steps: int | None = typer.Option(None, help="Sampling steps, as generate's --steps: fewer answer sooner "
                                     "(default: the model's sampler's, 10 DPM-Solver++ steps for the shipped "
                                     "models)."),
) -> None:
    """A local web app that keeps the model warm: type a prompt, watch the motion, download it; and a JSON
    endpoint for scripts (POST /api/generate)."""
    try:
        from physmotion.serve import ServeConfig, bind, check_physics, make_app, serve, url_of
    except ImportError as exc:
        raise PhysmotionError(f"physmotion serve needs the 'serve' extra ({exc.name} is missing): "
                              "pip install 'physmotion[serve]'") from None
    check_physics(physics)
    config = ServeConfig(physics=physics, seconds=seconds, waiting=waiting, steps=steps, host=host,
                         allowed_hosts=tuple(allow_host))  # fmt: skip
    sock = bind(host, port)
    app_ = make_app(_model_dir(model), config,
                    log=lambda line: console.print(line, highlight=False))
    if host not in ("127.0.0.1", "localhost", "::1"):
        _warn(f"listening on {host}: other machines can reach this server")
    console.print(f"serving on {url_of(sock)} (Ctrl-C stops)", highlight=False)
    serve(app_, sock)


# morph commands
morph_app = typer.Typer(help="Morph: synthetic motions refined by physics, selected, and fine-tuned on.",
                        no_args_is_help=True, context_settings=HELP)  # fmt: skip
app.add_typer(morph_app, name="morph")


# FinetuneConfig.floor's default (a test checks they agree); named here so that --help needs no torch.
FLOOR_HELP = (f"Floor of the training motions and so of the model's samples: '{FLOOR_SURFACE}' (the humanoid's soles "
              f"on the floor, as P simulated them) or '{FLOOR_JOINTS}' (HumanML3D's lowest joint on y = 0) "
              f"(default: {FLOOR_SURFACE}).")


ILC_HELP = ("Refine with P under iterative learning control, this many passes more per motion (as "
            "'physmotion project --ilc'; each costs one more simulation) (default: 0).")


@morph_app.command("synth")
def morph_synth_cmd(
    data: Path = typer.Option(..., help="HumanML3D-layout folder whose train captions are generated."),
    out: Path = typer.Option(..., "-o", "--out", help="Synthetic data folder; an unfinished run of the same "
                             "model and settings there is continued."),
    model: Path | None = typer.Option(None, help=MODEL_HELP),
    per_caption: int | None = typer.Option(None, "--per-caption", help="Samples per train caption (default: 1)."),
    seed: int | None = typer.Option(None, help="Random seed of noise and lengths (default: 0)."),
    workers: int | None = typer.Option(None, help="Physics worker processes (0: one per core) (default: 0)."),
    ilc: int | None = typer.Option(None, "--ilc", help=ILC_HELP),
    controller: str | None = typer.Option(None, help=CONTROLLER_HELP + " (default: tracker)"),
    policy: Path | None = typer.Option(None, help=POLICY_HELP),
) -> None:
    """Generate motions for every train caption and refine each with the physics projection P (Morph)."""
    from physmotion.morph.synth import SynthConfig, synthesize

    with _as_options(ilc_passes="--ilc", controller="--controller"):  # SynthConfig checks P's settings
        cfg = _with(SynthConfig(), per_caption=per_caption, seed=seed, workers=workers, ilc_passes=ilc,
                    controller=controller, policy=_opt_str(policy))  # fmt: skip
    report = synthesize(_model_dir(model), data, out, cfg, progress=sys.stderr.isatty())
    console.print(f"{out}: {report.done} new item(s), {report.total_done}/{report.planned} done in "
                  f"{report.seconds:.0f} s (sampling {report.sampling_seconds:.0f} s, physics "
                  f"{report.physics_seconds:.0f} s)", highlight=False)  # fmt: skip


@morph_app.command("select")
def morph_select_cmd(
    synth: Path = typer.Argument(..., help="A synthetic data folder made by 'physmotion morph synth'."),
    tau: float | None = typer.Option(None, help="MPJPE threshold in metres (default: Morph's 0.5)."),
) -> None:
    """Morph's imitation selection: refined motion where P imitated it, else the generated input."""
    from physmotion.morph.selection import TAU, select

    sel = select(synth, tau=TAU if tau is None else tau)
    c = sel.counts
    console.print(f"{c['items']} item(s): {c['refined']} refined, {c['input']} input; IFR {sel.ifr:.3f} "
                  f"({c['failed']} of {c['grounded']} grounded refinements rejected, {c['episode_failed']} "
                  f"fell); non-grounded captions (kept as input, not in IFR): {c['non_grounded']}",
                  highlight=False)  # fmt: skip
    if sel.help:
        h = sel.help
        console.print(f"P's help on the refined motions: root residual force mean {h['residual_force']:.3f} W, "
                      f"at its cap in {100 * h['residual_at_cap']:.1f} % of frames; a joint's torque over its "
                      f"actuator's limit in {100 * h['over_limit']:.1f} % of frames", highlight=False)  # fmt: skip


_MIX_HELP = "Share of synthetic motions in each batch; 0: the control on real motions alone (default: 0.1)."


@morph_app.command("finetune")
def morph_finetune_cmd(
    model: Path = typer.Option(..., help="Model folder to fine-tune (the one that made --synth), or a shipped "
                               "model's name (base, morph)."),
    synth: Path = typer.Option(..., help="Synthetic data folder made by 'physmotion morph synth' with --model."),
    data: Path = typer.Option(..., help="HumanML3D-layout folder whose train split is mixed in."),
    out: Path = typer.Option(..., "-o", "--out", help="Run folder: model, train_state.pt, loss.csv. Must be "
                             "new or empty, unless --resume continues the run in it."),
    mix: float | None = typer.Option(None, help=_MIX_HELP),
    lr: float | None = typer.Option(None, help="AdamW learning rate (Morph: 1e-5) (default: 1e-05)."),
    steps: int | None = typer.Option(None, help="Fine-tuning optimiser steps (default: 2000)."),
    batch_size: int | None = typer.Option(None, help="Batch size (default: the model's training run's)."),
    tau: float | None = typer.Option(None, help="Imitation selection threshold, metres (default: 0.5)."),
    seed: int | None = typer.Option(None, help="Seed of data order and noise (default: 0)."),
    floor: str | None = typer.Option(None, help=FLOOR_HELP),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in --out where it stopped."),
) -> None:
    """Morph's Stage 2: fine-tune a model on its physics-refined synthetic motions mixed with real ones."""
    from physmotion.morph.finetune import FinetuneConfig, finetune
    from physmotion.paths import check_output

    check_output(out, "folder", overwrite=resume, hint="pass --resume to continue its run, or choose another -o")
    base = FinetuneConfig(model=str(_model_dir(model)), synth=str(synth), data=str(data), out=str(out))
    cfg = _with(base, mix=mix, lr=lr, steps=steps, batch_size=batch_size, tau=tau, seed=seed, floor=floor)
    result = finetune(cfg, resume=resume, progress=sys.stderr.isatty())
    c, last = result.selection.counts, result.train.losses[-1][1] if result.train.losses else float("nan")
    data = (f"{result.synthetic_items} synthetic ({c['refined']} refined, {c['input']} input, IFR "
            f"{result.selection.ifr:.3f}) and {result.real_items} real motions" if cfg.mix > 0
            else f"{result.real_items} real motions alone (--mix 0: the control)")  # fmt: skip
    console.print(f"fine-tuned to step {result.train.step} on {data}, last loss {last:.4f}; model in {out}",
                  highlight=False)


@morph_app.command("run")
def morph_run_cmd(
    model: Path = typer.Option(..., help="Model folder of round 1, or a shipped model's name (base, morph)."),
    data: Path = typer.Option(..., help="HumanML3D-layout folder: its train captions and motions."),
    out: Path = typer.Option(..., "-o", "--out", help="Run folder (round_<k>/synth, round_<k>/model, rounds.md); "
                             "a run from the same model there is continued, finished rounds skipped."),
    rounds: int = typer.Option(..., help="Rounds of synthesis, selection and fine-tuning."),
    per_caption: int | None = typer.Option(None, "--per-caption", help="Samples per train caption (default: 1)."),
    steps: int | None = typer.Option(None, help="Fine-tuning steps per round (default: 2000)."),
    mix: float | None = typer.Option(None, help=_MIX_HELP),
    lr: float | None = typer.Option(None, help="Fine-tuning learning rate (default: 1e-05)."),
    seed: int | None = typer.Option(None, help="Random seed of synthesis and fine-tuning (default: 0)."),
    floor: str | None = typer.Option(None, help=FLOOR_HELP),
    ilc: int | None = typer.Option(None, "--ilc", help=ILC_HELP),
) -> None:
    """Morph's multi-round loop: per round, synthesise and refine, select, fine-tune from the last round."""
    from physmotion.morph.finetune import FinetuneConfig
    from physmotion.morph.loop import check_run_dir, run_rounds
    from physmotion.morph.synth import SynthConfig
    from physmotion.paths import check_output

    check_output(out, "folder", overwrite=True)
    model = _model_dir(model)
    check_run_dir(out, model)
    with _as_options(ilc_passes="--ilc"):
        synth_cfg = _with(SynthConfig(), per_caption=per_caption, seed=seed, ilc_passes=ilc)
    ft_cfg = _with(FinetuneConfig(model="", synth="", data=str(data), out=""), steps=steps, mix=mix, lr=lr, seed=seed,
                   floor=floor)  # fmt: skip
    rows = run_rounds(model, data, out, rounds, synth_cfg, ft_cfg, progress=sys.stderr.isatty())
    last = rows[-1]
    console.print(f"{len(rows)} round(s) done; last: IFR {last.ifr:.3f}, loss {last.final_loss:.4f}, model in "
                  f"{last.model}; table in {out / 'rounds.md'}", highlight=False)  # fmt: skip


def main() -> None:
    """Entry point of the console script: user errors become one line, never a traceback."""
    import warnings

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, PhysmotionWarning):
            _warn(str(message))
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show  # a library warning reads as one line, like an error
    try:
        app()
    except PhysmotionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(1) from None
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        raise SystemExit(130) from None


if __name__ == "__main__":
    main()
