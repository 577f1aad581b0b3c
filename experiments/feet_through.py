"""Generation's P with the feet carrying the root wrench through the leg actuators: the test-split table of
PhysDiff with ``TrackingConfig(feet_balance=True, feet_through_actuators=True)`` in the sampling preset,
against the preset as it is, both evaluated in this run (same split, seed, repeats and sampler), figure by
figure with their 95 % intervals and whether those overlap. The ``none`` row is evaluated with each, for
flight kept and jumps past the sample's.

Usage: python -m experiments.feet_through --data data_build/all [--repeats 3] [--max-motions N]
       [--out results/feet_through]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from experiments._results import ROOT, heading, markdown_table, parse_args, report, run_meta, write_results
from experiments.torque_cap import FIGURES, compare

MODES = ("none", "physdiff:end:2,space:1,fly:last")
_MORE = ("residual_force", "recovered_rate", "over_limit", "sec/motion")  # beside torque_cap's figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(ROOT / "data_build" / "all"))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--max-motions", type=int, default=None, help="a seeded subset of the test split")
    parser.add_argument("--out", default=str(ROOT / "results" / "feet_through"))
    args = parse_args(parser, argv)

    def run() -> tuple[str, list[Path]]:
        from physmotion.diffusion.model import MotionDiffusion
        from physmotion.diffusion.samplers import default_sampler
        from physmotion.eval.evaluator import Evaluator
        from physmotion.eval.table import EvaluateConfig, evaluate
        from physmotion.generate import GenerateConfig

        model, judge = MotionDiffusion.load(), Evaluator.load()
        preset = replace(GenerateConfig(), sampler=default_sampler(model))
        tracking = replace(preset.projection.tracking, feet_balance=True, feet_through_actuators=True)
        through = replace(preset, projection=replace(preset.projection, tracking=tracking))
        tables = {}
        for name, base in (("preset", preset), ("through", through)):
            cfg = EvaluateConfig(modes=MODES, repeats=args.repeats, max_motions=args.max_motions,
                                 real_row=False, base=base)  # fmt: skip
            tables[name] = evaluate(model, judge, args.data, cfg)
        rows, out = compare(tables["preset"], tables["through"], MODES[1:], FIGURES + _MORE)
        meta = run_meta(__file__, argv, args.tree, "sampling", repeats=args.repeats,
                        max_motions=args.max_motions)  # fmt: skip
        header = ["mode", "figure", "sampling preset (the default)", "feet through the actuators",
                  "intervals overlap"]  # fmt: skip
        title = "Generation's P with the root wrench carried by the feet through the leg actuators"
        md = heading(title, meta)
        md += markdown_table(header, rows)
        payload = {"meta": meta, "rows": out, "tables": {k: t.rows for k, t in tables.items()}}
        return md, write_results(args.out, md, payload)

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
