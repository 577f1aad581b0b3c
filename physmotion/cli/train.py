"""``physmotion train``: train the denoiser, the imitation policy, the evaluator and the length model."""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from physmotion.cli._common import HELP, _with, app, console
from physmotion.errors import PhysmotionError

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
    teacher: list[Path] = typer.Option([], help="Teacher folder(s) (`train teacher`): track the "
                                       "search's trajectories with no outside hand (cap 0 throughout); the "
                                       "observation keeps the kinematic reference. Not with --data or "
                                       "--motions."),
    warm_start: Path | None = typer.Option(None, "--warm-start", help="Policy folder the actor starts from "
                                           "(e.g. a behaviour-cloned student); its layer widths, action "
                                           "scale and tracking are taken, the critic starts fresh."),
    init_std: float | None = typer.Option(None, "--init-std", help="Initial spread of the Gaussian actions, "
                                          "in action units (default: 0.3; with --warm-start, 0.1)."),
    action_scale: float | None = typer.Option(None, "--action-scale", help="rad per unit action (default: "
                                              "0.15; with --teacher, 0.5; --warm-start takes its own)."),
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
    from dataclasses import replace

    from physmotion.imitator.clips import training_sets
    from physmotion.imitator.train import ImitatorTrainConfig, no_hand_config, train_imitator

    if teacher and (data or motions):
        raise PhysmotionError("--teacher trains with no outside hand: give it without --data or --motions")
    if warm_start is not None and action_scale is not None:
        raise PhysmotionError("--warm-start takes its policy's action scale: leave out --action-scale")
    clips, evals = training_sets(data, motions, eval_clips, teacher)
    if init_std is None and warm_start is not None:
        init_std = 0.1  # a small spread, so that the first iterations do not undo the warm start
    cfg = _with(ImitatorTrainConfig(), num_envs=envs, workers=workers, seed=seed, init_std=init_std)
    if teacher:
        cfg = no_hand_config(cfg, **({} if action_scale is None else {"action_scale": action_scale}))
    elif action_scale is not None:
        settings = replace(cfg.env.settings, action_scale=action_scale)
        cfg = replace(cfg, env=replace(cfg.env, settings=settings))
    policy_dir = train_imitator(out, clips, evals, iterations=iterations, minutes=minutes,
                                resume=resume, config=cfg, device=device,
                                sources=[str(p) for p in [*data, *motions, *teacher]], warm_start=warm_start,
                                log=console.print)  # fmt: skip
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


@train_app.command("teacher")
def train_teacher_cmd(
    data: list[Path] = typer.Option([], help="Built dataset folder(s) (`data build`): their train split, "
                                    "mirrored copies included, is searched; repeat for several."),
    motions: list[Path] = typer.Option([], help="Folder(s) of generated .npz motions (`generate --physics "
                                       "none`, or `morph synth`'s prompts) to search as well."),
    out: Path = typer.Option(..., "-o", "--out", help="Teacher folder: <job>.npz per search and index.json; "
                             "jobs already in it are skipped, so a stopped run continues."),
    jobs: int | None = typer.Option(None, help="Search only the first this many jobs of the seeded order (a "
                                    "random sample of the whole; a larger number extends it)."),
    effort: str = typer.Option("default", help="The search's effort: fast, default or best."),
    perturbed: int = typer.Option(1, help="Searches per segment from a pushed start, besides the plain one."),
    workers: int = typer.Option(0, help="Local processes, one job each (0: one per core)."),
    ray: str | None = typer.Option(None, help="Run one Ray task per job on the cluster at this address, or "
                                   "'local' (needs `pip install 'physmotion[ray]'`; docs/cluster.md)."),
    seed: int = typer.Option(0, help="Seed of the job order, the pushes and the search."),
) -> None:
    """Search many motions with no outside hand and keep what a policy learns from (teacher records)."""
    from physmotion.imitator.clips import dataset_clips, motion_clips
    from physmotion.imitator.teacher import TeacherConfig, build_teacher_set, teacher_jobs
    from physmotion.physics.search import effort as search_effort

    if not data and not motions:
        raise PhysmotionError("give at least one --data or --motions folder")
    clips = [c for d in data for c in dataset_clips(d, "train")] + [c for m in motions for c in motion_clips(m)]
    config = TeacherConfig(search=search_effort(effort, seed), perturbed=perturbed, seed=seed)
    todo = teacher_jobs(clips, config)[:jobs]
    index = build_teacher_set(todo, out, config, workers, ray, progress=sys.stderr.isatty())
    console.print(f"{index['written']} of {len(todo)} searches in {out} ({index['completed']} to the end, "
                  f"{index['cpu_seconds'] / 60:.0f} CPU min in all)", highlight=False)  # fmt: skip


@train_app.command("student")
def train_student_cmd(
    teacher: Path = typer.Option(..., help="Teacher folder (`train teacher`)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output folder: bc/ and dagger<r>/ policy folders; must be "
                             "new or empty."),
    dagger_rounds: int = typer.Option(2, help="Rounds of DAgger after behaviour cloning."),
    labels: str = typer.Option("mppi", help="Who labels the states: 'mppi' (a deterministic, smooth function of "
                               "the state: 32 candidates on common random numbers, averaged by their costs; its "
                               "own episodes are the first data) or 'search' (the records' committed offsets, then "
                               "a small search around the student's proposal)."),
    steps: int | None = typer.Option(None, help="Gradient steps per fit (default: 3000)."),
    workers: int = typer.Option(0, help="Processes for DAgger's episodes and labels (0: one per core)."),
    seed: int = typer.Option(0, help="Seed of the fit and the labels' searches."),
) -> None:
    """Learn a fast controller from the search's teacher records (no outside hand): BC, then DAgger."""
    from physmotion.imitator.student import Labeller, StudentConfig, train_student
    from physmotion.imitator.teacher import load_teacher_set
    from physmotion.paths import check_output

    if labels not in ("mppi", "search"):
        raise PhysmotionError(f"--labels must be mppi or search, got {labels!r}")
    check_output(out, "folder")
    records = load_teacher_set(teacher)
    labeller = Labeller() if labels == "mppi" else Labeller(temperature=None, seed=seed)
    folders = train_student(records, out, _with(StudentConfig(seed=seed), steps=steps), dagger_rounds, labeller,
                            workers=workers, log=console.print)  # fmt: skip
    last = folders[list(folders)[-1]]
    console.print(f"students in {out}; use the last with --controller policy --policy {last}, or as the "
                  f"proposal of a small search: --controller search --policy {last}", highlight=False)  # fmt: skip
