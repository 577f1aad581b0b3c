"""BioMoDiffuse's ablation (Tables 3 + 4) and speed-control study (Table 6) on our data, in one command.

    python -m experiments.biomodiffuse --data data_build/mocap --data329 data_build/mocap329 \\
        --runs runs/biomo_ablation -o results/biomodiffuse [--steps 2500] [--repeats 3]

``--data`` is the 263-d build (``physmotion data build``), ``--data329`` the 329-d one with activations
(``physmotion data build --features 329 --activations``); both come from the same mocap, so their splits
are the same. Trains the four models of :data:`RUNS` into ``--runs`` (a run already there at ``--steps`` is
reused, an unfinished one resumed): the same UNet width, steps, batch, crop and seed for all. Then
evaluates each row on the 263-d build's test split with the shipped evaluator, and the full model at each
speed of :data:`SPEEDS`, and writes <out>.md and <out>.json atomically. Hours of CPU: each model trains at
about 0.3-0.6 s per step on 2 cores. No projection: the meta's preset is null.

Rows, as the paper's, each a model trained with the same width, steps, seed and data order and sampled
alike (SDE DPM-Solver++, 10 steps, CFG 2.5):

- ``UNet baseline (263-d)``: the 1D UNet on HumanML3D's 263-d features, x0 MSE;
- ``+ L_accel (329-d)``: the same UNet on the 329-d features, L_diffusion + L_accel;
- ``+ PhysNet``: the UNet with the physical network (``arch="biomo"``), trained without P_c dropout and
  sampled with the network on every pass (the paper's row without guidance);
- ``+ PhysNet (P_c 10 %)``: the model of the last row, trained with P_c = 10 % (physics guidance needs
  the dropout), sampled with the network on every pass: what the dropout alone changes;
- ``+ physics guidance``: that model sampled with physics guidance (``phys_scale``).

Every row is measured by :func:`physmotion.eval.table.evaluate` (mode ``none``: no projection) on the
263-d build's split, so all rows meet the same real motions, captions and lengths.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import torch

from experiments._results import parse_args, run_meta, write_results
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.samplers import BIOMO_SAMPLER, SamplerConfig
from physmotion.diffusion.train import STATE_FILE, TrainConfig, train_denoiser
from physmotion.eval.evaluator import Evaluator
from physmotion.eval.table import REAL, EvaluateConfig, evaluate
from physmotion.generate import GenerateConfig
from physmotion.motion import write_atomic
from physmotion.nets.denoiser import DenoiserConfig

Row = dict[str, tuple[float, float]]  # metric -> (mean, 95 % half-width)

GENERATION = ("FID", "R@1", "R@2", "R@3", "MM-Dist", "Diversity", "MModality")
PHYSICAL = ("vc", "ac", "speed", "smoothness", "float_ratio", "skate_ratio", "penetrate_ratio", "clip_ratio",
            "phys_err")  # fmt: skip
SPEED_COLUMNS = ("FID", "R@3", "speed", "smoothness", "skate_ratio", "float_ratio")
SPEEDS = (0.5, 0.75, 1.0, 1.25, 1.5)
# The physical metrics "full BioMoDiffuse beats the baseline" is counted on; each metric's own ``better``
# (physmotion.metrics.physical.METRICS) says which way: lower, or closer to the real motions' value.
WIN_COLUMNS = ("vc", "ac", "smoothness", "skate_ratio", "float_ratio", "penetrate_ratio")


@dataclass(frozen=True)
class AblationRow:
    """One row: its label, the training run it samples (a folder name), and its physics guidance."""

    name: str
    run: str
    phys_scale: float | None = None

    def sampler(self) -> SamplerConfig:
        return replace(BIOMO_SAMPLER, phys_scale=self.phys_scale)


ROWS = (
    AblationRow("UNet baseline (263-d)", "unet263"),
    AblationRow("+ L_accel (329-d)", "unet329"),
    AblationRow("+ PhysNet", "biomo_nodrop"),
    AblationRow("+ PhysNet (P_c 10 %)", "biomo"),
    AblationRow("+ physics guidance", "biomo", BIOMO_SAMPLER.phys_scale),
)

RUNS: dict[str, dict] = {  # how each run is trained: its architecture, features and P_c
    "unet263": {"arch": "unet", "features": 263, "phys_drop": 0.0},
    "unet329": {"arch": "unet", "features": 329, "phys_drop": 0.0},
    "biomo_nodrop": {"arch": "biomo", "features": 329, "phys_drop": 0.0},
    "biomo": {"arch": "biomo", "features": 329, "phys_drop": 0.1},
}


def evaluate_row(
    model: MotionDiffusion,
    evaluator: Evaluator,
    data: str | Path,
    sampler: SamplerConfig,
    repeats: int = 3,
    seed: int = 0,
    on_progress: Callable[[int, int], None] | None = None,
    real_row: bool = True,
) -> tuple[Row, Row | None]:
    """(generated row, real row or None) of one model sampled with ``sampler``, no projection, ``repeats``
    runs. The real row does not depend on the model: ask for it once (``real_row``)."""
    cfg = EvaluateConfig(modes=("none",), repeats=repeats, seed=seed, base=GenerateConfig(sampler=sampler),
                         real_row=real_row)  # fmt: skip
    table = evaluate(model, evaluator, data, cfg, on_progress=on_progress)
    return table.rows["none"], table.rows.get(REAL)


def separated(a: Row, b: Row, columns: tuple[str, ...]) -> dict[str, str]:
    """For each column both rows have, ">" or "<" when b's mean lies above or below a's and the two 95 %
    intervals do not overlap, else "~" (within the noise of ``repeats`` runs)."""
    out = {}
    for col in (c for c in columns if c in a and c in b):  # MModality needs 2+ repeats
        (ma, ha), (mb, hb) = a[col], b[col]
        out[col] = ">" if mb - hb > ma + ha else "<" if mb + hb < ma - ha else "~"
    return out


def wins(baseline: Row, row: Row, real: Row, columns: tuple[str, ...] = WIN_COLUMNS) -> list[str]:
    """The columns where ``row`` is better than ``baseline`` beyond both 95 % intervals: lower, or (for
    metrics whose ``better`` is "closer to real") nearer the real row's mean by more than the two
    half-widths."""
    from physmotion.metrics.physical import METRICS

    out = []
    for c in columns:
        (ma, ha), (mb, hb) = baseline[c], row[c]
        if METRICS[c].better == "lower":
            won = mb + hb < ma - ha
        else:
            target = real[c][0]
            won = abs(mb - target) + hb < abs(ma - target) - ha
        if won:
            out.append(c)
    return out


def fmt(value: tuple[float, float]) -> str:
    mean, half = value
    digits = 3 if abs(mean) < 10 else 1
    return f"{mean:.{digits}f} ± {half:.{digits}f}"


def markdown_table(rows: dict[str, Row], columns: tuple[str, ...], first: str = "row") -> str:
    """One Markdown table: a row per entry of ``rows``, "mean ± half-width" per column."""
    lines = ["| " + " | ".join((first, *columns)) + " |", "|" + "---|" * (len(columns) + 1)]
    for name, row in rows.items():
        lines.append("| " + " | ".join((name, *(fmt(row[c]) if c in row else "" for c in columns))) + " |")
    return "\n".join(lines)


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


def main(argv: list[str] | None = None) -> None:
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
    args = parse_args(parser, argv)
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
        "meta": run_meta(__file__, argv, args.tree, None) | {
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
    write_results(args.out, _markdown(result), result)
    print(_markdown(result))


def _markdown(result: dict) -> str:
    meta, rows = result["meta"], result["rows"]
    cmp = result["full_vs_baseline"]
    diff = ", ".join(f"{c} {s}" for c, s in cmp["separated"].items() if s != "~") or "none"
    lines = [
        "# BioMoDiffuse ablation on our data (Tables 3, 4 and 6)",
        "",
        f"Written by `python -m experiments.biomodiffuse` ({meta['split']} split, {meta['repeats']} repeats, "
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
