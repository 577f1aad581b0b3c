"""Do a model's plain samples still jump? Jump and hop prompts sampled by several models, each held
against the first model's sample of the same prompt and seed: a fine-tune on physically refined motions
(Morph) learns whatever P did to them, a flattened jump included (issue 61, item 8).

Usage: python -m experiments.model_flight --model physmotion/weights/base --model runs/X [--names a,b,c]
       [--seeds 0,1,2,3,4] [--seconds 4] [--out results/model_flight]

Rows: one per model, sampled with ``generate --physics none`` (the default sampler) from the same noise.
Columns: samples that fly (both feet at least :data:`~physmotion.metrics.dynamics.MIN_FLIGHT` off their
stance, :func:`~physmotion.metrics.actions.flight_height`) and their median flight, flight kept against
the first model (median of this model's flight over the first's, where the first's sample flies:
:func:`~physmotion.metrics.dynamics.flight_ratios`), and the plain samples' Penetrate, Float, Skate and
Phys-Err on the humanoid surface. The prompts are ``experiments/flight_kept.py``'s: the jump and hop
categories of the unseen-prompt benchmark and its own four.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from experiments._results import ROOT, heading, markdown_table, parse_args, report, run_meta, write_results


def prompts() -> list[str]:
    """Jump and hop prompts no model was tuned to (flight_kept's)."""
    from experiments.flight_kept import FRESH
    from experiments.prompts import NEW_PROMPTS

    return [*NEW_PROMPTS["jump"], *NEW_PROMPTS["hop"], *FRESH]


def measure(models: list[str], seeds: list[int], seconds: float) -> list[dict]:
    """One dict of figures per model, in order (module docstring)."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.generate import GenerateConfig, generate
    from physmotion.metrics import physical_metrics
    from physmotion.metrics.actions import flight_height
    from physmotion.metrics.dynamics import MIN_FLIGHT, flight_ratios
    from physmotion.physics.surface import HumanoidSurface

    texts = prompts()
    first: list[np.ndarray] | None = None  # the first model's samples, which the others are held against
    rows = []
    for name in models:
        net = MotionDiffusion.load(name)
        joints = []
        for seed in seeds:
            cfg = GenerateConfig(seconds=seconds, physics="none", seed=seed)
            joints += [m.joints for m in generate(texts, cfg, model=net).motions]
        first = joints if first is None else first
        heights = np.array([flight_height(j.astype(np.float64)) for j in joints])
        flying = heights >= MIN_FLIGHT
        phys = physical_metrics(np.stack(joints), body=HumanoidSurface([None] * len(joints)))
        ratios = flight_ratios(joints, first)
        rows.append({"model": name, "samples": len(joints), "flying": int(flying.sum()),
                     "flight_median_m": float(np.median(heights[flying])) if flying.any() else None,
                     "flight_each_m": heights.tolist(),
                     "flight_kept": float(np.median(ratios)) if ratios else None, "compared": len(ratios),
                     **{k: float(phys[k]) for k in ("penetrate", "float", "skate", "phys_err")}})  # fmt: skip
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", action="append", required=True,
                        help="a model folder (repeat; the first is the one the others are held against)")
    parser.add_argument("--names", default=None, help="what the table calls the models, comma-separated")
    parser.add_argument("--seeds", default="0,1,2,3,4")
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--out", default=str(ROOT / "results" / "model_flight"))
    args = parse_args(parser, argv)

    def run() -> tuple[str, list[Path]]:
        names = args.names.split(",") if args.names else list(args.model)
        if len(names) != len(args.model):
            raise ValueError(f"--names gives {len(names)} names for {len(args.model)} models")
        seeds = [int(s) for s in args.seeds.split(",")]
        rows = measure(list(args.model), seeds, args.seconds)
        for row, name in zip(rows, names):
            row["name"] = name
        meta = run_meta(__file__, argv, args.tree, None, seeds=seeds, seconds=args.seconds,
                        models=dict(zip(names, args.model)), prompts=prompts())  # fmt: skip
        header = ["model", "flying samples", "flight, median cm", f"flight kept against {names[0]} (median)",
                  "Penetrate mm", "Float mm", "Skate mm", "Phys-Err mm"]
        body = [[r["name"], f"{r['flying']} of {r['samples']}",
                 "-" if r["flight_median_m"] is None else f"{100 * r['flight_median_m']:.1f}",
                 "-" if r["flight_kept"] is None else f"{r['flight_kept']:.2f} ({r['compared']})",
                 *(f"{r[k]:.1f}" for k in ("penetrate", "float", "skate", "phys_err"))] for r in rows]  # fmt: skip
        table = heading("Plain samples of jump and hop prompts, per model", meta) + markdown_table(header, body)
        return table, write_results(args.out, table, {"meta": meta, "rows": rows})

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
