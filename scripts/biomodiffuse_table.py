"""BioMoDiffuse's ablation (Tables 3 + 4) and speed-control study (Table 6) on our data, in one command.

    python scripts/biomodiffuse_table.py --data data_build/mocap --data329 data_build/mocap329 \\
        --runs runs/biomo_ablation -o results/biomodiffuse [--steps 2500] [--repeats 3]

``--data`` is the 263-d build (``physmotion data build``), ``--data329`` the 329-d one with activations
(``physmotion data build --features 329 --activations``); both come from the same mocap, so their splits
are the same. Trains the four models of :data:`physmotion.eval.ablation.RUNS` into ``--runs`` (a run
already there at ``--steps`` is reused, an unfinished one resumed): the same UNet width, steps, batch,
crop and seed for all. Then evaluates each row on the 263-d build's test split with the shipped
evaluator, and the full model at each speed of :data:`~physmotion.eval.ablation.SPEEDS`, and writes
<out>.md and <out>.json atomically. Hours of CPU: each model trains at about 0.3-0.6 s per step on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, replace
from pathlib import Path

import torch

from physmotion.nets.denoiser import DenoiserConfig
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.train import STATE_FILE, TrainConfig, train_denoiser
from physmotion.eval.ablation import (
    GENERATION,
    PHYSICAL,
    ROWS,
    RUNS,
    SPEED_COLUMNS,
    SPEEDS,
    WIN_COLUMNS,
    evaluate_row,
    markdown_table,
    separated,
    wins,
)
from physmotion.eval.evaluator import Evaluator
from physmotion.eval.table import table_paths
from physmotion.motion import write_atomic


def train_runs(args: argparse.Namespace, only: str | None = None) -> dict[str, MotionDiffusion]:
    """Train (or reuse, or resume) every run the rows need (or the run ``only``); returns the loaded models,
    on ``args.device``."""
    models = {}
    for run in [only] if only else dict.fromkeys(r.run for r in ROWS):
        out = Path(args.runs) / run
        spec = RUNS[run]
        data = args.data if spec["features"] == 263 else args.data329
        den = DenoiserConfig(arch=spec["arch"], d_model=args.d_model, layers=args.layers)
        cfg = TrainConfig(data=str(data), out=str(out), denoiser=den, crop=args.crop, batch_size=args.batch,
                          steps=args.steps, seed=args.seed, phys_drop=spec["phys_drop"],
                          device=args.device, bf16=args.bf16, accel_weight=args.accel_weight)  # fmt: skip
        done = (out / "config.json").is_file() and MotionDiffusion.load(out).info.get("steps") == args.steps
        if not done:
            print(f"training {run} to step {args.steps} in {out}", file=sys.stderr)
            train_denoiser(cfg, resume=(out / STATE_FILE).is_file(), progress=sys.stderr.isatty())
        models[run] = MotionDiffusion.load(out, device=args.device)
    return models


def _measured(args, run: str, label: str, sampler, repeats: int, evaluator, models, real_row: bool):
    """evaluate_row, kept in <runs>/<run>/eval_cache.json under everything it depends on, so that a
    re-run (or a row measured while another model still trains) is not measured twice."""
    path = Path(args.runs) / run / "eval_cache.json"
    key = json.dumps({"sampler": asdict(sampler), "repeats": repeats, "seed": args.seed, "data": str(args.data),
                      "steps": args.steps, "evaluator": args.evaluator, "real": real_row}, sort_keys=True)  # fmt: skip
    cache = json.loads(path.read_text()) if path.is_file() else {}
    if key not in cache:
        print(f"evaluating {label}", file=sys.stderr)
        row, real = evaluate_row(
            models[run], evaluator, args.data, sampler, repeats, args.seed, real_row=real_row
        )
        cache[key] = {"row": row, "real": real}
        write_atomic(path, lambda f: f.write(json.dumps(cache, indent=1)), "w")
    return _as_row(cache[key]["row"]), _as_row(cache[key]["real"])


def _as_row(stored: dict | None):
    """A row read back from JSON: (mean, half-width) lists -> tuples."""
    return None if stored is None else {k: tuple(v) for k, v in stored.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="263-d build")
    parser.add_argument("--data329", required=True, help="329-d build with activations")
    parser.add_argument("--runs", default="runs/biomo_ablation")
    parser.add_argument("-o", "--out", default="results/biomodiffuse")
    parser.add_argument("--evaluator", default=None, help="evaluator folder (default: the shipped one)")
    parser.add_argument("--steps", type=int, default=2500)
    parser.add_argument("--d-model", type=int, default=128)
    parser.add_argument("--layers", type=int, default=3)
    parser.add_argument("--crop", type=int, default=120)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--speed-repeats", type=int, default=1, help="repeats of each Table 6 row")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--accel-weight", type=float, default=TrainConfig.accel_weight,
                        help="weight of L_accel in the 329-d runs (the 263-d baseline has no acceleration dims)")
    parser.add_argument("--device", default="cpu", help="where to train and sample: cpu or cuda")
    parser.add_argument("--bf16", action=argparse.BooleanOptionalAction, default=None,
                        help="bf16 autocast in training (default: where the hardware has it natively; the "
                             "committed table: --no-bf16)")
    parser.add_argument("--train-only", choices=list(RUNS), default=None,
                        help="train this one run and stop (several runs can then train side by side)")
    args = parser.parse_args()
    if args.device.startswith("cuda"):
        torch.set_float32_matmul_precision("high")  # TF32 matmuls, as the committed table's GPU run

    models = train_runs(args, args.train_only)
    if args.train_only:
        return
    evaluator = Evaluator.load(args.evaluator)
    rows, real = {}, None
    for row in ROWS:
        rows[row.name], first = _measured(args, row.run, row.name, row.sampler(), args.repeats, evaluator,
                                          models, real is None)  # fmt: skip
        real = real or first
    full = ROWS[-1]
    speed_rows = {}
    for s in SPEEDS:
        sampler = replace(full.sampler(), speed=s)
        speed_rows[f"{s:g}"], _ = _measured(args, full.run, f"speed {s:g}", sampler, args.speed_repeats,
                                            evaluator, models, False)  # fmt: skip

    baseline, last = rows[ROWS[0].name], rows[full.name]
    result = {
        "meta": {
            "data": args.data,
            "data329": args.data329,
            "steps": args.steps,
            "d_model": args.d_model,
            "layers": args.layers,
            "crop": args.crop,
            "batch": args.batch,
            "device": args.device,
            "bf16": args.bf16,
            "repeats": args.repeats,
            "speed_repeats": args.speed_repeats,
            "seed": args.seed,
            "accel_weight": args.accel_weight,
            "split": "test",
            "sampler": asdict(full.sampler()),
            "models": {
                run: {
                    "parameters": sum(p.numel() for p in m.net.parameters()),
                    "train_seconds": m.info.get("train_seconds"),
                    "licence": m.licence_tag,
                }
                for run, m in models.items()
            },
        },
        "rows": {"real": real, **rows},
        "speed": speed_rows,
        "full_vs_baseline": {
            "separated": separated(baseline, last, GENERATION + PHYSICAL),
            "wins": wins(baseline, last, real),
            "fid_within_or_better": last["FID"][0] - last["FID"][1]
            <= baseline["FID"][0] + baseline["FID"][1],
        },
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    md_path, js_path = table_paths(out)
    write_atomic(js_path, lambda f: f.write(json.dumps(result, indent=2) + "\n"), "w")
    write_atomic(md_path, lambda f: f.write(_markdown(result)), "w")
    print(_markdown(result))


def _markdown(result: dict) -> str:
    meta, rows = result["meta"], result["rows"]
    cmp = result["full_vs_baseline"]
    diff = ", ".join(f"{c} {s}" for c, s in cmp["separated"].items() if s != "~") or "none"
    lines = [
        "# BioMoDiffuse ablation on our data (Tables 3, 4 and 6)",
        "",
        f"Written by `python scripts/biomodiffuse_table.py` ({meta['split']} split, {meta['repeats']} repeats, "
        f"mean ± 95 % half-width). Every model: 1D UNet, width {meta['d_model']}, {meta['layers']} levels, "
        f"{meta['steps']} steps, batch {meta['batch']}, crop {meta['crop']}, seed {meta['seed']}, "
        f"L_accel weight {meta.get('accel_weight', 1.0):g} (329-d rows), "
        f"trained and sampled on {meta['device']}. Sampling: "
        f"{meta['sampler']['sampler']}, {meta['sampler']['steps']} steps, CFG {meta['sampler']['cfg_scale']:g}; "
        "no projection.",
        "",
        "Parameters: "
        + ", ".join(f"{run} {m['parameters'] / 1e6:.2f} M" for run, m in meta["models"].items())
        + '. "+ PhysNet" is trained without P_c; the last two rows sample one model trained with P_c = 10 %. '
        "The Table 6 speed S scales the physical network's accelerations before they enter the UNet.",
        "",
        "## Table 3: generation",
        "",
        markdown_table(rows, GENERATION),
        "",
        "## Table 4: physical plausibility",
        "",
        markdown_table(rows, PHYSICAL),
        "",
        "## Full BioMoDiffuse against the UNet baseline",
        "",
        f"- Beyond both 95 % intervals (> higher, < lower): {diff}.",
        f"- Better on {len(cmp['wins'])} of {len(WIN_COLUMNS)} of {', '.join(WIN_COLUMNS)}: "
        f"{', '.join(cmp['wins']) or 'none'} (the issue asks for 4).",
        f"- FID within the baseline's interval or better: {'yes' if cmp['fid_within_or_better'] else 'no'}.",
        "",
        f"## Table 6: speed control signal (full model, physics guidance; {meta['speed_repeats']} repeat(s))",
        "",
        markdown_table({"real": rows["real"], **result["speed"]}, SPEED_COLUMNS, first="speed S"),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
