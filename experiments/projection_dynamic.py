"""The physics projection on every captured clip, by category of motion, for the baseline tracker and for
each change made for dynamic motion: writes results/projection_dynamic.md and .json.

Usage: python -m experiments.projection_dynamic [--mocap ../shared/data/mocap] [--out results/projection_dynamic]
       [--limit N]
Rows, each one of P's presets (physmotion/physics/presets.py; :data:`ROWS` maps a row's label to its preset):
"tracker v0.1" (``tracker_v01``: the model-based tracker as it was: no toe-off flattening, the root
residual carries the whole root wrench, bounded at 0.3 W and held over 4 simulation steps), "+ toe-off",
"+ feet balance", "toe-off + feet balance" (both, with the residual above), "+ ballistic flight"
(``plain_held_residual``: that, with flight phases made ballistic), and "default" (``plain``: all of it,
the residual bounded at 0.2 W and held over 2 steps, the feet's fit weighting torque 0.3), and "default +
ILC" (``ilc``: iterative learning control, the option of ``physmotion project --ilc``, three simulations
per clip), and "default at 1/720 s" (``fine``, the option of ``physmotion project --fine-step``: half the
simulation step, twice the steps).
Categories from the captions (experiments.projection_quality.category). Input metrics are measured on
the input grounded on the humanoid's surface (the metrics' floor convention), output metrics on the
simulation; airborne: share of frames with no foot patch within 2 cm of the floor.
"""

from __future__ import annotations

import argparse
import time

from experiments._results import parse_args, run_meta, write_results
from experiments.projection_quality import by_category, category_table, measure_clips, spread
from physmotion.io.importer import load_manifest
from physmotion.physics.presets import preset

ROWS = {  # a row's label -> P's preset
    "tracker v0.1": "tracker_v01",
    "+ toe-off": "tracker_v01_toe_off",
    "+ feet balance": "tracker_v01_feet_balance",
    "toe-off + feet balance": "tracker_v01_toe_off_feet_balance",
    "+ ballistic flight": "plain_held_residual",
    "default": "plain",
    "default + ILC": "ilc",
    "default at 1/720 s": "fine",
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


def _markdown(results: dict[str, dict[str, dict[str, float]]], seconds: dict[str, float]) -> str:
    out = ["# Physics projection on captured motion, by category",
           "",
           "Written by `python -m experiments.projection_dynamic`: every clip of `../shared/data/mocap`, "
           "projected once per preset of P (its plain Morph-selection mode, tau 0.5 m). Input "
           "metrics on the input grounded on the humanoid's surface, output metrics on the simulation, both on "
           "the clip's own humanoid; airborne: share of frames with no foot patch within 2 cm of the floor; "
           "feet touching: share of frame pairs with a foot joint in contact (5 mm) in both, slide per touch: "
           "Skate over those pairs (mm per 20 fps frame), so Skate = touching x slide; "
           "residual: root residual force (body weights) and torque (body weight x 1 m), mean and 95th "
           "percentile over all frames, and the share of frames at the force's cap; torque over limit: the share "
           "of frames with a joint's torque over its actuator's limit.",
           ""]
    for name, rows in results.items():
        out += [f"## {name} (preset `{ROWS[name]}`, {seconds[name]:.0f} s)", "", category_table(rows), ""]
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


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mocap", default="../shared/data/mocap")
    parser.add_argument("--out", default="results/projection_dynamic", help="writes OUT.md and OUT.json")
    parser.add_argument("--limit", type=int, default=0, help="only every k-th clip, N clips (a quick look)")
    args = parse_args(parser, argv)
    clips = spread(load_manifest(args.mocap), args.limit)
    results, seconds = {}, {}
    for name, preset_name in ROWS.items():
        start = time.perf_counter()
        config = preset(preset_name)
        results[name] = by_category(clips, measure_clips(clips, config), config.residual_bound())
        seconds[name] = time.perf_counter() - start
        print(f"{name}: {seconds[name]:.0f} s", flush=True)
    meta = run_meta(__file__, argv, args.tree, dict(ROWS), clips=len(clips), mocap=str(args.mocap),
                    seconds=seconds)
    md = _markdown(results, seconds)
    write_results(args.out, md, {"meta": meta, "configs": results})
    print(md)


if __name__ == "__main__":
    main()
