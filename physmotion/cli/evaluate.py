"""``physmotion evaluate``: generation and physical metrics per physics mode (physmotion.eval)."""

from __future__ import annotations

from pathlib import Path

import typer

from physmotion.cli._common import (
    CFG_HELP,
    CONTROLLER_HELP,
    ETA_HELP,
    MODEL_HELP,
    OVERWRITE_HELP,
    POLICY_HELP,
    RECOVER_HELP,
    SAMPLER_HELP,
    SAMPLER_OPTIONS,
    RESCUE_HELP,
    SEARCH_FALLBACK_HELP,
    _as_options,
    _check_out,
    _check_sampler_options,
    _model_dir,
    _opt_str,
    _step_bar,
    _with,
    app,
    console,
)

@app.command("evaluate")
def evaluate_cmd(
    data: Path = typer.Option(..., help="HumanML3D-layout folder to evaluate on."),
    model: Path | None = typer.Option(None, help=MODEL_HELP),
    evaluator: Path | None = typer.Option(None, help="Evaluator folder; the shipped one if left out."),
    split: str | None = typer.Option(None, help="Split to evaluate on (default: test)."),
    physics: str | None = typer.Option(
        None, help="Comma-separated modes: none, none+floor, post:K, physdiff:<schedule>, morph "
        "(default: none, none+floor, post:1, post:4, physdiff:end:2,space:1,fly:last)."),
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
    search_fallback: bool = typer.Option(False, "--search-fallback", help=SEARCH_FALLBACK_HELP),
    recover: bool | None = typer.Option(None, "--recover/--no-recover", help=RECOVER_HELP),
    rescue_flights: bool = typer.Option(False, "--rescue-flights", help=RESCUE_HELP),
    out: Path = typer.Option(Path("results/evaluate"), "-o", "--out", help="Writes <out>.md and <out>.json."),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Generation metrics (our evaluator) and physical metrics per physics mode, as the papers' tables.

    Each finished (mode, repeat) run is kept in <out>.parts until the table is written, so a killed
    evaluation, run again with the same command, resumes. Unset options take EvaluateConfig's defaults
    (the values the help quotes)."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.samplers import default_sampler
    from physmotion.eval.evaluator import Evaluator
    from physmotion.eval.parts import count_parts, remove_parts
    from physmotion.eval.table import EvaluateConfig, evaluate, parts_folder, table_paths
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
    if search_fallback:
        cfg.base = cfg.base.with_search_fallback(True)
    if recover is not None:
        cfg.base = cfg.base.with_search_recovery(recover)
    if rescue_flights:
        cfg.base = cfg.base.with_flight_rescue(True)
    parts = parts_folder(out)
    if found := count_parts(parts):
        typer.echo(f"{parts}: {found} finished run(s) of an earlier evaluation; those made with these "
                   "settings are reused", err=True)
    with _step_bar("evaluating") as tick, _as_options(**SAMPLER_OPTIONS):
        table = evaluate(net, judge, data, cfg, on_progress=tick, parts=parts)
    paths = table.write(out)
    remove_parts(parts)
    console.print(table.to_markdown(), highlight=False, markup=False, emoji=False)
    console.print("wrote " + ", ".join(str(p) for p in paths), highlight=False)
