"""What every command of the ``physmotion`` command line shares: the typer app, the console, the help
texts several commands quote, and the checks and helpers the commands call before and around the work."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import typer
from rich.console import Console

from physmotion.errors import PhysmotionError
from physmotion.paths import DEFAULT_MODEL, WEIGHTS_DIR

HELP = {"help_option_names": ["-h", "--help"]}  # -h everywhere, on the app and every sub-app

app = typer.Typer(
    help="Text-to-motion generation that obeys physics.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,  # help is plain text: "physdiff:end:4" must not become an emoji
    context_settings=HELP,
)
# User text (captions, paths, physics modes) goes into these lines: rich must neither turn ":end:" or
# ":fire:" into emoji nor read "[...]" as markup (rich docs, Console: emoji=, markup=). A line that wants
# markup asks for it (markup=True) and escapes the user's text in it (rich.markup.escape).
console = Console(soft_wrap=True, emoji=False, markup=False, highlight=False)
OVERWRITE_HELP = "Replace existing output instead of refusing."
SAMPLER_HELP = ("ddim, ddpm, dpmpp (DPM-Solver++ 2M, Karras) or dpmpp-sde (its SDE variant; a BioMoDiffuse "
                "model's default, with 10 steps) (default: dpmpp).")
ETA_HELP = "DDIM eta: 0 deterministic, 1 ancestral (DDPM-like) (default: 0)."
CFG_HELP = ("Classifier-free guidance scale, 0 to 10: 0 ignores the text, 1 follows it plainly, more follows it "
            "harder (MDM's 2.5) (default: 2.5).")
# SamplerConfig's fields as the options that set them, for its errors (_as_options).
SAMPLER_OPTIONS = {"steps": "--steps", "eta": "--eta", "cfg_scale": "--cfg-scale", "phys_scale": "--phys-scale",
                   "speed": "--speed"}  # fmt: skip


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import version

        print(f"physmotion {version('physmotion')}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the installed version and exit."),  # fmt: skip
) -> None:
    """Text-to-motion generation that obeys physics."""


def _check_out(out: Path, overwrite: bool | None = None, suffixes: tuple[str, ...] | None = None) -> None:
    """Refuse, before any work, an output file that exists (unless ``overwrite``), cannot be written, or
    (where ``suffixes`` are given) is of a format the command cannot write.

    overwrite None: the command has no --overwrite, so the message does not offer one."""
    from physmotion.paths import check_output

    hint = "delete it or choose another -o" if overwrite is None else "pass --overwrite to replace it"
    check_output(out, "file", overwrite=bool(overwrite), hint=hint, suffixes=suffixes)


@contextmanager
def _as_options(**options: str) -> Iterator[None]:
    """Errors of the library's config checks name a field (``ilc_passes must be ...``); on the command line
    they name the option the user typed (``--ilc must be ...``). ``options`` maps field to option."""
    try:
        yield
    except PhysmotionError as exc:
        message = str(exc)
        for name, option in options.items():
            if message.startswith(f"{name} "):
                raise PhysmotionError(option + message[len(name):]) from None
        raise


def _warn(message: str) -> None:
    """One ``warning: ...`` line on stderr: the CLI's voice for what does not stop the work."""
    print(f"warning: {message}", file=sys.stderr)


# The options of every command that reads a .bvh (import's own help says more).
BVH_RIG_HELP = "Rig of .bvh input, as for `import` (guessed if left out)."
BVH_FPS_HELP = "True frame rate of .bvh input, as for `import`."
MODEL_HELP = ("Model folder, or a shipped model's name: morph (the default, used if left out) or base (the model "
              "Morph fine-tuned it from).")
BVH_MAPPING_HELP = ("JSON file naming the .bvh's joint (or End Site, '<parent>_end') for each of our 22 joints, "
                    "as for `import` (docs/examples/mapping_bandai.json).")
CONTROLLER_HELP = ("Who drives the simulated humanoid: 'tracker' (the model-based tracker, with a bounded outside "
                   "hand on the pelvis), 'policy' (the learned imitation policy over it, physmotion train "
                   "imitator) or 'search' (no outside hand at all: the body's own joint targets searched; "
                   "seconds of CPU per second of motion).")
SEARCH_FALLBACK_HELP = ("Where the tracker (or the policy) falls and is reset, or keeps under 0.8 of a "
                        "flight (both feet off the floor), project that motion again with the search: no "
                        "outside hand, jumps keep their flight, for seconds of CPU per second of motion on "
                        "those motions (results/flight_kept_fallback.md) (default: off).")
RECOVER_HELP = ("Where the tracker (or the policy) falls, let the search carry the body with no outside hand "
                "from 0.5 s before to 0.5 s after (1 s before where it falls too), before resetting it onto "
                "the motion; seconds of CPU per stretch carried (results/recover_jumps.md). --no-recover "
                "resets at once: faster on motions that fall (default: on).")
RESCUE_HELP = ("Where the body under the tracker (or the policy) clears the floor by less than 0.8 of a "
               "flight of the motion, let the search re-do that take-off with no outside hand, from 0.5 s "
               "before the flight's highest (1 s before where that falls or flies no higher), kept where the "
               "body flies higher. Jumps keep more of their flight, but runs leap higher than their samples; "
               "about 2x the CPU on both (results/flight_kept_rescue*.md) (default: off).")
POLICY_HELP = ("With --controller policy: the policy folder (the shipped one if left out). With --controller search: a "
               "policy that proposes each window's first mean (amortized search, `train student`).")
PREVIEW_HELP = ("Write a GIF preview beside the output, <stem>.gif (under a second for a 6 s motion; "
                "docs/cli.md, Previews).")


def _check_preview(out: Path, overwrite: bool) -> None:
    """Before any work: refuse an existing ``<stem>.gif`` beside the output ``out`` unless ``overwrite``,
    with or without --no-preview (without, the write removes it: it showed another motion)."""
    from physmotion.render import preview_path

    _check_out(preview_path(out), overwrite)


def _model_dir(model: Path | None) -> Path | None:
    """A --model as given, or a shipped model's folder where a bare name (``base``, ``morph``, or
    ``default`` for the one used without --model) names one and no folder of that name exists here: model
    names work from any directory."""
    if model is None or model.exists() or len(model.parts) != 1:
        return model
    name = DEFAULT_MODEL if model.name == "default" else model.name
    shipped = WEIGHTS_DIR / name  # diffusion.model.DEFAULT_MODEL_DIR's folder, without torch
    return shipped if (shipped / "config.json").is_file() else model


def _opt_str(path: Path | None) -> str | None:
    return None if path is None else str(path)


def _check_sampler_options(*, steps: int | None, eta: float | None, cfg_scale: float | None) -> None:
    """The sampler options of generate and evaluate, checked before torch loads, named as typed. The
    same bounds as SamplerConfig.check, which runs again on the model's sampler."""
    import math

    from physmotion.conventions import CFG_SCALE_RANGE

    if steps is not None and not 1 <= steps <= 1000:
        raise PhysmotionError(f"--steps must be between 1 and 1000, got {steps}")
    if eta is not None and not (math.isfinite(eta) and 0.0 <= eta <= 1.0):
        raise PhysmotionError(f"--eta must be between 0 and 1, got {eta:g}")
    lo, hi = CFG_SCALE_RANGE
    if cfg_scale is not None and not (math.isfinite(cfg_scale) and lo <= cfg_scale <= hi):
        raise PhysmotionError(f"--cfg-scale must be between {lo:g} and {hi:g} (MDM's default: 2.5), "
                              f"got {cfg_scale:g}")  # fmt: skip


def _with(config, **given):
    """``config`` with the options the user gave (not None) replaced: the dataclass holds every default."""
    from dataclasses import replace

    return replace(config, **{k: v for k, v in given.items() if v is not None})


class _PlainProgress:
    """Progress as a plain stderr line for a log file (not a TTY): at most one per ``every`` seconds, the
    first after ``every`` seconds, so a short run prints nothing and an hour-long ``evaluate`` under
    ``nohup`` says how far it is. ``clock`` and ``stream`` are for tests."""

    def __init__(self, label: str, every: float = 60.0, clock=None, stream=None) -> None:
        import time

        self.label, self.every = label, every
        self.clock = clock or time.monotonic
        self.stream = stream or sys.stderr
        self.start = self.last = self.clock()

    def __call__(self, done: int, total: int | None) -> None:
        now = self.clock()
        if now - self.last < self.every:
            return
        self.last = now
        elapsed = now - self.start
        line = f"{self.label}: {done}" + (f"/{total}" if total else "") + f", {_clock(elapsed)} elapsed"
        if total and 0 < done < total:
            line += f", about {_clock(elapsed * (total - done) / done)} left"
        print(line, file=self.stream, flush=True)


def _clock(seconds: float) -> str:
    minutes, secs = divmod(int(round(seconds)), 60)
    return f"{minutes // 60}:{minutes % 60:02d}:{secs:02d}" if minutes >= 60 else f"{minutes}:{secs:02d}"


def _step_bar(label: str):
    """A context manager yielding tick(done, total): a rich progress bar on a TTY, otherwise a plain line
    a minute at most (:class:`_PlainProgress`)."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    @contextmanager
    def bar():
        if not sys.stderr.isatty():
            yield _PlainProgress(label)
            return
        # The label (a file name) is the task's description, not the column's format string: a "{" in a
        # path would break str.format, and "[..]" or ":fire:" would be read as markup or emoji.
        progress = Progress(TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(),
                            TimeElapsedColumn(), TimeRemainingColumn(),
                            console=Console(stderr=True, emoji=False, markup=False))  # fmt: skip
        with progress:
            task = progress.add_task(label, total=None)
            yield lambda done, total: progress.update(task, completed=done, total=total)

    return bar()
