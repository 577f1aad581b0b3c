"""``physmotion data``: build and inspect HumanML3D-layout datasets (physmotion.data)."""

from __future__ import annotations

import sys
from pathlib import Path

import typer
from rich.markup import escape
from rich.table import Table

from physmotion.cli._common import HELP, OVERWRITE_HELP, _warn, app, console

data_app = typer.Typer(help="Build and inspect HumanML3D-layout datasets.", no_args_is_help=True,
                       context_settings=HELP)  # fmt: skip
app.add_typer(data_app, name="data")


@data_app.command("build")
def data_build(
    source: list[Path] = typer.Option(..., help="Mocap folder with manifest.csv (e.g. ../shared/data/mocap); "
                                      "repeat it to build several into one dataset (their manifests in the same "
                                      "columns, clip ids unique)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output folder (HumanML3D layout). An earlier build "
                             "there is replaced only with --overwrite."),
    exclude_license: list[str] = typer.Option([], "--exclude-license", help="Leave out clips with this licence tag, e.g. NC."),
    seed: int = typer.Option(0, help="Salt of the take -> split assignment."),
    mirror: bool = typer.Option(True, help="Add left/right mirrored copies, as HumanML3D does."),
    pad_short: bool = typer.Option(True, help="Hold a clip shorter than 2 s still at both ends up to 2 s "
                                   "(HumanML3D's shortest motion) instead of skipping it; --no-pad-short skips "
                                   "them, as the shipped models' data was built."),
    jobs: int = typer.Option(0, help="Worker processes (0: one per core)."),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    activations: bool = typer.Option(False, "--activations", help="Also cache muscle-activation stand-ins "
                                     "(inverse-dynamics joint effort, 8 channels) in activations/."),
    features: int = typer.Option(263, help="263 (HumanML3D) or 329 (BioMoDiffuse: + joint accelerations; "
                                 "what `train denoiser --arch biomo` needs, with --activations)."),
) -> None:
    """Import every clip of one or more mocap collections into a HumanML3D-layout dataset."""
    from physmotion.data.build import BuildConfig, build_dataset
    from physmotion.paths import check_output

    check_output(out, "folder", overwrite=overwrite)
    config = BuildConfig(exclude_licences=tuple(exclude_license), seed=seed, mirror=mirror, jobs=jobs,
                         features=features, pad_short=pad_short)
    report = build_dataset(source, out, config, progress=sys.stderr.isatty())
    for clip, reason in sorted(report.skipped.items()):
        console.print(f"[yellow]skipped[/] {escape(clip)}: {escape(reason)}", markup=True)
    items = ", ".join(f"{k} {v}" for k, v in report.num_items.items())
    console.print(
        f"built {out}: {report.num_clips - len(report.skipped)}/{report.num_clips} clips, "
        f"{report.minutes:.1f} min of capture ({report.minutes_with_mirrors:.1f} min with mirrored copies); "
        f"items: {items}",
        highlight=False,
    )
    for name, src in report.sources.items():
        licences = "; ".join(f"{tag or 'open'} ({', '.join(names)})" for tag, names in src.licences.items())
        console.print(f"  {name}: {src.built}/{src.clips} clips, {src.minutes:.1f} min; {licences}",
                      highlight=False)  # fmt: skip
    latin1 = {name: src.latin1 for name, src in report.sources.items() if src.latin1}
    if latin1:
        _warn(f"{sum(latin1.values())} clips' files are not UTF-8 and were read as Latin-1 ("
              + ", ".join(f"{name} {n}" for name, n in latin1.items()) + ")")
    if activations:
        data_activations(out, jobs)


@data_app.command("activations")
def data_activations(
    root: Path = typer.Argument(..., help="A folder written by `physmotion data build`."),
    jobs: int = typer.Option(0, help="Worker processes (0: one per core)."),
) -> None:
    """Cache muscle-activation stand-ins (T, 8) per motion in ROOT/activations (replaces an earlier cache)."""
    from physmotion.data.build import build_activations

    n = build_activations(root, progress=sys.stderr.isatty(), jobs=jobs)
    console.print(f"activations for {n} motions in {root / 'activations'}", highlight=False)


@data_app.command("stats")
def data_stats(root: Path = typer.Argument(..., help="A HumanML3D-layout folder.")) -> None:
    """Print counts, minutes and the caption vocabulary of a dataset."""
    from physmotion.data.stats import dataset_stats

    stats = dataset_stats(root)
    table = Table(title=f"dataset {root}")
    table.add_column("split")
    table.add_column("motions", justify="right")
    table.add_column("minutes*", justify="right")
    for split, n in stats.items.items():
        table.add_row(split, str(n), f"{stats.minutes[split]:.1f}")
    table.add_row("all", str(sum(stats.items.values())), f"{stats.total_minutes:.1f}")
    console.print(table)
    console.print("* minutes count every motion listed, mirrored copies (ids starting with M) included",
                  highlight=False)
    if stats.licences:
        console.print("licences: " + ", ".join(f"{k} {v}" for k, v in stats.licences.items()))
    top = ", ".join(f"{w} {c}" for w, c in stats.vocabulary.most_common(30))
    console.print(f"captions: {stats.captions}; vocabulary: {len(stats.vocabulary)} words; most common: {top}")
