"""``physmotion metrics``: the physical metrics of motion files (physmotion.metrics)."""

from __future__ import annotations

import sys
from pathlib import Path

import typer
from rich.console import Console

from physmotion.cli._common import (
    BVH_FPS_HELP,
    BVH_MAPPING_HELP,
    BVH_RIG_HELP,
    OVERWRITE_HELP,
    _check_out,
    app,
    console,
)
from physmotion.errors import PhysmotionError

@app.command("metrics")
def metrics(
    paths: list[Path] = typer.Argument(
        ..., help="Motion files: .npz (joints, fps), or .bvh (imported on the fly, as render does)."),
    surface: str = typer.Option(
        "humanoid", help="Body surface for Penetrate/Float/Skate: 'humanoid' (MuJoCo geometry posed on "
        "the joints: the simulated body where the file carries it, as generate writes for projected "
        "motions) or 'joints' (a light model built from the joints alone)."),
    as_json: bool = typer.Option(False, "--json", help="JSON instead of the table: units and, per file, "
                                 "its label, path and metrics."),
    as_csv: bool = typer.Option(False, "--csv", help="CSV instead of the table: one row per file (label, "
                                "path, one column per metric)."),
    out: Path | None = typer.Option(
        None, "-o", "--out", help="Write the JSON or CSV to this file (atomically) instead of stdout; its "
        "suffix (.json, .csv) picks the format if neither flag is given."),
    rig: str | None = typer.Option(None, help=BVH_RIG_HELP),
    fps: float | None = typer.Option(None, help=BVH_FPS_HELP),
    mapping: Path | None = typer.Option(None, help=BVH_MAPPING_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Print the physical metrics (PhysDiff, EDGE/Morph, BioMoDiffuse) of one or more motions.

    One column per file, labelled by the shortest end of its path that tells it from the others
    (a/x.npz and b/x.npz stay apart). Where the table is wider than the terminal the columns are
    numbered and a legend names the files."""
    from physmotion.metrics import physical_metrics
    from physmotion.metrics.report import (fit_table, path_labels, residual_summary, table_width, to_csv,
                                           to_json)
    from physmotion.motion import write_atomic

    if surface not in ("humanoid", "joints"):
        raise PhysmotionError(f"--surface must be 'humanoid' or 'joints', got {surface!r}")
    if as_json and as_csv:
        raise PhysmotionError("give --json or --csv, not both")
    fmt = "json" if as_json else "csv" if as_csv else None
    if out is not None:
        fmt = fmt or {".json": "json", ".csv": "csv"}.get(out.suffix.lower())
        if fmt is None:
            raise PhysmotionError(f"{out}: give --json or --csv (or an -o ending in .json or .csv)")
        _check_out(out, overwrite)
    from physmotion.render import load_motion

    for path in paths:  # every file checked before any work
        if path.suffix.lower() not in (".npz", ".bvh"):
            raise PhysmotionError(f"{path}: metrics reads .npz or .bvh; run `physmotion import` on other formats")
        if not path.is_file():
            raise PhysmotionError(f"{path}: no such file")
    results = {}
    for path, label in zip(paths, path_labels(paths)):
        motion = load_motion(path, rig=rig, fps=fps, mapping=mapping)  # an .npz as saved, a .bvh imported
        body = None
        if surface == "humanoid":
            from physmotion.physics.surface import HumanoidSurface

            body = HumanoidSurface(motion.humanoid)  # P's body where the file has it, else estimated
        results[label] = physical_metrics(motion.joints, fps=motion.fps, body=body) | residual_summary(motion)
    if fmt is None:
        table, legend = fit_table(results, f"physical metrics ({surface} surface)", console.width)
        # A table that still does not fit prints whole (wider than the terminal) rather than with cut cells.
        Console(width=max(console.width, table_width(table)), emoji=False, markup=False).print(table)
        for line in legend:
            console.print(line, highlight=False, markup=False)
        return
    text = to_json(results, paths, surface) if fmt == "json" else to_csv(results, paths)
    if out is None:
        sys.stdout.write(text)
    else:
        data = text.encode("utf-8")
        write_atomic(out, lambda f: f.write(data))
        console.print(f"wrote {out}", highlight=False)
