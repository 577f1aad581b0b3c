"""``physmotion project``: the physics projection P over motion files (physmotion.physics)."""

from __future__ import annotations

from pathlib import Path

import typer

from physmotion.cli._common import (
    CONTROLLER_HELP,
    OVERWRITE_HELP,
    POLICY_HELP,
    PREVIEW_HELP,
    _as_options,
    _check_out,
    _check_preview,
    _opt_str,
    _step_bar,
    app,
    console,
)
from physmotion.errors import PhysmotionError
from physmotion.paths import MOTION_SUFFIXES

EFFORT_HELP = ("With --controller search: 'fast', 'default' or 'best' (more candidates, a longer lookahead; "
               "costs in results/search_quality.md).")


@app.command("project")
def project_motion(
    paths: list[Path] = typer.Argument(..., help="Motion .npz files (joints at any fps)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .npz with the projected motion (or .bvh: the motion "
                             "alone, without the simulation's records, as `export` writes), with its GIF "
                             "preview beside it (<stem>.gif); with several inputs, a folder that receives "
                             "<stem>.npz and <stem>.gif per input (those already there are skipped, so an "
                             "interrupted run resumes)."),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    preview: bool = typer.Option(True, help=PREVIEW_HELP),
    ilc: int = typer.Option(0, "--ilc", help="Iterative learning control: simulate this many more times, "
                            "each time with the root's error of the last fed forward into the reference, and "
                            "keep the simulation closest to the input (0: off; 2: captured runs 50 -> 43 mm "
                            "and Float 15.0 -> 12.5 mm, for 3x the time; results/projection_dynamic.md)."),
    fine_step: bool = typer.Option(False, "--fine-step", help="Simulate at 1/720 s instead of 1/360 s: "
                                   "fast motion lands and pushes off better (captured runs' Float 15.0 -> "
                                   "9.7 mm), for twice the simulation steps; results/projection_dynamic.md."),
    controller: str = typer.Option("tracker", help=CONTROLLER_HELP),
    policy: Path | None = typer.Option(None, help=POLICY_HELP),
    effort: str = typer.Option("default", help=EFFORT_HELP),
    seed: int = typer.Option(0, help="With --controller search: the seed of its random candidates."),
    teacher: bool = typer.Option(False, "--teacher", help="With --controller search: also write the search's "
                                 "teacher records beside each output, <stem>.teacher.npz (per control step, the "
                                 "observation a policy sees and the joint-target offsets chosen)."),
    workers: int = typer.Option(0, help="With several inputs: local worker processes, one motion each "
                                "(0: one per core)."),
    ray: str | None = typer.Option(None, help="With several inputs: run one Ray task per motion instead of "
                                   "local processes, on the Ray cluster at this address, or 'local' to start "
                                   "one on this machine (needs pip install 'physmotion[ray]'; docs/cluster.md)."),
    preset_name: str = typer.Option("plain", "--preset", help="P's preset by name (physmotion/physics/presets.py; "
                                    "docs/cli.md lists them): 'plain' keeps the input where the imitation fails, "
                                    "'sampling' is generation's P; --ilc and --fine-step apply on top."),
) -> None:
    """Physics projection (PhysDiff's P): imitate the motion with the simulated humanoid."""
    from dataclasses import replace

    from physmotion.physics.files import project_file, project_files, teacher_path
    from physmotion.physics.presets import preset
    from physmotion.physics.search import effort as search_effort
    from physmotion.render import preview_path

    if teacher and controller != "search":
        raise PhysmotionError("--teacher needs --controller search: only the search makes teacher records")
    search = search_effort(effort, seed) if controller == "search" else None
    with _as_options(ilc_passes="--ilc", controller="--controller"):
        config = preset(preset_name).with_controller(controller, _opt_str(policy), search)
        config = replace(config, ilc_passes=ilc) if ilc else config
    config = config.at_fine_step() if fine_step else config
    if len(paths) == 1 and ray is None:
        _check_out(out, overwrite, MOTION_SUFFIXES)  # written by suffix, as `export` writes
        if teacher:
            _check_out(teacher_path(out), overwrite)
        _check_preview(out, overwrite)
        with _step_bar(f"projecting {paths[0].name} ({controller}), control steps") as tick:
            result = project_file(paths[0], out, config, teacher, on_step=tick, preview=preview)
        shown = f" and its preview {preview_path(out)}" if preview else ""
        console.print(f"wrote {out}{shown} ({controller}): {result.summary}", highlight=False)
        return
    missing = [p for p in paths if not p.is_file()]
    if missing:
        raise PhysmotionError(f"{missing[0]}: no such file")
    if out.exists() and not out.is_dir():
        raise PhysmotionError(f"{out} is a file: with several inputs, -o names a folder")
    from physmotion.paths import check_output

    check_output(out, "folder", overwrite=True)  # its files are checked one by one: an earlier run resumes
    if overwrite:  # re-project everything: the outputs of an earlier run are not skipped
        from physmotion.physics.files import outputs_for

        for o in outputs_for(paths, out):
            for f in (o, teacher_path(o), preview_path(o)):
                f.unlink(missing_ok=True)
    with _step_bar(f"projecting {len(paths)} motions ({controller})") as tick:
        done = []

        def report(r) -> None:
            done.append(r)
            tick(len(done), len(paths))
            console.print(f"{r.source.name} -> {r.out}: {r.summary}", highlight=False)

        results = project_files(paths, out, config, teacher, workers=workers, ray=ray, on_done=report,
                                preview=preview)
    kept = sum(r.selected for r in results if not r.skipped)
    skipped = sum(r.skipped for r in results)
    console.print(f"wrote {len(results) - skipped} motions to {out} ({controller}): {kept} simulations kept"
                  + (f"; {skipped} already there, skipped" if skipped else ""), highlight=False)
