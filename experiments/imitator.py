"""The learned imitation policy against the model-based tracker, inside P: one table from one run.

Usage: python -m experiments.imitator generated [--seeds 0,1,2] [--categories run,jog,jump,hop,kick]
       python -m experiments.imitator captured [--mocap ../shared/data/mocap,../shared/data/hdm05] [--limit N]
       (either with --policy DIR; default: the shipped one; --out results/imitator_<part>)

generated: the unseen prompts (``experiments.prompts.NEW_PROMPTS``) of the fast categories, 6 s each, PhysDiff's
default schedule with P driven by the tracker and by the policy, against the same seed's ``none+floor``.
Per output: Phys-Err (mm) and whether it is below ``none+floor``'s, the projection's resets, the root
residual force (fractions of body weight W) and torque (W x 1 m) of the last projection, and that
projection's MPJPE to the motion it was given (the denoiser's prediction at the last step).

captured: every clip of the mocap folders, the plain P (no reset: imitation selection), per category of
motion (``experiments.projection_quality``, as ``experiments/projection_dynamic.py``): success, MPJPE, Float, Skate
and Penetrate of the input and of the simulation, root residual force and torque (mean and p95).

Writes ``<out>.md`` (the table) and ``<out>.json`` (per-output rows and a meta block: command, commit,
CPU, date, P's preset and controller settings).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from experiments._results import parse_args, run_meta, write_results
from physmotion.conventions import FPS
from physmotion.physics.presets import preset

FAST = ("run", "jog", "jump", "hop", "kick")
CONTROLLERS = ("tracker", "tracker at cap", "policy")  # "tracker at cap": its residual bounded as the policy's


def _with_controller(config, name: str, policy_dir: str | None):
    """``config`` (a ProjectionConfig or GenerateConfig) driven by the controller called ``name``."""
    from physmotion.physics.policy import capped_tracking, load_policy

    if name != "tracker at cap":
        return config.with_controller(name, policy_dir)
    cap = load_policy(policy_dir).settings.cap
    if hasattr(config, "projection"):
        return replace(config, projection=replace(config.projection,
                                                  tracking=capped_tracking(config.projection.tracking, cap)))
    return replace(config, tracking=capped_tracking(config.tracking, cap))


def _meta(args: argparse.Namespace, argv: list[str] | None, preset_name: str) -> dict:
    from physmotion.physics.policy import load_policy

    policy = load_policy(args.policy)
    return run_meta(__file__, argv, args.tree, preset_name, policy=args.policy or "shipped",
                    policy_cap=policy.settings.cap,
                    policy_card={k: policy.card.get(k) for k in ("iterations", "samples", "wall_minutes", "hardware")})


def _phys(joints: np.ndarray, body) -> dict[str, float]:
    from physmotion.metrics import physical_metrics
    from physmotion.physics.surface import HumanoidSurface

    return physical_metrics(joints[None], FPS, body=HumanoidSurface([body]))


def generated(args: argparse.Namespace, argv: list[str] | None = None) -> tuple[list[dict], dict]:
    from experiments.prompts import NEW_PROMPTS
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.samplers import ddim_50
    from physmotion.generate import GenerateConfig, generate

    model = MotionDiffusion.load(args.model)
    rows = []
    for cat in args.categories.split(","):
        prompts = list(NEW_PROMPTS[cat])
        for seed in [int(s) for s in args.seeds.split(",")]:
            base = GenerateConfig(seed=seed, sampler=ddim_50(), projection=preset("sampling"))
            floor = generate(prompts, replace(base, physics="none+floor"), model)
            outs = {}
            for ctrl in CONTROLLERS:
                start = time.perf_counter()
                outs[ctrl] = generate(prompts, _with_controller(base, ctrl, args.policy), model)
                outs[ctrl].seconds = time.perf_counter() - start
            for i, text in enumerate(prompts):
                f = floor.motions[i]
                n_last = len(prompts)  # the last projection's entries: the outputs (PhysDiff projects last)
                base_err = _phys(f.joints, f.humanoid)["phys_err"]
                for ctrl in CONTROLLERS:
                    m = outs[ctrl].motions[i]
                    err = _phys(m.joints, m.humanoid)["phys_err"]
                    res = m.residual if m.residual is not None else np.zeros((len(m.joints), 2))
                    last = outs[ctrl].projections.mpjpe_mm[-n_last:]
                    rows.append({
                        "category": cat, "prompt": text, "seed": seed, "controller": ctrl,
                        "phys_err": err, "floor_phys_err": base_err, "below_floor": bool(err < base_err),
                        "resets": int(m.resets or 0),
                        "residual_force": float(res[:, 0].mean()), "residual_torque": float(res[:, 1].mean()),
                        "residual_force_p95": float(np.percentile(res[:, 0], 95)),
                        "mpjpe_last_projection_mm": float(last[i]),
                        "seconds": outs[ctrl].seconds / len(prompts),
                    })  # fmt: skip
            print(f"{cat} seed {seed} done", file=sys.stderr, flush=True)
            if args.partial:  # a long run leaves what it has measured so far
                Path(args.partial).write_text(json.dumps(rows))
    return rows, _meta(args, argv, "sampling")


def captured(args: argparse.Namespace, argv: list[str] | None = None) -> tuple[list[dict], dict]:
    from experiments.projection_quality import by_category, measure_clips, spread
    from physmotion.io.importer import load_manifest

    clips = spread([c for folder in args.mocap.split(",") for c in load_manifest(folder)], args.limit)
    rows = []
    for ctrl in CONTROLLERS:
        start = time.perf_counter()
        measured = measure_clips(clips, _with_controller(preset("plain"), ctrl, args.policy))
        seconds = (time.perf_counter() - start) / len(clips)
        for cat, row in by_category(clips, measured).items():
            rows.append({"controller": ctrl, "category": cat, **row, "seconds_per_clip": seconds})
        print(f"{ctrl} done", file=sys.stderr, flush=True)
    return rows, _meta(args, argv, "plain")


def _table(rows: list[dict], part: str) -> str:
    def mean(sel, key):
        return float(np.mean([r[key] for r in sel]))

    if part == "generated":
        head = ("| category | P's controller | outputs | with a reset | Phys-Err mm | none+floor mm | below none+floor "
                "| residual W | residual p95 W | torque W m | MPJPE of the last P mm | s/motion |")  # fmt: skip
        lines = [head, "|---" * 12 + "|"]
        for cat in dict.fromkeys(r["category"] for r in rows):
            for ctrl in CONTROLLERS:
                sel = [r for r in rows if r["category"] == cat and r["controller"] == ctrl]
                lines.append(f"| {cat} | {ctrl} | {len(sel)} | {100 * np.mean([r['resets'] > 0 for r in sel]):.0f} % "
                             f"| {mean(sel, 'phys_err'):.1f} | {mean(sel, 'floor_phys_err'):.1f} "
                             f"| {100 * mean(sel, 'below_floor'):.0f} % | {mean(sel, 'residual_force'):.3f} "
                             f"| {mean(sel, 'residual_force_p95'):.3f} | {mean(sel, 'residual_torque'):.3f} "
                             f"| {mean(sel, 'mpjpe_last_projection_mm'):.0f} | {mean(sel, 'seconds'):.2f} |")  # fmt: skip
        for ctrl in CONTROLLERS:
            sel = [r for r in rows if r["controller"] == ctrl]
            lines.append(f"| **all** | {ctrl} | {len(sel)} | {100 * np.mean([r['resets'] > 0 for r in sel]):.0f} % "
                         f"| {mean(sel, 'phys_err'):.1f} | {mean(sel, 'floor_phys_err'):.1f} "
                         f"| {100 * mean(sel, 'below_floor'):.0f} % | {mean(sel, 'residual_force'):.3f} "
                         f"| {mean(sel, 'residual_force_p95'):.3f} | {mean(sel, 'residual_torque'):.3f} "
                         f"| {mean(sel, 'mpjpe_last_projection_mm'):.0f} | {mean(sel, 'seconds'):.2f} |")  # fmt: skip
        return "\n".join(lines)
    head = ("| category | P's controller | clips | success | MPJPE mm | Float in→out mm | Skate in→out mm "
            "| Penetrate in→out mm | residual W mean / p95 | torque W m mean / p95 | s/clip |")
    lines = [head, "|---" * 11 + "|"]
    for cat in dict.fromkeys(r["category"] for r in rows):
        for r in (r for r in rows if r["category"] == cat):
            lines.append(f"| {cat} | {r['controller']} | {r['clips']} | {100 * r['success']:.1f} % "
                         f"| {r['mpjpe_mm']:.1f} | {r['float_in']:.2f} → {r['float_out']:.2f} "
                         f"| {r['skate_in']:.2f} → {r['skate_out']:.2f} "
                         f"| {r['penetrate_in']:.2f} → {r['penetrate_out']:.2f} "
                         f"| {r['residual_force_mean']:.3f} / {r['residual_force_p95']:.3f} "
                         f"| {r['residual_torque_mean']:.3f} / {r['residual_torque_p95']:.3f} "
                         f"| {r['seconds_per_clip']:.2f} |")  # fmt: skip
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", choices=("generated", "captured"))
    parser.add_argument("--policy", default=None)
    parser.add_argument("--model", default=None)
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--categories", default=",".join(FAST))
    parser.add_argument("--mocap", default="../shared/data/mocap,../shared/data/hdm05",
                        help="captured: comma-separated mocap folders (each with its manifest.csv)")
    parser.add_argument("--limit", type=int, default=0, help="captured: only N clips, evenly spread")
    parser.add_argument("--out", default=None)
    parser.add_argument("--partial", default=None, help="generated: rewrite the rows so far to this JSON file")
    args = parse_args(parser, argv)
    rows, meta = generated(args, argv) if args.part == "generated" else captured(args, argv)
    table = _table(rows, args.part)
    print(table)
    md = f"# P's controllers on {args.part} motion\n\n`{meta['command']}` (commit {meta['commit']}, {meta['cpu']})\n\n{table}\n"
    write_results(args.out or f"results/imitator_{args.part}", md, {"meta": meta, "rows": rows})


if __name__ == "__main__":
    main()
