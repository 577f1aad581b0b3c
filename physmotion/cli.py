"""The ``physmotion`` command line: thin commands over the library's public functions.

Any :class:`~physmotion.errors.PhysmotionError` becomes one line on stderr and exit code 1.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.table import Table

from physmotion.errors import PhysmotionError

app = typer.Typer(
    help="Text-to-motion generation that obeys physics.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
data_app = typer.Typer(help="Build and inspect HumanML3D-layout datasets.", no_args_is_help=True)
app.add_typer(data_app, name="data")
console = Console(soft_wrap=True)


@data_app.command("build")
def data_build(
    source: Path = typer.Option(..., help="Mocap folder with manifest.csv (e.g. ../shared/data/mocap)."),
    out: Path = typer.Option(..., help="Output folder (HumanML3D layout)."),
    exclude_license: list[str] = typer.Option([], "--exclude-license", help="Leave out clips with this licence tag, e.g. NC."),
    seed: int = typer.Option(0, help="Salt of the take -> split assignment."),
    mirror: bool = typer.Option(True, help="Add left/right mirrored copies, as HumanML3D does."),
    jobs: int = typer.Option(0, help="Worker processes (0: one per core)."),
) -> None:
    """Import every clip of a mocap collection into a HumanML3D-layout dataset."""
    from physmotion.data.build import BuildConfig, build_dataset

    config = BuildConfig(exclude_licences=tuple(exclude_license), seed=seed, mirror=mirror, jobs=jobs)
    report = build_dataset(source, out, config, progress=sys.stderr.isatty())
    for clip, reason in sorted(report.skipped.items()):
        console.print(f"[yellow]skipped[/] {clip}: {reason}", highlight=False)
    items = ", ".join(f"{k} {v}" for k, v in report.num_items.items())
    console.print(
        f"built {out}: {report.num_clips - len(report.skipped)}/{report.num_clips} clips, "
        f"{report.minutes:.1f} min of motion; items: {items}",
        highlight=False,
    )


@data_app.command("stats")
def data_stats(root: Path = typer.Argument(..., help="A HumanML3D-layout folder.")) -> None:
    """Print counts, minutes and the caption vocabulary of a dataset."""
    from physmotion.data.stats import dataset_stats

    stats = dataset_stats(root)
    table = Table(title=f"dataset {root}")
    table.add_column("split")
    table.add_column("motions", justify="right")
    table.add_column("minutes", justify="right")
    for split, n in stats.items.items():
        table.add_row(split, str(n), f"{stats.minutes[split]:.1f}")
    table.add_row("all", str(sum(stats.items.values())), f"{stats.total_minutes:.1f}")
    console.print(table)
    if stats.licences:
        console.print("licences: " + ", ".join(f"{k} {v}" for k, v in stats.licences.items()))
    top = ", ".join(f"{w} {c}" for w, c in stats.vocabulary.most_common(30))
    console.print(f"captions: {stats.captions}; vocabulary: {len(stats.vocabulary)} words; most common: {top}")


@app.command("import")
def import_motion(
    path: Path = typer.Argument(..., help="A .bvh or .amc file (an .amc needs --asf)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .npz (or .bvh)."),
    rig: Optional[str] = typer.Option(None, help="Rig table name (see physmotion.io.rigs); guessed if left out."),
    asf: Optional[Path] = typer.Option(None, help="The skeleton (.asf) of an .amc file."),
    fps: Optional[float] = typer.Option(None, help="True frame rate, where the header is wrong or absent."),
    up_axis: Optional[str] = typer.Option(None, help="Y or Z, overriding the rig's."),
    units: Optional[str] = typer.Option(None, help="cm, m, inch or a factor to metres, overriding the rig's."),
) -> None:
    """Import one mocap file to the 22-joint skeleton at 20 fps, Y up, floor at 0, facing +Z."""
    from physmotion.io.export import save_motion
    from physmotion.io.importer import import_clip

    motion = import_clip(path, rig=rig, asf=asf, fps=fps, up_axis=up_axis, units=units)
    save_motion(motion, out)
    console.print(f"wrote {out}: {motion.num_frames} frames, {motion.seconds:.1f} s", highlight=False)


@app.command("export")
def export_motion(
    path: Path = typer.Argument(..., help="A motion .npz."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .bvh or .npz."),
) -> None:
    """Write a motion to BVH (metres, Y up, the 22-joint rig) or .npz."""
    from physmotion.io.export import save_motion
    from physmotion.motion import Motion

    save_motion(Motion.load(path), out)
    console.print(f"wrote {out}", highlight=False)


@app.command("project")
def project_motion(
    path: Path = typer.Argument(..., help="A motion .npz (joints at any fps)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .npz with the projected motion."),
) -> None:
    """Physics projection (PhysDiff's P): imitate the motion with the simulated humanoid."""
    from dataclasses import replace

    from physmotion.motion import Motion
    from physmotion.physics.projection import project

    motion = Motion.load(path)
    result = project(motion.joints, motion.fps)
    replace(motion, joints=result.joints, rotations=None, offsets=None).save(out)
    kept = "simulation kept" if result.selected else "tracking failed: input kept (flagged)"
    console.print(
        f"wrote {out}: {kept}; MPJPE mean {1000 * result.mpjpe.mean():.0f} mm, "
        f"root residual mean {result.residual_force.mean():.2f} W",
        highlight=False,
    )


@app.command("metrics")
def metrics(
    paths: list[Path] = typer.Argument(..., help="Motion .npz files (joints, fps)."),
    surface: str = typer.Option(
        "humanoid", help="Body surface for Penetrate/Float/Skate: 'humanoid' (MuJoCo geometry posed on "
        "the joints) or 'joints' (a light model built from the joints alone)."),
) -> None:
    """Print the physical metrics (PhysDiff, EDGE/Morph, BioMoDiffuse) of one or more motions."""
    from physmotion.metrics import format_table, physical_metrics
    from physmotion.motion import Motion

    if surface not in ("humanoid", "joints"):
        raise PhysmotionError(f"--surface must be 'humanoid' or 'joints', got {surface!r}")
    results = {}
    for path in paths:
        motion = Motion.load(path)
        body = None
        if surface == "humanoid":
            from physmotion.physics.surface import HumanoidSurface

            body = HumanoidSurface()
        results[path.name] = physical_metrics(motion.joints, fps=motion.fps, body=body)
    console.print(format_table(results, title=f"physical metrics ({surface} surface)"))


def main() -> None:
    """Entry point of the console script: user errors become one line, never a traceback."""
    try:
        app()
    except PhysmotionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(1) from None
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        raise SystemExit(130) from None


if __name__ == "__main__":
    main()
