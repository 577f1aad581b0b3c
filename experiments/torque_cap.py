"""The tracker with a smaller torque cap on the outside hand: the test-split table of generation's P
(``post:1`` and PhysDiff) at ``--cap`` W m against the default 1 W m, figure by figure (issue 62 item 3:
"make it the default if the test-split figures stay within their intervals").

Usage: python -m experiments.torque_cap --data data_build/all --baseline results/evaluate_default.json
       [--cap 0.25] [--out results/torque_cap]

The baseline is a ``physmotion evaluate`` table of the default model (same split, seed, repeats and
sampler); this script evaluates the same modes with the sampling preset's torque cap changed (the
``none`` row too, for flight kept) and lists, per figure, both means with their 95 % intervals and
whether the intervals overlap.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from experiments._results import ROOT, heading, markdown_table, parse_args, report, run_meta, write_results

if TYPE_CHECKING:
    from physmotion.eval.table import EvalTable

MODES = ("none", "post:1", "physdiff:end:2,space:1")
FIGURES = ("phys_err", "penetrate", "float", "skate", "FID", "R@3", "flight_kept", "step_jumps", "reset_rate",
           "fell", "residual_force_p95", "residual_torque_p95", "residual_at_cap")  # fmt: skip


def compare(base: EvalTable, table: EvalTable, modes: Sequence[str], figures: Sequence[str],
            names: tuple[str, str] = ("before", "after")) -> tuple[list[list[str]], dict]:  # fmt: skip
    """Each figure of each mode in both tables: markdown rows (mode, figure, both means ± 95 % half-widths,
    whether the intervals overlap) and the same as a dict keyed by ``names``; figures either lacks are left
    out."""
    rows, out = [], {}
    for mode in modes:
        for fig in figures:
            old, new = base.rows[mode].get(fig), table.rows[mode].get(fig)
            if old is None or new is None:
                continue
            overlap = abs(new[0] - old[0]) <= new[1] + old[1]
            out.setdefault(mode, {})[fig] = {names[0]: old, names[1]: new, "intervals_overlap": overlap}
            rows.append([mode, fig, f"{old[0]:.3f} ± {old[1]:.3f}", f"{new[0]:.3f} ± {new[1]:.3f}",
                         "yes" if overlap else "**no**"])  # fmt: skip
    return rows, out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(ROOT / "data_build" / "all"))
    parser.add_argument("--baseline", default=str(ROOT / "results" / "evaluate_default.json"))
    parser.add_argument("--cap", type=float, default=0.25, help="root torque cap, x body weight x 1 m")
    parser.add_argument("--out", default=str(ROOT / "results" / "torque_cap"))
    args = parse_args(parser, argv)

    def run() -> tuple[str, list[Path]]:
        from physmotion.diffusion.model import MotionDiffusion
        from physmotion.diffusion.samplers import default_sampler
        from physmotion.eval.evaluator import Evaluator
        from physmotion.eval.table import EvalTable, EvaluateConfig, evaluate
        from physmotion.generate import GenerateConfig

        base = EvalTable.from_json(args.baseline)
        model, judge = MotionDiffusion.load(), Evaluator.load()
        generate = GenerateConfig()
        projection = replace(generate.projection, tracking=replace(generate.projection.tracking,
                                                                   residual_torque=args.cap))  # fmt: skip
        generate = replace(generate, projection=projection, sampler=default_sampler(model))
        cfg = EvaluateConfig(modes=MODES, repeats=base.meta["repeats"], seed=base.meta["seed"], real_row=False,
                             base=generate)  # fmt: skip
        table = evaluate(model, judge, args.data, cfg)
        rows, out = compare(base, table, MODES[1:], FIGURES, names=("default", "cap"))
        meta = run_meta(__file__, argv, args.tree, "sampling", cap=args.cap, baseline=args.baseline,
                        baseline_commit=base.meta.get("commit"))  # fmt: skip
        header = ["mode", "figure", "torque cap 1 W m (default)", f"torque cap {args.cap:g} W m", "intervals overlap"]
        md = heading(f"Generation's P with the root torque capped at {args.cap:g} W m", meta)
        md += markdown_table(header, rows)
        return md, write_results(args.out, md, {"meta": meta, "rows": out, "table": table.rows})

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
