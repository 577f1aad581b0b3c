"""PhysDiff's Fig. 4 on our data: FID, R-Precision and Phys-Err against the number of projection steps.

    python scripts/schedule_study.py --data data_build/mocap --out results/schedule_study

writes <out>.md, <out>.json and <out>.png. It is a script rather than a command because it is a study:
it runs `physmotion evaluate` once per projection count (see physmotion/eval/schedule_study.py).
"""

from __future__ import annotations

import argparse
import sys

from physmotion.diffusion.model import MotionDiffusion
from physmotion.errors import PhysmotionError
from physmotion.eval.evaluator import Evaluator
from physmotion.eval.schedule_study import DEFAULT_COUNTS, plot_study, schedule_study, write_study
from physmotion.eval.table import EvalTable, EvaluateConfig


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="HumanML3D-layout folder")
    parser.add_argument("--out", default="results/schedule_study", help="output stem")
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    parser.add_argument("--evaluator", default=None, help="evaluator folder (default: the shipped one)")
    parser.add_argument("--split", default="test")
    parser.add_argument("--counts", default=",".join(map(str, DEFAULT_COUNTS)), help="projection counts")
    parser.add_argument("--motions", type=int, default=None, help="a seeded subset of the split")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--steps", type=int, default=50, help="DDIM steps")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plot-only", action="store_true", help="redraw <out>.png from <out>.json")
    args = parser.parse_args(argv)
    try:
        if args.plot_only:
            print("wrote", plot_study(EvalTable.from_json(f"{args.out}.json"), f"{args.out}.png"))
            return 0
        counts = [int(c) for c in args.counts.split(",")]
        cfg = EvaluateConfig(split=args.split, repeats=args.repeats, max_motions=args.motions, seed=args.seed)
        cfg.base.sampler.steps = args.steps
        table = schedule_study(MotionDiffusion.load(args.model), Evaluator.load(args.evaluator), args.data,
                               counts, cfg)  # fmt: skip
        paths = write_study(table, args.out)
    except (PhysmotionError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(table.to_markdown())
    print("wrote " + ", ".join(map(str, paths)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
