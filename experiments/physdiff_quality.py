"""PhysDiff against no physics, no physics grounded on the floor, and post-processing, with the default
model: one table from one run.

Usage: python -m experiments.physdiff_quality [--model DIR] [--prompts 32] [--seeds 0,1,2] [--out STEM]
       python -m experiments.physdiff_quality --runs-from A.json B.json [--out STEM]
       (one table from runs made apart, e.g. the seeds in parallel processes: their runs and seeds joined)
       python -m experiments.physdiff_quality --set new [--model DIR] [--seeds 0] [--out STEM]
       (either with --fine-step: every projection at 1/720 s, P's presets ``sampling_fine`` and ``fine``, as
       ``generate --fine-step``; or --tau M: the generation P's reset threshold, 0.15 m in the sampling preset)
Writes ``<out>.md`` (the table) and ``<out>.json`` (every mode's metrics per seed and the meta block; default
``results/physdiff_quality``, with ``--set new`` ``results/new_prompts_default``), which the docs quote and
tests/test_results.py checks them against.
Rows: none (as sampled), none+floor (each motion moved vertically by the constant shift that leaves it the
least Phys-Err: the fair baseline), post:1, post:4 (as many projections as PhysDiff's default),
physdiff:end:4,space:1. Metrics on the humanoid's MuJoCo geometry posed on the joints, with the body P
simulated for projected outputs (PhysDiff's Penetrate/Float/Skate/Phys-Err, mm), averaged over the seeds.
"vs none" and "vs none+floor" are the change in Phys-Err; "per seed" gives "vs none+floor" for each seed,
because one seed's 32 motions move the ratio by about a point. "no fall": projections (all of them,
PhysDiff's four per motion included) in which the humanoid never fell; "reset": outputs with at least one
reset (a jump back onto the motion), and resets per output.
``--set new`` runs the prompts written from scratch (``NEW_PROMPTS``: runs, jogs, jumps, hops, kicks,
turns, dances, gestures, standing; none a caption of our data) with Morph's inference mode added, one row
per category and mode, so that runs and jumps read on their own.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from experiments._results import markdown_table, parse_args, run_meta, write_results
from experiments.prompts import NEW_PROMPTS, PHYSICS_PROMPTS
from physmotion.conventions import FPS
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.samplers import ddim_50
from physmotion.eval.physics_columns import imitation_columns, metric_surface, reset_columns, residual_columns
from physmotion.generate import GenerateConfig, generate
from physmotion.metrics import physical_metrics
from physmotion.physics.presets import preset
from physmotion.pipelines.modes import PhysicsMode

MODES = ("none", "none+floor", "post:1", "post:4", "physdiff:end:4,space:1")
NEW_SET_MODES = ("none", "none+floor", "post:1", "physdiff:end:4,space:1", "morph")
COLUMNS = ("penetrate", "float", "skate", "phys_err")


def compare_modes(
    model: MotionDiffusion,
    prompts: Sequence[str],
    modes: Sequence[str | PhysicsMode],
    base: GenerateConfig | None = None,
    surface: str = "humanoid",
) -> dict[str, dict[str, float]]:
    """Generate one motion per prompt in each mode; mode spelling -> physical metrics (mean over
    motions) plus ``seconds_per_motion``, ``tracked`` (fraction of all projections, PhysDiff's four per
    motion included, in which the humanoid never fell), :func:`reset_columns` and
    :func:`imitation_columns`.

    surface "humanoid": the humanoid's geometry, with the body P simulated for projected outputs and one
    estimated from the joints otherwise; "joints": the joint-only surface model."""
    base = base or GenerateConfig(sampler=ddim_50())
    metric_surface(surface)  # a bad name fails before any work
    results: dict[str, dict[str, float]] = {}
    for mode in [PhysicsMode.parse(m) for m in modes]:
        cfg = replace(base, physics=mode)
        start = time.perf_counter()
        out = generate(list(prompts), cfg, model)
        seconds = time.perf_counter() - start
        joints = np.stack([m.joints for m in out.motions])
        row = physical_metrics(joints, FPS, body=metric_surface(surface, out.bodies))
        row["seconds_per_motion"] = seconds / len(prompts)
        log = out.projections
        row["tracked"] = float(np.mean(log.tracked)) if log.tracked else float("nan")
        row.update(reset_columns([out]))
        row.update(residual_columns([out]))
        row.update(imitation_columns([out]))
        results[str(mode)] = row
    return results


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None)
    parser.add_argument("--prompts", type=int, default=32)
    parser.add_argument("--seeds", default="0,1,2", help="comma-separated sampling seeds")
    parser.add_argument("--out", default=None, help="writes OUT.md and OUT.json")
    parser.add_argument("--set", choices=("physics", "new"), default="physics",
                        help="physics: the 32 prompts in our captions' words; new: the unseen prompts by category")
    parser.add_argument("--fine-step", action="store_true",
                        help="every projection at 1/720 s (generate --fine-step)")
    parser.add_argument("--tau", type=float, default=None,
                        help="the generation P's reset threshold in metres (default: the sampling preset's)")
    parser.add_argument("--runs-from", type=Path, nargs="+", default=None,
                        help="no generation: one table from these files' runs (physics set, same settings)")
    args = parse_args(parser, argv)
    if args.runs_from:
        _join(args.runs_from, argv, args)
        return
    seeds = [int(s) for s in args.seeds.split(",")]
    model = MotionDiffusion.load(args.model)
    presets = {"physdiff, post": "sampling_fine" if args.fine_step else "sampling",
               "morph": "fine" if args.fine_step else "plain"}  # fmt: skip
    base = GenerateConfig(sampler=ddim_50(), projection=preset(presets["physdiff, post"]),
                          morph_projection=preset(presets["morph"]))  # fmt: skip
    if args.tau is not None:
        base = replace(base, projection=replace(base.projection, tau=args.tau))
    run = _new_prompts if args.set == "new" else _physics_prompts
    md, runs, settings = run(model, seeds, base, args.prompts)
    print(md)
    meta = run_meta(__file__, argv, args.tree, presets, seeds=seeds, model_steps=model.info.get("steps"),
                    sim_dt=base.projection.humanoid.sim_dt, tau=base.projection.tau, **settings)  # fmt: skip
    default = "results/new_prompts_default" if args.set == "new" else "results/physdiff_quality"
    write_results(args.out or default, md, {"meta": meta, "runs": runs})


def _physics_prompts(model: MotionDiffusion, seeds: list[int], base: GenerateConfig,
                     count: int) -> tuple[str, list[dict], dict]:  # fmt: skip
    """The physics prompt set: one row per mode (means over the seeds); the table, the runs, the settings."""
    prompts = PHYSICS_PROMPTS[:count]
    runs = [compare_modes(model, prompts, MODES, replace(base, seed=seed)) for seed in seeds]
    p = base.projection
    table = _physics_table(runs, seeds, len(prompts), _step(p.humanoid.sim_dt, p.tau))
    return table, runs, {"prompts": len(prompts), "seconds": base.seconds}


def _physics_table(runs: list[dict], seeds: list[int], prompts: int, step: str) -> str:
    """The physics set's table from its runs, one per seed; ``step``: :func:`_step`'s words for P."""
    title = (f"physics modes, {prompts} prompts, 6 s each{step}, mean over seeds "
             f"{','.join(map(str, seeds))}")
    ref = {m: np.mean([r[m]["phys_err"] for r in runs]) for m in ("none", "none+floor")}
    rows = []
    for mode in MODES:
        mean = {k: _mean([r[mode].get(k, np.nan) for r in runs])
                for k in (*COLUMNS, "tracked", "reset_rate", "resets", "seconds_per_motion", *HELP)}  # fmt: skip
        per_seed = "/".join(f"{100 * (r[mode]['phys_err'] / r['none+floor']['phys_err'] - 1):+.1f}" for r in runs)
        changes = [f"{100 * (mean['phys_err'] / ref[b] - 1):+.1f}%" for b in ("none", "none+floor")]
        projected = mode.startswith(("post", "physdiff"))
        falls = [f"{100 * mean['tracked']:.0f}%", f"{100 * mean['reset_rate']:.0f}%", f"{mean['resets']:.2f}",
                 *_help_cells(mean)]
        rows.append((mode, *(f"{mean[k]:.2f}" for k in COLUMNS), *changes, per_seed,
                     *(falls if projected else ["-"] * len(falls)), f"{mean['seconds_per_motion']:.2f}"))  # fmt: skip
    header = ("mode", "Penetrate", "Float", "Skate", "Phys-Err", "vs none", "vs none+floor",
              "per seed (vs none+floor)", "no fall", "reset", "resets", *HELP_HEADER, "s/motion")  # fmt: skip
    return f"# {title}\n\n{markdown_table(header, rows)}\n"


def _join(files: list[Path], argv: list[str] | None, args: argparse.Namespace) -> None:
    """``--runs-from``: the runs of ``files`` (physics set, one commit, one setting) as one results file."""
    parts = [json.loads(Path(f).read_text()) for f in files]
    first = parts[0]["meta"]
    same = ("commit", "dirty", "preset", "prompts", "seconds", "sim_dt", "tau", "model_steps")
    for part, f in zip(parts, files):
        meta = part["meta"]
        if meta.get("set", "physics") != "physics" or any(meta.get(k) != first.get(k) for k in same):
            raise SystemExit(f"error: {f}: not a physics-set run with the settings of {files[0]}")
    seeds = [seed for part in parts for seed in part["meta"]["seeds"]]
    runs = [run for part in parts for run in part["runs"]]
    if len(set(seeds)) != len(seeds):
        raise SystemExit(f"error: a seed appears twice in {', '.join(map(str, files))}")
    md = _physics_table(runs, seeds, first["prompts"], _step(first["sim_dt"], first["tau"]))
    print(md)
    settings = {k: first[k] for k in ("model_steps", "sim_dt", "tau", "prompts", "seconds") if k in first}
    meta = run_meta(__file__, argv, args.tree, first["preset"], seeds=seeds, **settings)
    # the figures are the parts': their commit and tree, and how each was made
    meta.update(commit=first["commit"], dirty=first["dirty"], parts=[p["meta"]["command"] for p in parts])
    write_results(args.out or "results/physdiff_quality", md, {"meta": meta, "runs": runs})


# P's help in the tables (eval.physics_columns.residual_columns): the root residual, its share of frames at
# the cap, and the frames with a joint over its torque limit.
HELP = ("residual_force", "residual_force_p95", "residual_at_cap", "residual_torque", "residual_torque_p95",
        "over_limit")  # fmt: skip
HELP_HEADER = ("root force W mean / p95 (at cap)", "root torque W m mean / p95", "torque over limit")


def _mean(values: list[float]) -> float:
    """The mean of the finite values (a run in which P made none of a mode's outputs has none); NaN if none."""
    v = np.asarray(values, dtype=np.float64)
    return float(v[np.isfinite(v)].mean()) if np.isfinite(v).any() else float("nan")


def _help_cells(row: dict[str, float]) -> list[str]:
    """The HELP_HEADER cells of one row (means over seeds); '-' where P made none of its outputs."""
    if not np.isfinite(row["residual_force"]):
        return ["-"] * len(HELP_HEADER)
    return [f"{row['residual_force']:.3f} / {row['residual_force_p95']:.3f} ({100 * row['residual_at_cap']:.0f}%)",
            f"{row['residual_torque']:.3f} / {row['residual_torque_p95']:.3f}", f"{100 * row['over_limit']:.1f}%"]


def _step(sim_dt: float, tau: float) -> str:
    """The projection's simulation step (s) and reset threshold (m), for a table title."""
    return f", P at 1/{round(1 / sim_dt)} s, reset at {tau:g} m"


def _new_prompts(model: MotionDiffusion, seeds: list[int], base: GenerateConfig,
                 count: int) -> tuple[str, dict, dict]:  # fmt: skip
    """One row per category and mode of NEW_PROMPTS (means over the category's prompts and the seeds)."""
    runs = {cat: [compare_modes(model, list(prompts), NEW_SET_MODES, replace(base, seed=seed)) for seed in seeds]
            for cat, prompts in NEW_PROMPTS.items()}  # fmt: skip
    p, total = base.projection, sum(map(len, NEW_PROMPTS.values()))
    title = (f"unseen prompts ({total}), 6 s each{_step(p.humanoid.sim_dt, p.tau)}, "
             f"seeds {','.join(map(str, seeds))}, model steps {model.info.get('steps')}")
    rows = []
    for cat, cat_runs in runs.items():
        mean = {m: {k: _mean([r[m].get(k, np.nan) for r in cat_runs])
                    for k in (*COLUMNS, "reset_rate", "fell", "imitation_failure_rate", "seconds_per_motion", *HELP)}
                for m in NEW_SET_MODES}  # fmt: skip
        for mode in NEW_SET_MODES:
            row = mean[mode]
            changes = [f"{100 * (row['phys_err'] / mean[b]['phys_err'] - 1):+.0f}%" for b in ("none", "none+floor")]
            rates = [f"{100 * row[k]:.0f}%" if np.isfinite(row[k]) else "-"
                     for k in ("reset_rate", "fell", "imitation_failure_rate")]  # fmt: skip
            rows.append((cat, mode, *(f"{row[k]:.2f}" for k in COLUMNS), *changes, *rates, *_help_cells(row),
                         f"{row['seconds_per_motion']:.2f}"))
    header = ("category", "mode", "Penetrate", "Float", "Skate", "Phys-Err", "vs none", "vs none+floor",
              "reset", "fell", "imitation failed", *HELP_HEADER, "s/motion")  # fmt: skip
    settings = {"set": "new", "prompts": {c: list(p) for c, p in NEW_PROMPTS.items()},
                "model_info": model.info.get("morph", {})}  # fmt: skip
    return f"# {title}\n\n{markdown_table(header, rows)}\n", runs, settings


if __name__ == "__main__":
    main()
