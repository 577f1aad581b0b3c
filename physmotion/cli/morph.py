"""``physmotion morph``: synthesise, select and fine-tune (Morph; physmotion.morph)."""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from physmotion.cli._common import (
    CONTROLLER_HELP,
    HELP,
    MODEL_HELP,
    POLICY_HELP,
    _as_options,
    _model_dir,
    _opt_str,
    _with,
    app,
    console,
)
from physmotion.conventions import FLOOR_JOINTS, FLOOR_SURFACE

morph_app = typer.Typer(help="Morph: synthetic motions refined by physics, selected, and fine-tuned on.",
                        no_args_is_help=True, context_settings=HELP)  # fmt: skip
app.add_typer(morph_app, name="morph")


# FinetuneConfig.floor's default (a test checks they agree); named here so that --help needs no torch.
FLOOR_HELP = (f"Floor of the training motions and so of the model's samples: '{FLOOR_SURFACE}' (the humanoid's soles "
              f"on the floor, as P simulated them) or '{FLOOR_JOINTS}' (HumanML3D's lowest joint on y = 0) "
              f"(default: {FLOOR_SURFACE}).")


ILC_HELP = ("Refine with P under iterative learning control, this many passes more per motion (as "
            "'physmotion project --ilc'; each costs one more simulation) (default: 0).")


RAY_HELP = ("Refine on Ray, one task per motion, on the cluster at this address, or 'local' to start one on "
            "this machine, instead of --workers (needs pip install 'physmotion[ray]'; docs/cluster.md).")
CAPTIONS_HELP = ("Generate a seeded random subset of this many distinct train captions (a costly controller, a "
                 "quick run) (default: all).")


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
    captions: int | None = typer.Option(None, help=CAPTIONS_HELP),
    ray: str | None = typer.Option(None, help=RAY_HELP),
) -> None:
    """Generate motions for every train caption and refine each with the physics projection P (Morph)."""
    from physmotion.morph.synth import SynthConfig, synthesize

    with _as_options(ilc_passes="--ilc", controller="--controller"):  # SynthConfig checks P's settings
        cfg = _with(SynthConfig(), per_caption=per_caption, seed=seed, workers=workers, ilc_passes=ilc,
                    controller=controller, policy=_opt_str(policy), captions=captions, ray=ray)  # fmt: skip
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
    controller: str | None = typer.Option(None, help=CONTROLLER_HELP + " (default: tracker)"),
    policy: Path | None = typer.Option(None, help=POLICY_HELP),
    captions: int | None = typer.Option(None, help=CAPTIONS_HELP),
    ray: str | None = typer.Option(None, help=RAY_HELP),
) -> None:
    """Morph's multi-round loop: per round, synthesise and refine, select, fine-tune from the last round."""
    from physmotion.morph.finetune import FinetuneConfig
    from physmotion.morph.loop import check_run_dir, run_rounds
    from physmotion.morph.synth import SynthConfig
    from physmotion.paths import check_output

    check_output(out, "folder", overwrite=True)
    model = _model_dir(model)
    check_run_dir(out, model)
    with _as_options(ilc_passes="--ilc", controller="--controller"):
        synth_cfg = _with(SynthConfig(), per_caption=per_caption, seed=seed, ilc_passes=ilc, controller=controller,
                          policy=_opt_str(policy), captions=captions, ray=ray)  # fmt: skip
    ft_cfg = _with(FinetuneConfig(model="", synth="", data=str(data), out=""), steps=steps, mix=mix, lr=lr, seed=seed,
                   floor=floor)  # fmt: skip
    rows = run_rounds(model, data, out, rounds, synth_cfg, ft_cfg, progress=sys.stderr.isatty())
    last = rows[-1]
    console.print(f"{len(rows)} round(s) done; last: IFR {last.ifr:.3f}, loss {last.final_loss:.4f}, model in "
                  f"{last.model}; table in {out / 'rounds.md'}", highlight=False)  # fmt: skip
