"""The ``physmotion`` command line: thin commands over the library's public functions.

Any :class:`~physmotion.errors.PhysmotionError` becomes one line on stderr and exit code 1.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from physmotion.errors import PhysmotionError

app = typer.Typer(
    help="Text-to-motion generation that obeys physics.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,  # help is plain text: "physdiff:end:4" must not become an emoji
)
data_app = typer.Typer(help="Build and inspect HumanML3D-layout datasets.", no_args_is_help=True)
app.add_typer(data_app, name="data")
console = Console(soft_wrap=True)


@data_app.command("build")
def data_build(
    source: Path = typer.Option(..., help="Mocap folder with manifest.csv (e.g. ../shared/data/mocap)."),
    out: Path = typer.Option(..., help="Output folder (HumanML3D layout)."),
    exclude_license: list[str] = typer.Option([], "--exclude-license", help="Leave out clips with this licence tag, e.g. NC."),
    seed: int = typer.Option(0, help="Salt of the take -> split assignment."),
    mirror: bool = typer.Option(True, help="Add left/right mirrored copies, as HumanML3D does."),
    jobs: int = typer.Option(0, help="Worker processes (0: one per core)."),
) -> None:
    """Import every clip of a mocap collection into a HumanML3D-layout dataset."""
    from physmotion.data.build import BuildConfig, build_dataset

    config = BuildConfig(exclude_licences=tuple(exclude_license), seed=seed, mirror=mirror, jobs=jobs)
    report = build_dataset(source, out, config, progress=sys.stderr.isatty())
    for clip, reason in sorted(report.skipped.items()):
        console.print(f"[yellow]skipped[/] {clip}: {reason}", highlight=False)
    items = ", ".join(f"{k} {v}" for k, v in report.num_items.items())
    console.print(
        f"built {out}: {report.num_clips - len(report.skipped)}/{report.num_clips} clips, "
        f"{report.minutes:.1f} min of motion; items: {items}",
        highlight=False,
    )


@data_app.command("stats")
def data_stats(root: Path = typer.Argument(..., help="A HumanML3D-layout folder.")) -> None:
    """Print counts, minutes and the caption vocabulary of a dataset."""
    from physmotion.data.stats import dataset_stats

    stats = dataset_stats(root)
    table = Table(title=f"dataset {root}")
    table.add_column("split")
    table.add_column("motions", justify="right")
    table.add_column("minutes", justify="right")
    for split, n in stats.items.items():
        table.add_row(split, str(n), f"{stats.minutes[split]:.1f}")
    table.add_row("all", str(sum(stats.items.values())), f"{stats.total_minutes:.1f}")
    console.print(table)
    if stats.licences:
        console.print("licences: " + ", ".join(f"{k} {v}" for k, v in stats.licences.items()))
    top = ", ".join(f"{w} {c}" for w, c in stats.vocabulary.most_common(30))
    console.print(f"captions: {stats.captions}; vocabulary: {len(stats.vocabulary)} words; most common: {top}")


@app.command("import")
def import_motion(
    path: Path = typer.Argument(..., help="A .bvh or .amc file (an .amc needs --asf)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .npz (or .bvh)."),
    rig: str | None = typer.Option(None, help="Rig table name (see physmotion.io.rigs); guessed if left out."),
    asf: Path | None = typer.Option(None, help="The skeleton (.asf) of an .amc file."),
    fps: float | None = typer.Option(None, help="True frame rate, where the header is wrong or absent."),
    up_axis: str | None = typer.Option(None, help="Y or Z, overriding the rig's."),
    units: str | None = typer.Option(None, help="cm, m, inch or a factor to metres, overriding the rig's."),
) -> None:
    """Import one mocap file to the 22-joint skeleton at 20 fps, Y up, floor at 0, facing +Z."""
    from physmotion.io.export import save_motion
    from physmotion.io.importer import import_clip

    motion = import_clip(path, rig=rig, asf=asf, fps=fps, up_axis=up_axis, units=units)
    save_motion(motion, out)
    console.print(f"wrote {out}: {motion.num_frames} frames, {motion.seconds:.1f} s", highlight=False)


@app.command("export")
def export_motion(
    path: Path = typer.Argument(..., help="A motion .npz."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .bvh or .npz."),
) -> None:
    """Write a motion to BVH (metres, Y up, the 22-joint rig) or .npz."""
    from physmotion.io.export import save_motion
    from physmotion.motion import Motion

    save_motion(Motion.load(path), out)
    console.print(f"wrote {out}", highlight=False)


@app.command("project")
def project_motion(
    path: Path = typer.Argument(..., help="A motion .npz (joints at any fps)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .npz with the projected motion."),
) -> None:
    """Physics projection (PhysDiff's P): imitate the motion with the simulated humanoid."""
    from dataclasses import replace

    from physmotion.motion import Motion
    from physmotion.physics.projection import project

    motion = Motion.load(path)
    result = project(motion.joints, motion.fps)
    body = result.body if result.selected else None  # the input kept is not the humanoid's motion
    resets = int(result.resets) if result.selected else None
    replace(motion, joints=result.joints, rotations=None, offsets=None, humanoid=body, resets=resets).save(out)
    kept = "simulation kept" if result.selected else "tracking failed: input kept (flagged)"
    console.print(
        f"wrote {out}: {kept}; MPJPE mean {1000 * result.mpjpe.mean():.0f} mm, "
        f"root residual mean {result.residual_force.mean():.2f} W",
        highlight=False,
    )


@app.command("metrics")
def metrics(
    paths: list[Path] = typer.Argument(..., help="Motion .npz files (joints, fps)."),
    surface: str = typer.Option(
        "humanoid", help="Body surface for Penetrate/Float/Skate: 'humanoid' (MuJoCo geometry posed on "
        "the joints: the simulated body where the file carries it, as generate writes for projected "
        "motions) or 'joints' (a light model built from the joints alone)."),
) -> None:
    """Print the physical metrics (PhysDiff, EDGE/Morph, BioMoDiffuse) of one or more motions."""
    from physmotion.metrics import format_table, physical_metrics
    from physmotion.motion import Motion

    if surface not in ("humanoid", "joints"):
        raise PhysmotionError(f"--surface must be 'humanoid' or 'joints', got {surface!r}")
    results = {}
    for path in paths:
        motion = Motion.load(path)
        body = None
        if surface == "humanoid":
            from physmotion.physics.surface import HumanoidSurface

            body = HumanoidSurface(motion.humanoid)  # P's body where the file has it, else estimated
        results[path.name] = physical_metrics(motion.joints, fps=motion.fps, body=body)
    console.print(format_table(results, title=f"physical metrics ({surface} surface)"))


@app.command("generate")
def generate_cmd(
    texts: list[str] = typer.Argument(..., help="One or more captions, e.g. \"a person walks forward\"."),
    out: Path = typer.Option(Path("out"), "-o", "--out", help="Output folder."),
    seconds: float | None = typer.Option(None, help="Length of each motion in seconds (default: 6)."),
    physics: str | None = typer.Option(
        None, help="none, none+floor (plain sampling, shifted onto the floor as well as a constant "
        "shift can), post[:K] (K projections after sampling) or physdiff[:SCHEDULE] (projection "
        "inside sampling; SCHEDULE uniform:N, start:M,end:N or end:N,space:S) "
        "(default: physdiff:end:4,space:1)."),
    num: int | None = typer.Option(None, help="Samples per caption (default: 1)."),
    seed: int | None = typer.Option(None, help="Random seed; the same seed gives the same motions (default: 0)."),
    sampler: str | None = typer.Option(None, help="ddim, ddpm or dpmpp (DPM-Solver++ 2M, Karras) (default: ddim)."),
    steps: int | None = typer.Option(None, help="Sampling steps (default: 50)."),
    eta: float | None = typer.Option(None, help="DDIM eta (default: 0)."),
    cfg_scale: float | None = typer.Option(None, help="Classifier-free guidance scale (default: 2.5)."),
    model: Path | None = typer.Option(None, help="Model folder; the shipped model if left out."),
    preview: bool = typer.Option(True, help="Write a GIF preview per motion."),
) -> None:
    """Generate motions from text: .npz, .bvh and a GIF preview per sample.

    Unset options take GenerateConfig's and SamplerConfig's defaults (the values the help quotes)."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.generate import GenerateConfig, check_request, generate, write_outputs

    cfg = _with(GenerateConfig(), seconds=seconds, num=num, physics=physics, seed=seed)
    cfg.sampler = _with(cfg.sampler, sampler=sampler, steps=steps, eta=eta, cfg_scale=cfg_scale)
    net = MotionDiffusion.load(model)
    check_request(texts, cfg, net)
    with _step_bar("generating") as tick:
        result = generate(texts, cfg, net, on_step=tick)
    paths = write_outputs(result, out, cfg, preview=preview)
    log = result.projections
    phys = ""
    if log.tracked:
        phys = (f"; humanoid tracked without a fall in {sum(log.tracked)}/{len(log.tracked)} projections, "
                f"{sum(result.resets)} reset(s) in the outputs (each a jump back onto the motion)")
    console.print(f"wrote {len(result.motions)} motion(s) to {out} ({len(paths)} files){phys}", highlight=False)


def _with(config, **given):
    """``config`` with the options the user gave (not None) replaced: the dataclass holds every default."""
    from dataclasses import replace

    return replace(config, **{k: v for k, v in given.items() if v is not None})


def _step_bar(label: str):
    """A context manager yielding tick(done, total) that drives a rich progress bar (silent if not a TTY)."""
    from contextlib import contextmanager

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    @contextmanager
    def bar():
        progress = Progress(TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                            console=Console(stderr=True), disable=not sys.stderr.isatty())
        with progress:
            task = progress.add_task(label, total=None)
            yield lambda done, total: progress.update(task, completed=done, total=total)

    return bar()


train_app = typer.Typer(help="Train models.", no_args_is_help=True)
app.add_typer(train_app, name="train")


@train_app.command("denoiser")
def train_denoiser_cmd(
    data: Path = typer.Option(..., help="HumanML3D-layout folder (our build or a real HumanML3D)."),
    out: Path = typer.Option(..., "-o", "--out", help="Run folder: model, train_state.pt, loss.csv."),
    arch: str | None = typer.Option(
        None, help="transformer (MDM) or unet (BioMoDiffuse's 1D UNet) (default: transformer)."),
    d_model: int | None = typer.Option(None, help="Width (default: 256)."),
    layers: int | None = typer.Option(None, help="Transformer layers, or UNet levels (default: 4)."),
    heads: int | None = typer.Option(None, help="Attention heads (default: 4)."),
    crop: int | None = typer.Option(
        None, help="Training windows are cropped to at most this many frames (default: 196)."),
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
    resume: bool = typer.Option(False, "--resume", help="Continue the run in --out where it stopped."),
) -> None:
    """Train a text-to-motion denoiser (DDPM, x0 prediction, EMA, classifier-free text dropout).

    Unset options take TrainConfig's and DenoiserConfig's defaults (the values the help quotes)."""
    from physmotion.diffusion.denoiser import DenoiserConfig
    from physmotion.diffusion.train import TrainConfig, train_denoiser

    den = _with(DenoiserConfig(), arch=arch, d_model=d_model, layers=layers, heads=heads)
    cfg = _with(TrainConfig(data=str(data), out=str(out), denoiser=den), crop=crop, batch_size=batch_size,
                steps=steps, lr=lr, bf16=bf16, device=device, seed=seed, checkpoint_minutes=checkpoint_minutes)
    result = train_denoiser(cfg, resume=resume, progress=sys.stderr.isatty())
    last = f", last loss {result.losses[-1][1]:.4f}" if result.losses else ""
    console.print(f"trained to step {result.step} in {result.seconds / 60:.1f} min{last}; model in {out}",
                  highlight=False)


@train_app.command("evaluator")
def train_evaluator_cmd(
    data: Path = typer.Option(..., help="HumanML3D-layout folder with train (and val, test) splits."),
    out: Path = typer.Option(..., help="Output evaluator folder."),
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

    cfg = EvaluatorTrainConfig(data=str(data), out=str(out), evaluator=EvaluatorConfig(latent_dim=latent_dim),
                               epochs=epochs, batch_size=batch_size, lr=lr, device=device, seed=seed)  # fmt: skip
    result = train_evaluator(cfg, progress=sys.stderr.isatty())
    test = result.test["own_captions"] if result.test else None
    score = f"; test R@1 {test['R@1']['mean']:.3f}, R@3 {test['R@3']['mean']:.3f}" if test else ""
    console.print(f"trained in {result.seconds / 60:.1f} min, kept epoch {result.best_epoch}{score}; "
                  f"evaluator in {out}", highlight=False)  # fmt: skip


@app.command("evaluate")
def evaluate_cmd(
    data: Path = typer.Option(..., help="HumanML3D-layout folder to evaluate on."),
    model: Path | None = typer.Option(None, help="Model folder; the shipped model if left out."),
    evaluator: Path | None = typer.Option(None, help="Evaluator folder; the shipped one if left out."),
    split: str | None = typer.Option(None, help="Split to evaluate on (default: test)."),
    physics: str | None = typer.Option(
        None, help="Comma-separated modes: none, none+floor, post:K, physdiff:<schedule> "
        "(default: none,none+floor,post:1,post:4,physdiff:end:4,space:1)."),
    repeats: int | None = typer.Option(
        None, help="Repeated generation runs (95% intervals over them) (default: 3)."),
    steps: int | None = typer.Option(None, help="Sampling steps (DDIM) (default: 50)."),
    seed: int | None = typer.Option(None, help="Random seed (default: 0)."),
    quick: bool = typer.Option(False, "--quick", help="Smoke run: 32 motions, 2 repeats, 10 steps."),
    out: Path = typer.Option(Path("results/evaluate"), "-o", "--out", help="Writes <out>.md and <out>.json."),
) -> None:
    """Generation metrics (our evaluator) and physical metrics per physics mode, as the papers' tables.

    Unset options take EvaluateConfig's defaults (the values the help quotes)."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.eval.evaluator import Evaluator
    from physmotion.eval.table import EvaluateConfig, evaluate
    from physmotion.physics_mode import parse_modes

    modes = tuple(str(m) for m in parse_modes(physics)) if physics is not None else None
    cfg = _with(EvaluateConfig.quick() if quick else EvaluateConfig(), modes=modes, split=split, seed=seed,
                repeats=None if quick else repeats)
    cfg.base.sampler = _with(cfg.base.sampler, steps=None if quick else steps)
    net, judge = MotionDiffusion.load(model), Evaluator.load(evaluator)
    with _step_bar("evaluating") as tick:
        table = evaluate(net, judge, data, cfg, on_progress=tick)
    paths = table.write(out)
    console.print(table.to_markdown(), highlight=False, markup=False, emoji=False)
    console.print("wrote " + ", ".join(str(p) for p in paths), highlight=False)


def main() -> None:
    """Entry point of the console script: user errors become one line, never a traceback."""
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
