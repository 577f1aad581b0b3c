"""Print the README's results table from a committed results file (default: results/evaluate_default.json).

    python docs/make_readme_table.py [results/evaluate_default.json]

The README holds this script's output verbatim; tests/test_results.py fails when the two differ, so a
re-run of `physmotion evaluate -o results/evaluate_default` is followed by pasting the new table.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "results" / "evaluate_default.json"

# Each row of the file, in plain words: (row key, what the motion is).
ROWS = (
    ("real", "captured motion (the test split itself)"),
    ("none", "generated, no physics (`none`)"),
    ("none+floor", "generated, then moved up or down onto the floor (`none+floor`)"),
    ("post:1", "generated, then one simulation (`post:1`)"),
    ("post:4", "generated, then four simulations (`post:4`)"),
    ("physdiff:end:2,space:1,fly:last",
     "**PhysDiff: simulations inside generation (`physdiff`, the last 2 steps; a motion that flies, the last)**"),
)


def _cell(row: dict, key: str, fmt: str) -> str:
    return f"{row[key]['mean']:{fmt}}"


def table(path: Path = DEFAULT) -> str:
    """The markdown table of one `physmotion evaluate` results file."""
    result = json.loads(Path(path).read_text())
    rows = result["rows"]
    lines = [
        "| motion | physical error, mm | sinking / floating / sliding, mm | flight kept | realism: FID "
        "| matches its text: R@3 | outputs with a reset (projections that fell) "
        "| outside help on the pelvis: force, W (p95) / torque, W m (p95); frames held at a cap |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for key, words in ROWS:
        row = rows[key]
        resets = "-"
        if "reset_rate" in row:
            fell = f" ({100 * row['fell']['mean']:.0f} %)" if "fell" in row else ""
            resets = f"{100 * row['reset_rate']['mean']:.0f} %{fell}"
        flight = _cell(row, "flight_kept", ".2f") if "flight_kept" in row else "-"
        helped = "-"  # the root residual P applied; the tables made before it was measured lack it
        if "residual_force" in row:
            at_cap = f"; {100 * row['residual_at_cap']['mean']:.0f} %" if "residual_at_cap" in row else ""
            helped = (f"{_cell(row, 'residual_force', '.2f')} ({_cell(row, 'residual_force_p95', '.2f')}) / "
                      f"{_cell(row, 'residual_torque', '.2f')} ({_cell(row, 'residual_torque_p95', '.2f')}){at_cap}")
        parts = " / ".join(_cell(row, k, ".1f") for k in ("penetrate", "float", "skate"))
        cells = (_cell(row, "phys_err", ".1f"), parts, flight, _cell(row, "FID", ".3f"), _cell(row, "R@3", ".2f"),
                 resets, helped)
        lines.append(f"| {words} | " + " | ".join(cells) + " |")
    meta = result["meta"]
    lines.append("")
    sampler = meta["sampler"]
    name = {"dpmpp": "DPM-Solver++", "ddim": "DDIM"}.get(sampler["sampler"], sampler["sampler"])
    lines.append(f"{meta['motions']} test motions ({meta['data']}) x {meta['repeats']} repeats, the default model "
                 f"(Morph-tuned) and the shipped evaluator, sampled with {name} {sampler['steps']} steps, "
                 f"`{Path(path).relative_to(ROOT).as_posix()}`; the base model it was tuned from is beside it in "
                 "`results/morph_retuned.md`.")
    return "\n".join(lines)


if __name__ == "__main__":
    print(table(Path(sys.argv[1]).resolve() if len(sys.argv) > 1 else DEFAULT))
