"""How much of a generated jump's flight does generation's P keep? Plain samples of jump and hop prompts,
then P under the sampling preset and variants of it, each against its own plain sample.

Usage: python -m experiments.flight_kept [--seeds 0,1,2] [--seconds 4] [--variants sampling,ballistic,...]
       [--mode physdiff:end:2,space:1 --mode ...] [--mode-variant NAME ...] [--fallback] [--recover]
       [--categories jump,hop] [--out results/flight_kept]

Rows: each ``--mode`` (default: generate's default, PhysDiff with P at the last 2 steps) is ``generate``
with that physics mode against the plain sample of the same prompt and seed; every other row is one P (as ``post:1``) of the plain samples under a variant of
:meth:`ProjectionConfig.sampling` (:data:`VARIANTS`). Columns: flight kept (median of output over
sample flight where the sample flies, :mod:`physmotion.metrics.dynamics`), the share of outputs with a
reset, jumps past the sample's largest frame step + 2 cm, the root help (force and torque p95, share
held at a cap), Phys-Err, the share of outputs the search made (``ProjectionConfig.fallback``), and the
cost: CPU seconds (this process and P's worker processes) per second of output motion, and wall
seconds per output; a mode's cost includes sampling. The prompts are the jump and hop categories of the
unseen-prompt benchmark (``experiments/prompts.py`` ``NEW_PROMPTS``) and :data:`FRESH`, written for this
study.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import resource
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from experiments._results import ROOT, heading, markdown_table, parse_args, report, run_meta, write_results

FRESH: tuple[str, ...] = ("a person jumps up and lands softly", "someone jumps on the spot twice",
                          "a person skips forward", "someone hops over a small box")  # fmt: skip


JUMPS: tuple[str, ...] = ("jump", "hop")  # the unseen-prompt categories measured by default


def _variant(name: str):
    """The P of a row: the sampling preset with one change."""
    from physmotion.physics.projection import ProjectionConfig

    base = ProjectionConfig.sampling()
    if name == "sampling":
        return base
    if name == "ballistic":  # the plain preset's ballistic flight phases in the reference
        return replace(base, shaping=replace(base.shaping, ballistic_flight=True))
    if name == "no_land":  # a body short of a flight is reset into the air instead of landing
        return replace(base, let_land=False)
    if name == "ballistic_no_land":
        return replace(base, let_land=False, shaping=replace(base.shaping, ballistic_flight=True))
    if name == "lift_0.3":  # the lift cap up to the force cap
        return replace(base, tracking=replace(base.tracking, residual_lift=0.3))
    if name == "feet_balance":  # the root wrench carried by the feet first, as in the plain P
        return replace(base, tracking=replace(base.tracking, feet_balance=True))
    if name == "feet_through_actuators":  # the same, those joint torques through the actuators' targets
        return replace(base, tracking=replace(base.tracking, feet_balance=True, feet_through_actuators=True))
    if name == "fallback":  # the search where the tracker resets, fails or keeps under 0.8 of the flight
        return replace(base, fallback=True)
    if name == "no_recover":  # the tracker resets the body at once where it falls (the default before recover)
        return replace(base, recover=False)
    if name == "search":  # the search controller in place of the tracker: no outside hand, default effort
        return base.with_controller("search")
    if name == "search_velocity":  # the same, its cost also on the bodies' velocity error to the reference's
        searched = base.with_controller("search")
        cost = replace(searched.search.cost, body_velocity=0.1)
        return replace(searched, search=replace(searched.search, cost=cost))
    if name == "no_push_off":  # the rise into a flight played as the motion has it, however slow
        return replace(base, shaping=replace(base.shaping, push_off=False))
    if name == "rescue":  # the search re-does a take-off whose flight the body kept under 0.8 of (no hand)
        return replace(base, rescue_flight=0.8)
    if name == "copied_arms":  # the arms' bone directions copied as they are, not fitted to the body first
        return replace(base, reach_arms=False)
    raise ValueError(f"unknown variant {name!r}")


VARIANTS = ("sampling", "ballistic", "no_land", "ballistic_no_land", "lift_0.3", "feet_balance",
            "feet_through_actuators", "fallback", "no_recover", "search", "search_velocity", "copied_arms",
            "no_push_off", "rescue")


def _cpu_wall() -> np.ndarray:
    """(CPU seconds of this process and its children, wall seconds) now. P's worker pool lives on between
    calls, so its live processes' CPU is read from /proc (Linux) as well as that of the finished ones."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime
    for child in multiprocessing.active_children():
        try:
            fields = Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[1].split()
            cpu += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime
        except (OSError, IndexError, ValueError):  # gone meanwhile, or no /proc
            pass
    return np.array([cpu, time.perf_counter()])


def measure(seeds: list[int], seconds: float, variants: list[str], modes: list[str],
            fallback: bool = False, recover: bool = False,
            mode_variants: tuple[str, ...] = (),
            categories: tuple[str, ...] = JUMPS) -> dict[str, dict]:  # fmt: skip
    """Row name -> figures (see the module docstring); with ``fallback``, each mode again with the search
    as the tracker's fallback (row "<mode> +fallback"); with ``recover``, again with the other setting of
    the search carrying the body where the tracker would reset it (row "<mode> +recover" or "-recover");
    for each of ``mode_variants``, again with that variant's P (row "<mode> [variant]"). The prompts are
    those of ``categories`` in the unseen-prompt benchmark, and :data:`FRESH` with the jump categories."""
    from experiments.prompts import NEW_PROMPTS
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.physdiff import on_data_floor
    from physmotion.generate import GenerateConfig, generate
    from physmotion.metrics import physical_metrics
    from physmotion.metrics.dynamics import flight_ratios, step_jumps
    from physmotion.metrics.report import help_stats
    from physmotion.motion import Motion
    from physmotion.physics.projection import project
    from physmotion.physics.surface import HumanoidSurface

    prompts = [p for c in categories for p in NEW_PROMPTS[c]] + (list(FRESH) if categories == JUMPS else [])
    model = MotionDiffusion.load()
    plain, outputs, spent = [], {}, {}
    for seed in seeds:
        cfg = GenerateConfig(seconds=seconds, physics="none", seed=seed)
        plain += [m.joints for m in generate(prompts, cfg, model=model).motions]
        for mode in modes:
            runs = {mode: cfg.projection}
            if recover:  # the other setting than generate's default
                on = not cfg.projection.recover
                runs[f"{mode} {'+' if on else '-'}recover"] = replace(cfg.projection, recover=on)
            if fallback:
                runs[f"{mode} +fallback"] = replace(cfg.projection, fallback=True)
            for name in mode_variants:
                runs[f"{mode} [{name}]"] = _variant(name)
            for name, projection in runs.items():
                start = _cpu_wall()
                res = generate(prompts, replace(cfg, physics=mode, projection=projection), model=model)
                outputs.setdefault(name, []).extend(res.motions)
                spent[name] = spent.get(name, np.zeros(2)) + _cpu_wall() - start
    for name in variants:
        config = _variant(name)
        start = _cpu_wall()
        res = project(np.stack([on_data_floor(j) for j in plain]), config=config)
        spent[name] = _cpu_wall() - start
        outputs[name] = [Motion(joints=res.joints[i], humanoid=res.body[i], **res.record(i).motion_fields(
            config.residual_bound())) for i in range(len(plain))]  # fmt: skip
    rows = {}
    for name, motions in outputs.items():
        joints = [m.joints for m in motions]
        ratios = flight_ratios(joints, plain)
        phys = physical_metrics(np.stack(joints), body=HumanoidSurface([m.humanoid for m in motions]))
        rows[name] = {"flight_kept": float(np.median(ratios)) if ratios else None, "flying": len(ratios),
                      "flight_kept_each": ratios, "motions": len(motions),
                      "with_reset": float(np.mean([(m.resets or 0) > 0 for m in motions])),
                      "step_jumps": step_jumps(joints, plain), "phys_err": float(phys["phys_err"]),
                      "searched": float(np.mean([bool(m.searched) for m in motions])),
                      "recovered": float(np.mean([(m.recovered or 0) > 0 for m in motions])),
                      "cpu_s_per_s": float(spent[name][0] / sum(m.seconds for m in motions)),
                      "wall_s_per_output": float(spent[name][1] / len(motions)), **help_stats(motions)}  # fmt: skip
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--variants", default=",".join(VARIANTS))
    parser.add_argument("--mode", action="append", default=None,
                        help="a generate physics mode to measure (repeatable; default: generate's default)")
    parser.add_argument("--fallback", action="store_true",
                        help="each --mode again with the search as the tracker's fallback")
    parser.add_argument("--recover", action="store_true",
                        help="each --mode again with the other setting of ProjectionConfig.recover (the search "
                        "carrying the body where the tracker would reset it)")
    parser.add_argument("--mode-variant", action="append", default=[],
                        help="each --mode again with this variant's P in place of the sampling preset "
                        "(repeatable)")
    parser.add_argument("--categories", default=",".join(JUMPS),
                        help="the unseen-prompt categories to generate (experiments/prompts.py NEW_PROMPTS); "
                        "FRESH's prompts join the default jump and hop only")
    parser.add_argument("--out", default=str(ROOT / "results" / "flight_kept"))
    args = parse_args(parser, argv)

    def run() -> tuple[str, list[Path]]:
        seeds = [int(s) for s in args.seeds.split(",")]
        variants = [v for v in args.variants.split(",") if v]
        for v in [*variants, *args.mode_variant]:
            _variant(v)  # a bad name fails before any work
        from experiments.prompts import NEW_PROMPTS

        categories = tuple(c for c in args.categories.split(",") if c)
        if not categories or not set(categories) <= set(NEW_PROMPTS):
            raise ValueError(f"--categories: choose from {', '.join(NEW_PROMPTS)}")
        from physmotion.generate import GenerateConfig

        modes = args.mode if args.mode is not None else [str(GenerateConfig().physics)]
        rows = measure(seeds, args.seconds, variants, [m for m in modes if m], args.fallback, args.recover,
                       tuple(args.mode_variant), categories)
        meta = run_meta(__file__, argv, args.tree, {name: "sampling" for name in rows}, seeds=seeds,
                        seconds=args.seconds, categories=list(categories))
        header = ["row", "flight kept (median)", "flying samples", "outputs with a reset", "jumps past the sample's",
                  "root force p95, W", "root torque p95, W m", "held at a cap", "Phys-Err, mm", "searched",
                  "carried by the search, not reset",
                  "CPU s / s of motion", "wall s / output"]
        body = [[name, "-" if r["flight_kept"] is None else f"{r['flight_kept']:.2f}", r["flying"],
                 f"{100 * r['with_reset']:.0f} %", f"{100 * r['step_jumps']:.0f} %",
                 f"{r['residual_force_p95']:.2f}", f"{r['residual_torque_p95']:.2f}",
                 f"{100 * r['residual_at_cap']:.0f} %", f"{r['phys_err']:.1f}", f"{100 * r['searched']:.0f} %",
                 f"{100 * r['recovered']:.0f} %",
                 f"{r['cpu_s_per_s']:.2f}", f"{r['wall_s_per_output']:.1f}"] for name, r in rows.items()]  # fmt: skip
        kinds = "jump and hop" if categories == JUMPS else " and ".join(categories)
        title = f"Flight kept by generation's P on {kinds} prompts"
        table = heading(title, meta) + markdown_table(header, body)
        return table, write_results(args.out, table, {"meta": meta, "rows": rows})

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
