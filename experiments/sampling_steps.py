"""Few-step sampling against DDIM 50 (issue 51, item 2): quality on the test split and warm timings, one table.

    python -m experiments.sampling_steps --data data_build/mocap [--tables runs/sampling_steps] [--runs 5]
        [--out results/sampling_steps] [--skip-timing] [--model MODEL] [--evaluator EVALUATOR]

Quality: one ``physmotion evaluate`` run per sampler setting of :data:`RUNS` (test split, 3 repeats, the
shipped model and evaluator or those given, CFG 2.5, eta 0, seed 0): plain sampling and, for DDIM 50 and
the candidate,
PhysDiff with schedules adapted to the step count. Each run's table is ``<tables>/<name>.{md,json}``; a
table already there (made by the ``physmotion evaluate`` command that :func:`evaluate_command` spells: the
same computation) is read, after checking its meta, instead of re-run. Each row's FID and R@3 are held
against DDIM 50's 95 % intervals of the same physics kind (plain against DDIM 50's ``none``, PhysDiff
against its ``physdiff:end:4,space:1``) from the same set of runs: within or better, i.e. FID at most the
interval's upper edge and R@3 at least its lower edge.

Timing: one 6 s motion ("a person walks forward") through :func:`physmotion.generate.generate`, the model
and text encoder loaded and each setting run once before timing; the minimum of ``--runs`` rounds, the
rounds interleaving the settings so that a slow spell of the shared machine hits them alike. The load
average is recorded before and after.

Writes ``<out>.md`` (the table) and ``<out>.json`` (rows, the acceptance of issue 51 per candidate, and
the meta block of ``experiments/_results.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from experiments._results import (
    heading,
    markdown_table,
    parse_args,
    report,
    run_meta,
    within_interval,
    write_results,
)
from physmotion.errors import PhysmotionError

BASELINE = "ddim50"
PHYSDIFF_BASE = "physdiff:end:4,space:1"  # PhysDiff's schedule at DDIM 50, the row PhysDiff candidates meet
PROMPT = "a person walks forward"
SECONDS = 6.0
PLAIN_LIMIT_S = 0.2  # issue 51: plain sampling of one 6 s motion in a warm process
PHYSDIFF_RATIO = 1.5  # issue 51: PhysDiff at most this times plain
REPEATS = 3


@dataclass(frozen=True)
class EvalRun:
    """One evaluate run: a sampler setting and the physics modes evaluated with it."""

    name: str
    sampler: str
    steps: int
    modes: tuple[str, ...]


RUNS = (
    EvalRun(BASELINE, "ddim", 50, ("none", PHYSDIFF_BASE)),
    EvalRun("dpmpp10", "dpmpp", 10, ("none", "physdiff:end:2,space:1", "physdiff:end:4,space:1")),
    EvalRun("dpmpp10_end3", "dpmpp", 10, ("physdiff:end:3,space:1",)),
    EvalRun("dpmpp15", "dpmpp", 15, ("none",)),
    EvalRun("dpmpp20", "dpmpp", 20, ("none",)),
    EvalRun("ddim10", "ddim", 10, ("none",)),
)


def evaluate_command(run: EvalRun, data: str, tables: Path, model: str | None = None,
                     evaluator: str | None = None) -> str:  # fmt: skip
    """The ``physmotion evaluate`` command that writes ``run``'s table (the shipped model and evaluator
    where None)."""
    given = (f" --model {model}" if model else "") + (f" --evaluator {evaluator}" if evaluator else "")
    return (f"physmotion evaluate --data {data}{given} --sampler {run.sampler} --steps {run.steps} "
            f"--physics {','.join(run.modes)} --repeats {REPEATS} -o {tables / run.name}")  # fmt: skip


def _check_meta(meta: dict, run: EvalRun, path: Path) -> None:
    """Refuse a table that is not the computation ``run`` names."""
    s = meta["sampler"]
    want = {"split": "test", "repeats": REPEATS, "seed": 0, "sampler": run.sampler, "steps": run.steps,
            "eta": 0.0, "cfg_scale": 2.5}  # fmt: skip
    got = {"split": meta["split"], "repeats": meta["repeats"], "seed": meta["seed"], "sampler": s["sampler"],
           "steps": s["steps"], "eta": s["eta"], "cfg_scale": s["cfg_scale"]}  # fmt: skip
    missing = [m for m in run.modes if m not in meta["modes"]]
    if got != want or missing:
        raise PhysmotionError(f"{path}: not the run {run.name} ({got} vs {want}; modes missing: {missing})")


def eval_tables(runs: Sequence[EvalRun], data: str, tables: Path, model: str | None = None,
                evaluator: str | None = None) -> dict[str, dict]:  # fmt: skip
    """Each run's evaluate table as ``EvalTable.to_json`` writes it, read from ``tables`` or computed there
    with ``model`` and ``evaluator`` (folders; the shipped ones where None)."""
    out: dict[str, dict] = {}
    for run in runs:
        path = tables / f"{run.name}.json"
        if not path.exists():
            from physmotion.diffusion.model import MotionDiffusion
            from physmotion.diffusion.samplers import SamplerConfig
            from physmotion.eval.evaluator import Evaluator
            from physmotion.eval.table import EvaluateConfig, evaluate
            from physmotion.generate import GenerateConfig

            command = evaluate_command(run, data, tables, model, evaluator)
            print(f"evaluating {run.name}: {command}", flush=True)
            base = GenerateConfig(sampler=SamplerConfig(sampler=run.sampler, steps=run.steps))
            cfg = EvaluateConfig(modes=run.modes, repeats=REPEATS, base=base)
            table = evaluate(MotionDiffusion.load(model), Evaluator.load(evaluator), data, cfg)
            table.write(tables / run.name)
        table = json.loads(path.read_text())
        _check_meta(table["meta"], run, path)
        out[run.name] = table
    return out


Setting = tuple[str, int, str]  # (sampler, steps, physics mode)


def warm_timings(settings: Sequence[Setting], rounds: int, model=None) -> dict[Setting, list[float]]:
    """Seconds of ``generate`` for one 6 s motion per setting in a warm process, ``rounds`` rounds each."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.samplers import SamplerConfig
    from physmotion.generate import GenerateConfig, generate

    model = model or MotionDiffusion.load()
    configs = {key: GenerateConfig(seconds=SECONDS, physics=key[2], sampler=SamplerConfig(sampler=key[0],
                                                                                           steps=key[1]))
               for key in settings}  # fmt: skip
    for cfg in configs.values():  # warm-up: encoder load, lazy imports, each scheduler's first call
        generate([PROMPT], cfg, model)
    times: dict[Setting, list[float]] = {key: [] for key in settings}
    for _ in range(rounds):
        for key, cfg in configs.items():
            start = time.perf_counter()
            generate([PROMPT], cfg, model)
            times[key].append(time.perf_counter() - start)
    return times


def table_rows(
    runs: Sequence[EvalRun], tables: dict[str, dict], times: dict[Setting, list[float]]
) -> list[dict]:
    """One row per (run, mode): the evaluate figures, the comparison with DDIM 50, the warm timing."""
    base = tables[BASELINE]["rows"]
    rows = []
    for run in runs:
        for mode in run.modes:
            r = tables[run.name]["rows"][mode]
            ref = base["none" if mode == "none" else PHYSDIFF_BASE]
            warm, plain = (
                times.get((run.sampler, run.steps, mode)),
                times.get((run.sampler, run.steps, "none")),
            )
            rows.append({
                "sampler": run.sampler, "steps": run.steps, "physics": mode,
                **{k: r[k] for k in ("FID", "R@3", "R@1", "MM-Dist", "Diversity", "phys_err", "penetrate", "float",
                                     "skate", "smoothness", "reset_rate", "resets", "sec/motion") if k in r},
                "FID_within": within_interval(r["FID"]["mean"], ref["FID"], False),
                "R@3_within": within_interval(r["R@3"]["mean"], ref["R@3"], True),
                "warm_s": min(warm) if warm else None, "warm_rounds_s": warm,
                "warm_over_plain": min(warm) / min(plain) if warm and plain and mode != "none" else None,
            })  # fmt: skip
    return rows


def acceptance(rows: list[dict]) -> list[dict]:
    """Issue 51's lines for every row but DDIM 50's (None where the row was not timed)."""
    out = []
    for r in rows:
        if (r["sampler"], r["steps"]) == ("ddim", 50):
            continue
        plain = r["physics"] == "none"
        out.append({"sampler": r["sampler"], "steps": r["steps"], "physics": r["physics"],
                    "FID_and_R@3_within": r["FID_within"] and r["R@3_within"],
                    "plain_at_most_0.2_s": (r["warm_s"] <= PLAIN_LIMIT_S) if plain and r["warm_s"] else None,
                    "physdiff_at_most_1.5x_plain": (r["warm_over_plain"] <= PHYSDIFF_RATIO)
                    if not plain and r["warm_over_plain"] else None})  # fmt: skip
    return out


def _fmt(v: dict | None, digits: int = 3) -> str:
    return "-" if v is None else f"{v['mean']:.{digits}f} ± {v['ci95']:.{digits}f}"


def markdown(rows: list[dict], meta: dict) -> str:
    """The table with a header saying how it was made."""
    header = ["sampler", "steps", "physics", "FID", "R@3", "Phys-Err mm", "reset_rate", "sec/motion (evaluate)",
              "warm s (one 6 s motion)", "x plain", "FID, R@3 within DDIM 50's"]  # fmt: skip
    body = [[r["sampler"], r["steps"], r["physics"], _fmt(r["FID"]), _fmt(r["R@3"]), _fmt(r["phys_err"], 2),
             _fmt(r.get("reset_rate")), _fmt(r["sec/motion"], 2),
             "-" if r["warm_s"] is None else f"{r['warm_s']:.3f}",
             "-" if r["warm_over_plain"] is None else f"{r['warm_over_plain']:.1f}",
             f"{'yes' if r['FID_within'] else 'no'}, {'yes' if r['R@3_within'] else 'no'}"] for r in rows]  # fmt: skip
    t = meta.get("timing")
    timing = (f"Warm: `generate` of one {SECONDS:g} s motion in a warm process, min of {t['rounds']} rounds, "
              f"{t['torch_threads']} torch threads, load average {t['load_before']} before and "
              f"{t['load_after']} after." if t else "Warm timings not run (--skip-timing).")  # fmt: skip
    return (heading("Few-step sampling against DDIM 50 (issue 51, item 2)", meta) +
            f"Test split ({meta['motions']} motions), {REPEATS} repeats, mean ± 95 % interval, model "
            f"{meta.get('model', 'shipped')}, evaluator {meta.get('evaluator', 'shipped')}, CFG 2.5, eta 0, "
            f"seed 0; Phys-Err on the humanoid surface. Plain rows are held "
            f"against DDIM 50's `none` intervals, PhysDiff rows against DDIM 50's `{PHYSDIFF_BASE}` (within or "
            f"better). sec/motion: evaluate's wall time per motion (batches of 16, 2 cores shared with other "
            f"jobs). {timing}\n\n" + markdown_table(header, body) + "\n")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="data_build/mocap", help="HumanML3D-layout folder")
    parser.add_argument("--tables", default="runs/sampling_steps", help="folder of the evaluate tables")
    parser.add_argument(
        "--runs", type=int, default=5, help="timed rounds after the warm-up; the minimum counts"
    )
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="torch threads for the timing (default: torch's; 1 keeps a loaded machine's cores "
        "from stalling every parallel region)",
    )
    parser.add_argument("--skip-timing", action="store_true", help="the quality table only")
    parser.add_argument("--out", default="results/sampling_steps", help="output stem")
    parser.add_argument("--model", default=None, help="model folder (default: the shipped one)")
    parser.add_argument("--evaluator", default=None, help="evaluator folder (default: the shipped one)")
    args = parse_args(parser, argv)

    def run() -> tuple[str, list[Path]]:
        tdir = Path(args.tables)
        tables = eval_tables(RUNS, args.data, tdir, args.model, args.evaluator)
        commands = {r.name: evaluate_command(r, args.data, tdir, args.model, args.evaluator) for r in RUNS}
        meta = run_meta(__file__, argv, args.tree, "sampling", motions=tables[BASELINE]["meta"]["motions"],
                        data=args.data, model=args.model or "shipped", evaluator=args.evaluator or "shipped",
                        evaluate_commands=commands)  # fmt: skip
        times: dict[Setting, list[float]] = {}
        if not args.skip_timing:
            import torch

            if args.threads:
                torch.set_num_threads(args.threads)
            before = os.getloadavg()
            from physmotion.diffusion.model import MotionDiffusion

            times = warm_timings([(r.sampler, r.steps, m) for r in RUNS for m in r.modes], args.runs,
                                 MotionDiffusion.load(args.model))  # fmt: skip
            meta["timing"] = {"rounds": args.runs, "prompt": PROMPT, "seconds": SECONDS,
                              "torch_threads": torch.get_num_threads(),
                              "load_before": " ".join(f"{x:.2f}" for x in before),
                              "load_after": " ".join(f"{x:.2f}" for x in os.getloadavg())}  # fmt: skip
        rows = table_rows(RUNS, tables, times)
        md = markdown(rows, meta)
        return md, write_results(args.out, md, {"meta": meta, "rows": rows, "acceptance": acceptance(rows)})

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
