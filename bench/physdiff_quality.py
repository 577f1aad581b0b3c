"""PhysDiff against no physics and post-processing, with the default model: one table from one run.

Usage: python bench/physdiff_quality.py [--model DIR] [--prompts 32] [--seed 0]
Rows: none, post:1, post:4 (as many projections as PhysDiff's default), physdiff:end:4,space:1.
Metrics on the humanoid's MuJoCo geometry posed on the joints, with the body P simulated for projected outputs
(PhysDiff's Penetrate/Float/Skate/Phys-Err, mm).
"""

from __future__ import annotations

import argparse

from rich.console import Console
from rich.table import Table

from physmotion.diffusion.model import MotionDiffusion
from physmotion.eval.physics_modes import compare_modes
from physmotion.eval.prompts import PHYSICS_PROMPTS
from physmotion.generate import GenerateConfig

MODES = ("none", "post:1", "post:4", "physdiff:end:4,space:1")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None)
    parser.add_argument("--prompts", type=int, default=32)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    model = MotionDiffusion.load(args.model)
    prompts = PHYSICS_PROMPTS[: args.prompts]
    res = compare_modes(model, prompts, MODES, GenerateConfig(seed=args.seed))
    none = res["none"]["phys_err"]
    table = Table(title=f"physics modes, {len(prompts)} prompts, 6 s each, seed {args.seed}")
    for col in ("mode", "Penetrate", "Float", "Skate", "Phys-Err", "vs none", "no fall", "s/motion"):
        table.add_column(col, justify="left" if col == "mode" else "right")
    for mode, r in res.items():
        table.add_row(mode, f"{r['penetrate']:.2f}", f"{r['float']:.2f}", f"{r['skate']:.2f}",
                      f"{r['phys_err']:.2f}", f"{100 * (r['phys_err'] / none - 1):+.0f}%",
                      "-" if r["tracked"] != r["tracked"] else f"{100 * r['tracked']:.0f}%", f"{r['seconds_per_motion']:.2f}")
    Console().print(table)


if __name__ == "__main__":
    main()
