"""``physmotion import`` and ``export``: mocap files in, motions out (physmotion.io)."""

from __future__ import annotations

from pathlib import Path

import typer

from physmotion.cli._common import OVERWRITE_HELP, PREVIEW_HELP, _check_out, _check_preview, app, console
from physmotion.errors import PhysmotionError
from physmotion.paths import MOTION_SUFFIXES

# The rig tables' names for `import --rig`'s help (physmotion.io.rigs.RIGS, which imports scipy: not
# imported for --help; tests/test_cli_cold.py checks the two agree).
RIG_NAMES = ("bandai", "cmu_bvh_cgspeed_max", "cmu_bvh_cgspeed_max_scaled_m", "cmu_asf", "cmu_iclone_cc_base",
             "mixamo", "mixamo_plain", "smpl22")  # fmt: skip


@app.command("import")
def import_motion(
    path: Path | None = typer.Argument(None, help="A .bvh or .amc file (an .amc needs --asf)."),
    out: Path | None = typer.Option(None, "-o", "--out", help="Output .npz (or .bvh), with a GIF preview "
                                    "beside it (<stem>.gif)."),
    rig: str | None = typer.Option(
        None, help=f"Rig table: {', '.join(RIG_NAMES)}; guessed if left out. '--rig list' describes them."
    ),
    mapping: Path | None = typer.Option(
        None, help="JSON file naming the file's joint for each of our 22 joints, plus optional units, "
        "up_axis and fps, for a rig without a table (docs/examples/mapping_bandai.json); an End Site is "
        "named '<parent>_end'. Flags override it."),
    asf: Path | None = typer.Option(None, help="The skeleton (.asf) of an .amc file."),
    fps: float | None = typer.Option(None, help="True frame rate, where the header is wrong or absent."),
    up_axis: str | None = typer.Option(None, help="Y or Z, overriding the rig's or mapping's."),
    units: str | None = typer.Option(None, help="cm, m, inch or a factor to metres, overriding the rig's or mapping's."),
    preview: bool = typer.Option(True, help=PREVIEW_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Import one mocap file to the 22-joint skeleton at 20 fps, Y up, facing +Z, its stance soles on the
    floor (y = 0; a tilted capture floor is levelled first, and the summary says so)."""
    from physmotion.io.rigs import RIGS, describe_rig

    if rig == "list":
        for name, table in RIGS.items():
            console.print(f"{name}: {describe_rig(table)}", highlight=False)
        return
    if path is None or out is None:
        raise PhysmotionError("import needs a FILE and -o OUT (or --rig list to see the rig tables)")
    _check_out(out, overwrite, MOTION_SUFFIXES)
    _check_preview(out, overwrite)
    from physmotion.io.importer import import_clip_with_report
    from physmotion.render import save_with_preview

    motion, report = import_clip_with_report(
        path, rig=rig, mapping=mapping, asf=asf, fps=fps, up_axis=up_axis, units=units
    )
    files = save_with_preview(motion, out, preview, title=path.name)
    tilt = report.grounding.tilt
    levelled = f"; its capture floor, tilted {tilt:.1f} degrees, levelled" if tilt else ""
    console.print(f"wrote {' and '.join(map(str, files))}: {motion.num_frames} frames, {motion.seconds:.1f} s"
                  f"{levelled}", highlight=False)  # fmt: skip


@app.command("export")
def export_motion(
    path: Path = typer.Argument(..., help="A motion .npz."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .bvh, .glb (glTF 2.0 with a skinned body) or .npz."),
    rig_from: Path | None = typer.Option(
        None, "--rig-from", help="A BVH file of your character's skeleton: the output .bvh has its hierarchy, "
        "offsets and rest pose, the motion retargeted onto it (stance feet held)."),
    rig: str | None = typer.Option(None, help=f"With --rig-from: its rig table ({', '.join(RIG_NAMES)}); "
                                   "guessed if left out."),
    mapping: Path | None = typer.Option(None, help="With --rig-from: a mapping JSON as `import` takes it."),
    units: str | None = typer.Option(None, help="With --rig-from: the file's units (cm, m, inch or metres "
                                     "per unit), overriding the rig's or mapping's."),
    in_place: bool = typer.Option(False, "--in-place", help="Remove the root's horizontal travel (heading "
                                  "and height kept)."),
    loop: bool = typer.Option(False, "--loop", help="Trim to the frames whose first and last poses are "
                              "closest (searched in the first and last 30 %); prints the pose distance."),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Write a motion to BVH (metres, Y up, the 22-joint rig, or your skeleton with --rig-from), glTF binary
    (.glb: the rig, a skinned capsule body and the animation) or .npz."""
    from physmotion.io.export import export_file

    _check_out(out, overwrite, MOTION_SUFFIXES)
    for line in export_file(path, out, rig_from=rig_from, rig=rig, mapping=mapping, units=units, in_place=in_place,
                            loop=loop):  # fmt: skip
        console.print(line, highlight=False)
