"""What P's refinement did to Morph's synthetic motions: synthetic data folders of the same model, plan
and seed (so the same generated inputs, item by item) refined by different controllers (issue 61, item 8).

Usage: python -m experiments.synth_refinement SYNTH [SYNTH ...] [--names tracker,search]
       [--out results/synth_refinement]

One row per folder (``physmotion morph synth``). Columns: items, Morph's imitation selection (refined
motions kept, IFR, episodes that fell), the refined motions' Penetrate, Float, Skate and Phys-Err on the
humanoid surface against their inputs', flight kept (median over the items whose input flies of refined
over input flight, :func:`~physmotion.metrics.dynamics.flight_ratios`), world MPJPE to the input, and
the outside help (mean root force, share of frames at a cap). The folders must hold the same items: the
comparison is paired.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from experiments._results import ROOT, heading, markdown_table, parse_args, report, run_meta, write_results


def _joints(folder: Path, sub: str, ids: list[str]) -> list[np.ndarray]:
    return [np.load(folder / sub / f"{i}.npy").astype(np.float64) for i in ids]


def _metrics(joints: list[np.ndarray]) -> dict[str, float]:
    """Penetrate, Float, Skate and Phys-Err (mm) over motions of different lengths."""
    from physmotion.metrics import ragged_physical_metrics
    from physmotion.physics.surface import HumanoidSurface

    phys = ragged_physical_metrics(joints, body=HumanoidSurface([None] * len(joints)))
    return {k: float(phys[k]) for k in ("penetrate", "float", "skate", "phys_err")}


def measure(folders: list[Path]) -> list[dict]:
    """One dict of figures per folder (module docstring). Raises ValueError for folders whose items differ."""
    from physmotion.metrics.dynamics import MIN_FLIGHT, flight_ratios
    from physmotion.morph.selection import read_index, select

    rows = []
    first: tuple[list[str], list[np.ndarray]] | None = None  # the first folder's ids and inputs
    for folder in folders:
        index = read_index(folder)
        ids = [r["id"] for r in index]
        inputs, refined = _joints(folder, "input_joints", ids), _joints(folder, "new_joints", ids)
        if first is None:
            first = (ids, inputs)
        elif ids != first[0]:
            raise ValueError(f"{folder} holds other items than {folders[0]}: the comparison is paired")
        elif any(a.shape != b.shape or not np.allclose(a, b, atol=1e-5) for a, b in zip(inputs, first[1])):
            raise ValueError(f"{folder}'s generated inputs differ from {folders[0]}'s: another model, plan or seed")
        sel = select(folder)
        ratios = flight_ratios(refined, inputs, MIN_FLIGHT)
        mpjpe = [float(np.linalg.norm(r - i, axis=-1).mean()) for r, i in zip(refined, inputs)]
        rows.append({
            "folder": str(folder), "items": len(ids), "refined": sel.counts["refined"], "ifr": sel.ifr,
            "fell": sel.counts["episode_failed"], "input": _metrics(inputs), "output": _metrics(refined),
            "flight_kept": float(np.median(ratios)) if ratios else None, "flying": len(ratios),
            "mpjpe_mm": 1000 * float(np.mean(mpjpe)),
            "residual_force": float(np.mean([float(r.get("residual_force") or 0) for r in index])),
            "residual_at_cap": float(np.mean([float(r.get("residual_at_cap") or 0) for r in index])),
        })  # fmt: skip
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("synth", nargs="+", type=Path, help="synthetic data folders (morph synth) of the same plan")
    parser.add_argument("--names", default=None, help="what the table calls the folders, comma-separated")
    parser.add_argument("--out", default=str(ROOT / "results" / "synth_refinement"))
    args = parse_args(parser, argv)

    def run() -> tuple[str, list[Path]]:
        names = args.names.split(",") if args.names else [str(f) for f in args.synth]
        if len(names) != len(args.synth):
            raise ValueError(f"--names gives {len(names)} names for {len(args.synth)} folders")
        rows = measure(list(args.synth))
        for row, name in zip(rows, names):
            row["name"] = name
        meta = run_meta(__file__, argv, args.tree, None, folders=dict(zip(names, map(str, args.synth))))
        header = ["refined by", "items", "refined kept (IFR)", "fell", "Penetrate in/out mm", "Float in/out mm",
                  "Skate in/out mm", "Phys-Err in/out mm", "flight kept (median, flying inputs)",
                  "MPJPE to input mm", "root force mean, W", "frames at a cap"]  # fmt: skip
        body = []
        for r in rows:
            i, o = r["input"], r["output"]
            body.append([r["name"], r["items"], f"{r['refined']} ({r['ifr']:.3f})", r["fell"],
                         *(f"{i[k]:.1f} / {o[k]:.1f}" for k in ("penetrate", "float", "skate", "phys_err")),
                         "-" if r["flight_kept"] is None else f"{r['flight_kept']:.2f} ({r['flying']})",
                         f"{r['mpjpe_mm']:.0f}", f"{r['residual_force']:.3f}",
                         f"{100 * r['residual_at_cap']:.0f} %"])  # fmt: skip
        table = heading("Morph's synthetic motions, refined by each controller", meta) + markdown_table(header, body)
        return table, write_results(args.out, table, {"meta": meta, "rows": rows})

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
