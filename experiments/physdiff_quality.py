"""PhysDiff against no physics, no physics grounded on the floor, and post-processing, with the default
model: one table from one run.

Usage: python bench/physdiff_quality.py [--model DIR] [--prompts 32] [--seeds 0,1,2] [--json FILE]
       python bench/physdiff_quality.py --set new [--model DIR] [--seeds 0] [--json FILE]
       (either with --fine-step: every projection at 1/720 s, as ``generate --fine-step``; or --tau M: the
       generation P's reset threshold, 0.15 m in the sampling preset)
(--json also writes every mode's metrics per seed, e.g. results/physdiff_quality.json, which the README
quotes and tests/test_results.py checks it against.)
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
from dataclasses import replace

import numpy as np
from rich.console import Console
from rich.table import Table

from physmotion.diffusion.model import MotionDiffusion
from physmotion.eval.physics_modes import compare_modes
from physmotion.eval.prompts import NEW_PROMPTS, PHYSICS_PROMPTS
from physmotion.generate import GenerateConfig
from physmotion.motion import write_atomic

MODES = ("none", "none+floor", "post:1", "post:4", "physdiff:end:4,space:1")
NEW_SET_MODES = ("none", "none+floor", "post:1", "physdiff:end:4,space:1", "morph")
COLUMNS = ("penetrate", "float", "skate", "phys_err")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None)
    parser.add_argument("--prompts", type=int, default=32)
    parser.add_argument("--seeds", default="0,1,2", help="comma-separated sampling seeds")
    parser.add_argument("--json", default=None, help="also write the per-seed metrics to this file")
    parser.add_argument("--set", choices=("physics", "new"), default="physics",
                        help="physics: the 32 prompts in our captions' words; new: the unseen prompts by category")
    parser.add_argument("--fine-step", action="store_true",
                        help="every projection at 1/720 s (generate --fine-step)")
    parser.add_argument("--tau", type=float, default=None,
                        help="the generation P's reset threshold in metres (default: the sampling preset's)")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    model = MotionDiffusion.load(args.model)
    base = GenerateConfig().at_fine_step() if args.fine_step else GenerateConfig()
    if args.tau is not None:
        base = replace(base, projection=replace(base.projection, tau=args.tau))
    if args.set == "new":
        _new_prompts(model, seeds, args.json, base)
        return
    prompts = PHYSICS_PROMPTS[: args.prompts]
    runs = [compare_modes(model, prompts, MODES, replace(base, seed=seed)) for seed in seeds]
    table = Table(title=f"physics modes, {len(prompts)} prompts, 6 s each{_step(base)}, mean over seeds "
                        f"{args.seeds}")
    for col in ("mode", "Penetrate", "Float", "Skate", "Phys-Err", "vs none", "vs none+floor",
                "per seed (vs none+floor)", "no fall", "reset", "resets", "s/motion"):
        table.add_column(col, justify="left" if col == "mode" else "right")
    ref = {m: np.mean([r[m]["phys_err"] for r in runs]) for m in ("none", "none+floor")}
    for mode in MODES:
        mean = {k: float(np.mean([r[mode].get(k, np.nan) for r in runs]))
                for k in (*COLUMNS, "tracked", "reset_rate", "resets", "seconds_per_motion")}
        per_seed = "/".join(f"{100 * (r[mode]['phys_err'] / r['none+floor']['phys_err'] - 1):+.1f}"
                            for r in runs)
        changes = [f"{100 * (mean['phys_err'] / ref[b] - 1):+.1f}%" for b in ("none", "none+floor")]
        projected = mode.startswith(("post", "physdiff"))
        falls = [f"{100 * mean['tracked']:.0f}%", f"{100 * mean['reset_rate']:.0f}%", f"{mean['resets']:.2f}"]
        table.add_row(mode, *(f"{mean[k]:.2f}" for k in COLUMNS), *changes, per_seed,
                      *(falls if projected else ["-"] * 3), f"{mean['seconds_per_motion']:.2f}")
    Console(width=160, emoji=False).print(table)
    if args.json:
        meta = {"prompts": len(prompts), "seconds": base.seconds, "seeds": seeds,
                "model_steps": model.info.get("steps"), "sim_dt": base.projection.humanoid.sim_dt,
                "tau": base.projection.tau}
        runs = [{m: {k: (None if np.isnan(v) else v) for k, v in row.items()} for m, row in run.items()}
                for run in runs]  # strict JSON: no NaN (the unprojected rows have no fall counts)
        write_atomic(args.json, lambda f: f.write(json.dumps({"meta": meta, "runs": runs}, indent=2)), "w")


def _step(base: GenerateConfig) -> str:
    """The projection's simulation step and reset threshold, for a table title."""
    p = base.projection
    return f", P at 1/{round(1 / p.humanoid.sim_dt)} s, reset at {p.tau:g} m"


def _new_prompts(model: MotionDiffusion, seeds: list[int], json_path: str | None, base: GenerateConfig) -> None:
    """One row per category and mode of NEW_PROMPTS (means over the category's prompts and the seeds)."""
    runs = {cat: [compare_modes(model, list(prompts), NEW_SET_MODES, replace(base, seed=seed)) for seed in seeds]
            for cat, prompts in NEW_PROMPTS.items()}  # fmt: skip
    table = Table(title=f"unseen prompts ({sum(map(len, NEW_PROMPTS.values()))}), 6 s each{_step(base)}, "
                  f"seeds {','.join(map(str, seeds))}, model steps {model.info.get('steps')}")  # fmt: skip
    for col in ("category", "mode", "Penetrate", "Float", "Skate", "Phys-Err", "vs none", "vs none+floor",
                "reset", "imitation failed", "s/motion"):
        table.add_column(col, justify="left" if col in ("category", "mode") else "right")
    for cat, cat_runs in runs.items():
        mean = {m: {k: float(np.mean([r[m].get(k, np.nan) for r in cat_runs]))
                    for k in (*COLUMNS, "reset_rate", "imitation_failure_rate", "seconds_per_motion")}
                for m in NEW_SET_MODES}  # fmt: skip
        for mode in NEW_SET_MODES:
            row = mean[mode]
            changes = [f"{100 * (row['phys_err'] / mean[b]['phys_err'] - 1):+.0f}%" for b in ("none", "none+floor")]
            rates = [f"{100 * row[k]:.0f}%" if np.isfinite(row[k]) else "-"
                     for k in ("reset_rate", "imitation_failure_rate")]  # fmt: skip
            table.add_row(cat, mode, *(f"{row[k]:.2f}" for k in COLUMNS), *changes, *rates,
                          f"{row['seconds_per_motion']:.2f}")
    Console(width=160, emoji=False).print(table)
    if json_path:
        clean = {cat: [{m: {k: (None if np.isnan(v) else v) for k, v in row.items()} for m, row in run.items()}
                       for run in cat_runs] for cat, cat_runs in runs.items()}  # fmt: skip
        meta = {"set": "new", "prompts": {c: list(p) for c, p in NEW_PROMPTS.items()}, "seeds": seeds,
                "model_steps": model.info.get("steps"), "model_info": model.info.get("morph", {}),
                "sim_dt": base.projection.humanoid.sim_dt, "tau": base.projection.tau}
        write_atomic(json_path, lambda f: f.write(json.dumps({"meta": meta, "runs": clean}, indent=2)), "w")


if __name__ == "__main__":
    main()
