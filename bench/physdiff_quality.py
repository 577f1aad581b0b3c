"""PhysDiff against no physics and post-processing, with the default model: one table from one run.

Usage: python bench/physdiff_quality.py [--model DIR] [--prompts 32] [--seeds 0,1,2]
Rows: none, post:1, post:4 (as many projections as PhysDiff's default), physdiff:end:4,space:1.
Metrics on the humanoid's MuJoCo geometry posed on the joints, with the body P simulated for projected outputs
(PhysDiff's Penetrate/Float/Skate/Phys-Err, mm), averaged over the seeds; "vs none" is also given per seed,
because one seed's 32 motions move the ratio by about a point (PhysDiff on 2026-11-24: -80.9 / -82.4 /
-81.6 % for seeds 0 / 1 / 2).
"""

from __future__ import annotations

import argparse

import numpy as np
from rich.console import Console
from rich.table import Table

from physmotion.diffusion.model import MotionDiffusion
from physmotion.eval.physics_modes import compare_modes
from physmotion.eval.prompts import PHYSICS_PROMPTS
from physmotion.generate import GenerateConfig

MODES = ("none", "post:1", "post:4", "physdiff:end:4,space:1")
COLUMNS = ("penetrate", "float", "skate", "phys_err")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None)
    parser.add_argument("--prompts", type=int, default=32)
    parser.add_argument("--seeds", default="0,1,2", help="comma-separated sampling seeds")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    model = MotionDiffusion.load(args.model)
    prompts = PHYSICS_PROMPTS[: args.prompts]
    runs = [compare_modes(model, prompts, MODES, GenerateConfig(seed=seed)) for seed in seeds]
    table = Table(title=f"physics modes, {len(prompts)} prompts, 6 s each, mean over seeds {args.seeds}")
    for col in ("mode", "Penetrate", "Float", "Skate", "Phys-Err", "vs none", "per seed", "no fall",
                "s/motion"):
        table.add_column(col, justify="left" if col == "mode" else "right")
    none = np.mean([r["none"]["phys_err"] for r in runs])
    for mode in MODES:
        mean = {k: float(np.mean([r[mode][k] for r in runs]))
                for k in (*COLUMNS, "tracked", "seconds_per_motion")}
        per_seed = "/".join(f"{100 * (r[mode]['phys_err'] / r['none']['phys_err'] - 1):+.1f}" for r in runs)
        change = f"{100 * (mean['phys_err'] / none - 1):+.1f}%"
        no_fall = "-" if mode == "none" else f"{100 * mean['tracked']:.0f}%"
        table.add_row(mode, *(f"{mean[k]:.2f}" for k in COLUMNS), change, per_seed, no_fall,
                      f"{mean['seconds_per_motion']:.2f}")
    Console(width=160).print(table)


if __name__ == "__main__":
    main()
