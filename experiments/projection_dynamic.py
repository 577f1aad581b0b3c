"""The physics projection on every captured clip, by category of motion, for the baseline tracker and for
each change made for dynamic motion: writes results/projection_dynamic.md and .json.

Usage: python scripts/projection_dynamic.py [--mocap ../shared/data/mocap] [--out results/projection_dynamic]
       [--limit N]
Rows: "tracker v0.1" (the model-based tracker as it was: no toe-off flattening, the root residual carries
the whole root wrench, bounded at 0.3 W and held over 4 simulation steps), "+ toe-off", "+ feet balance",
"toe-off + feet balance" (both, with the residual above), "+ ballistic flight" (that, with flight phases
made ballistic), and "default" (``ProjectionConfig()``: all of it, the residual bounded at 0.2 W and held
over 2 steps, the feet's fit weighting torque 0.3), and "default + ILC" (iterative learning control:
``ProjectionConfig(ilc_passes=2)``, the option of ``physmotion project --ilc``, three simulations per clip),
and "default at 1/720 s" (``ProjectionConfig().at_fine_step()``, the option of ``physmotion project
--fine-step``: half the simulation step, twice the steps).
Categories from the captions (physmotion.eval.projection_quality.category). Input metrics are measured on
the input grounded on the humanoid's surface (the metrics' floor convention), output metrics on the
simulation; airborne: share of frames with no foot patch within 2 cm of the floor.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

from physmotion.eval.projection_quality import by_category, measure_clips
from physmotion.io.importer import load_manifest
from physmotion.motion import write_atomic
from physmotion.physics.projection import ProjectionConfig
from physmotion.physics.shaping import ShapingConfig
from physmotion.physics.tracking import TrackingConfig


def configs() -> dict[str, ProjectionConfig]:
    base = ProjectionConfig()
    # The residual before docs/decisions/projection.md "residual within 0.1 W on walks and runs": a baseline
    # row.
    held = replace(base, humanoid=replace(base.humanoid, residual_every=4),
                   tracking=replace(base.tracking, residual_force=0.3, feet_torque_weight=1.0))
    no_feet = replace(held.tracking, feet_balance=False)
    no_ballistic = replace(base.shaping, ballistic_flight=False)
    no_toe = replace(no_ballistic, flatten_toe_off=False)
    return {
        "tracker v0.1": replace(held, tracking=no_feet, shaping=no_toe),
        "+ toe-off": replace(held, tracking=no_feet, shaping=no_ballistic),
        "+ feet balance": replace(held, shaping=no_toe),
        "toe-off + feet balance": replace(held, shaping=no_ballistic),
        "+ ballistic flight": held,
        "default": base,
        "default + ILC": replace(base, ilc_passes=2),
        "default at 1/720 s": ProjectionConfig().at_fine_step(),
    }


ACCEPTANCE_ROWS = ("default", "default + ILC", "default at 1/720 s")  # the rows judged against TARGETS
TARGETS = {  # the acceptance, per row of the default on runs and jumps
    "success >= 95 %": lambda r: r["success"] >= 0.95,
    "MPJPE <= 60 mm": lambda r: r["mpjpe_mm"] <= 60.0,
    "Float <= input + 2 mm": lambda r: r["float_out"] <= r["float_in"] + 2.0,
    "Skate < input": lambda r: r["skate_out"] < r["skate_in"],
    "Penetrate < input": lambda r: r["penetrate_out"] < r["penetrate_in"],
    "airborne within 10 points": lambda r: abs(r["airborne_out"] - r["airborne_in"]) <= 0.10,
}


def _category_table(rows: dict[str, dict[str, float]]) -> list[str]:
    lines = ["| category | clips | success | MPJPE mm | Penetrate in→out | Float in→out | Skate in→out | "
             "Phys-Err in→out | airborne in→out | feet touching in→out | slide per touch in→out | "
             "residual F mean / p95 (W) | residual τ mean / p95 (W m) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        cells = [name, str(r["clips"]), f"{100 * r['success']:.1f} %", f"{r['mpjpe_mm']:.1f}"]
        cells += [f"{r[k + '_in']:.2f} → {r[k + '_out']:.2f}" for k in ("penetrate", "float", "skate", "phys_err")]
        cells += [f"{100 * r['airborne_in']:.1f} → {100 * r['airborne_out']:.1f} %",
                  f"{100 * r['contact_in']:.1f} → {100 * r['contact_out']:.1f} %",
                  f"{r['slide_in']:.1f} → {r['slide_out']:.1f}",
                  f"{r['residual_force_mean']:.3f} / {r['residual_force_p95']:.3f}",
                  f"{r['residual_torque_mean']:.3f} / {r['residual_torque_p95']:.3f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _markdown(results: dict[str, dict[str, dict[str, float]]], seconds: dict[str, float]) -> str:
    out = ["# Physics projection on captured motion, by category",
           "",
           "Written by `python scripts/projection_dynamic.py`: every clip of `../shared/data/mocap`, projected "
           "once per configuration (`ProjectionConfig`, P's plain Morph-selection mode, tau 0.5 m). Input "
           "metrics on the input grounded on the humanoid's surface, output metrics on the simulation, both on "
           "the clip's own humanoid; airborne: share of frames with no foot patch within 2 cm of the floor; "
           "feet touching: share of frame pairs with a foot joint in contact (5 mm) in both, slide per touch: "
           "Skate over those pairs (mm per 20 fps frame), so Skate = touching x slide; "
           "residual: root residual force (body weights) and torque (body weight x 1 m), mean and 95th "
           "percentile over all frames.",
           ""]
    for name, rows in results.items():
        out += [f"## {name} ({seconds[name]:.0f} s)", "", *_category_table(rows), ""]
    out += ["## Acceptance on captured runs and jumps", "",
            "| target | " + " | ".join(f"{c}, {row}" for row in ACCEPTANCE_ROWS for c in ("run", "jump")) + " |",
            "|---" * (1 + 2 * len(ACCEPTANCE_ROWS)) + "|"]
    default = results["default"]
    for target, check in TARGETS.items():
        cells = ["-" if c not in results[row] else "yes" if check(results[row][c]) else "**no**"
                 for row in ACCEPTANCE_ROWS for c in ("run", "jump")]
        out.append(f"| {target} | " + " | ".join(cells) + " |")
    base = results["tracker v0.1"]["walks+runs"]
    new = default["walks+runs"]
    out += ["", "## Walks and runs (the 203 clips of earlier figures)", "",
            "| | tracker v0.1 | default |", "|---|---|---|",
            f"| success | {100 * base['success']:.1f} % | {100 * new['success']:.1f} % |",
            f"| MPJPE mm | {base['mpjpe_mm']:.1f} | {new['mpjpe_mm']:.1f} |",
            f"| Penetrate mm | {base['penetrate_out']:.2f} | {new['penetrate_out']:.2f} |",
            f"| Skate mm | {base['skate_out']:.2f} | {new['skate_out']:.2f} |",
            f"| residual force mean / p95 (W) | {base['residual_force_mean']:.3f} / {base['residual_force_p95']:.3f} "
            f"| {new['residual_force_mean']:.3f} / {new['residual_force_p95']:.3f} |",
            f"| residual torque mean / p95 (W m) | {base['residual_torque_mean']:.3f} / "
            f"{base['residual_torque_p95']:.3f} | {new['residual_torque_mean']:.3f} / {new['residual_torque_p95']:.3f} |",
            "",
            "Residual targets (walks and runs): mean <= 0.1 W "
            f"{'met' if new['residual_force_mean'] <= 0.1 else '**not met**'}, p95 <= 0.2 W "
            f"{'met' if new['residual_force_p95'] <= 0.2 + 1e-9 else '**not met**'}.", ""]
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mocap", default="../shared/data/mocap")
    parser.add_argument("--out", default="results/projection_dynamic", help="writes OUT.md and OUT.json")
    parser.add_argument("--limit", type=int, default=0, help="only every k-th clip, N clips (a quick look)")
    args = parser.parse_args()
    clips = load_manifest(args.mocap)
    if args.limit:
        clips = clips[:: max(1, len(clips) // args.limit)][: args.limit]
    results, seconds = {}, {}
    for name, cfg in configs().items():
        start = time.perf_counter()
        results[name] = by_category(clips, measure_clips(clips, cfg))
        seconds[name] = time.perf_counter() - start
        print(f"{name}: {seconds[name]:.0f} s", flush=True)
    meta = {"clips": len(clips), "mocap": str(args.mocap), "seconds": seconds}
    text = json.dumps({"meta": meta, "configs": results}, indent=2) + "\n"
    write_atomic(Path(args.out + ".json"), lambda f: f.write(text.encode()))
    md = _markdown(results, seconds)
    write_atomic(Path(args.out + ".md"), lambda f: f.write(md.encode()))
    print(md)


if __name__ == "__main__":
    main()
