"""``physmotion render`` and ``view``: pictures, videos and a 3-D page of motions (physmotion.render,
physmotion.viewer)."""

from __future__ import annotations

from pathlib import Path

import typer

from physmotion.cli._common import (
    BVH_FPS_HELP,
    BVH_MAPPING_HELP,
    BVH_RIG_HELP,
    OVERWRITE_HELP,
    _check_out,
    app,
    console,
)

@app.command("render")
def render_cmd(
    paths: list[Path] = typer.Argument(..., help="Motion files: .npz, or .bvh (imported on the fly)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .gif or .mp4 (mp4 needs the 'video' extra), "
                             "or .png with --frame."),
    layout: str = typer.Option("side", help="side (one panel per motion) or overlay (one panel, a colour "
                               "per motion, with a legend)."),
    frame: int | None = typer.Option(None, help="Write only this frame (0-based, at the common rate) as a .png."),
    size: int = typer.Option(480, help="Pixels per panel (square)."),
    rig: str | None = typer.Option(None, help=BVH_RIG_HELP),
    fps: float | None = typer.Option(None, help=BVH_FPS_HELP),
    mapping: Path | None = typer.Option(None, help=BVH_MAPPING_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Draw motions side by side or overlaid: floor grid with a 1 m bar, frame/time counter, foot contacts.

    Motions at different rates are resampled to the highest; a shorter motion holds its last frame."""
    from physmotion.render import render_files

    _check_out(out, overwrite)
    done = render_files(paths, out, layout=layout, size=size, frame=frame, rig=rig, fps=fps,  # type: ignore[arg-type]
                        mapping=mapping)
    console.print(f"wrote {out}: {done.frames} frame(s) at {done.fps:g} fps, {done.width}x{done.height} px",
                  highlight=False)


@app.command("view")
def view_cmd(
    paths: list[Path] = typer.Argument(..., help="Motion files: .npz, or .bvh (imported on the fly)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .html: one self-contained page, no network."),
    rig: str | None = typer.Option(None, help=BVH_RIG_HELP),
    fps: float | None = typer.Option(None, help=BVH_FPS_HELP),
    mapping: Path | None = typer.Option(None, help=BVH_MAPPING_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Write a 3-D viewer page (WebGL): orbit camera, play/pause, scrub slider, foot contacts, floor grid."""
    from physmotion.viewer import view_files

    _check_out(out, overwrite)
    done = view_files(paths, out, rig=rig, fps=fps, mapping=mapping)
    console.print(f"wrote {out}: {done.frames} frames at {done.fps:g} fps, {done.bytes / 1e6:.1f} MB; "
                  "open it in a browser", highlight=False)  # fmt: skip
