"""P over motion files: one output per input, written atomically, on this machine or on Ray.

What ``physmotion project`` runs. One motion is one task (its projection, its output file, its GIF
preview of input and output side by side and, for the search, its teacher records): a task writes its
files through a temporary file renamed into place, so a killed worker loses that motion only, and a re-run
skips the motions whose output is already there (only drawing the preview where that is missing).
Tasks run in local worker processes (:mod:`physmotion.physics.workers`) or, with ``ray``, as Ray tasks
(one CPU each) on a local Ray or a cluster (docs/cluster.md): Ray is an existing engine for this, and
an optional extra (``pip install physmotion[ray]``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

from physmotion.errors import PhysmotionError
from physmotion.physics.cluster import map_on_ray, one_core
from physmotion.physics.projection import ProjectionConfig, project
from physmotion.render import preview_path

TEACHER_SUFFIX = ".teacher.npz"


@dataclass
class FileResult:
    """What projecting one file did. ``skipped``: its output existed (a finished motion of an earlier run;
    ``summary`` says whether its missing preview was drawn)."""

    source: Path
    out: Path
    selected: bool = False
    resets: int = 0
    mpjpe_mm: float = 0.0
    summary: str = ""
    skipped: bool = False


def teacher_path(out: Path) -> Path:
    """Where the teacher records of the output ``out`` go: beside it, ``<stem>.teacher.npz``."""
    return out.with_name(out.stem + TEACHER_SUFFIX)


def project_file(source: str | Path, out: str | Path, config: ProjectionConfig, teacher: bool = False,
                 on_step: Callable[[int, int], None] | None = None, preview: bool = False) -> FileResult:  # fmt: skip
    """Project the motion in ``source`` (.npz) and write the result to ``out`` (.npz, or .bvh by its suffix;
    with ``preview``, a GIF of input and output side by side beside it, :func:`physmotion.render.preview_path`;
    and, with ``teacher`` under the search, its teacher records beside it), atomically: a failure leaves
    none of them. The input kept by imitation selection carries none of the simulation's records."""
    from physmotion.metrics.report import help_words
    from physmotion.motion import Motion

    source, out = Path(source), Path(out)
    if teacher and config.controller != "search":
        raise PhysmotionError("teacher records need the search controller: only the search makes them")
    motion = Motion.load(source)
    result = project(motion.joints, motion.fps, config, on_step=on_step)
    # the input kept by imitation selection carries none of the simulation's records
    sim = dict(humanoid=result.body, **result.record().motion_fields(config.residual_bound()))
    sim = sim if result.selected else dict.fromkeys(sim)
    if teacher:  # first, so that an output on disk means its records are there too
        from physmotion.physics.search import save_teacher

        save_teacher(teacher_path(out), result, motion)
    from physmotion.render import save_with_preview

    projected = replace(motion, joints=result.joints, rotations=None, offsets=None, **sim)
    try:  # by suffix: .npz (with the records above) or .bvh; then the preview, the reset frames marked
        save_with_preview(projected, out, preview, before=motion)
    except BaseException:
        if teacher:
            teacher_path(out).unlink(missing_ok=True)
        raise
    kept = "simulation kept" if result.selected else "tracking failed: input kept (flagged)"
    if config.ilc_passes:
        kept += f" (pass {int(result.ilc_pass)} of {config.ilc_passes + 1})"
    if config.reset_on_fail:  # a preset that puts the fallen humanoid back on the motion (a jump in the output)
        kept += f", the humanoid put back onto the motion {int(result.resets)} time(s)"
    mpjpe = 1000 * float(result.mpjpe.mean())
    helped = help_words(result.residual, config.residual_bound(), result.over_limit, result.at_cap,
                        result.residual_peak)  # fmt: skip
    summary = f"{kept}; MPJPE mean {mpjpe:.0f} mm, {helped}"
    return FileResult(source, out, bool(result.selected), int(result.resets), mpjpe, summary)


def preview_file(source: str | Path, out: str | Path) -> None:
    """Draw the preview of a projection already on disk (``source`` its input, ``out`` its output), as
    :func:`project_file` does: for an output of an earlier run written without it."""
    from physmotion.motion import Motion
    from physmotion.render import PREVIEW_LABELS, load_motion, preview_path, save_preview

    save_preview(preview_path(out), [Motion.load(source), load_motion(out)], PREVIEW_LABELS)


def outputs_for(sources: Sequence[Path], out_dir: Path) -> list[Path]:
    """``<out_dir>/<stem>.npz`` per source; two sources of one stem are an error (one would overwrite the other)."""
    outs = [out_dir / (Path(s).stem + ".npz") for s in sources]
    seen: dict[Path, Path] = {}
    for s, o in zip(sources, outs):
        if o in seen:
            raise PhysmotionError(f"{s} and {seen[o]} would both be written to {o}: rename one")
        seen[o] = Path(s)
    return outs


def project_files(
    sources: Sequence[str | Path],
    out_dir: str | Path,
    config: ProjectionConfig,
    teacher: bool = False,
    workers: int = 0,
    ray: str | None = None,
    on_done: Callable[[FileResult], None] | None = None,
    preview: bool = False,
) -> list[FileResult]:
    """Project every file of ``sources`` into ``out_dir`` (``<stem>.npz``, with ``preview`` its GIF
    ``<stem>.gif``), skipping those already written: a finished output whose preview is missing gets only
    its preview drawn.

    workers: local processes (0: one per core); ray: a Ray address ("local": start a Ray on this machine)
    to run one task per motion there instead. on_done(result): after each motion, in the order they finish.
    Returns the results in the order of ``sources``. A motion that fails raises; those finished stay written.
    """
    sources = [Path(s) for s in sources]
    out_dir = Path(out_dir)
    outs = outputs_for(sources, out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results: list[FileResult | None] = [None] * len(sources)
    todo, drawn = [], []
    for i, (s, o) in enumerate(zip(sources, outs)):
        if o.exists() and (not teacher or teacher_path(o).exists()):
            if preview and not preview_path(o).exists():  # an output of a run without its preview
                preview_file(s, o)
                drawn.append(i)
            said = "already written: skipped" + (", its missing preview drawn" if i in drawn else "")
            results[i] = FileResult(s, o, skipped=True, summary=said)
            if on_done is not None:
                on_done(results[i])
        else:
            todo.append(i)
    # Each motion is one task of one core.
    fn = partial(_task, config=replace(one_core(config), workers=1), teacher=teacher, preview=preview)
    jobs = [(sources[i], outs[i]) for i in todo]
    if ray is not None:
        finished: Iterator[tuple[int, FileResult]] = map_on_ray(fn, jobs, ray)
    else:
        from physmotion.physics.workers import imap_in_workers

        finished = imap_in_workers(fn, jobs, workers)
    for j, result in finished:
        results[todo[j]] = result
        if on_done is not None:
            on_done(result)
    return [r for r in results if r is not None]


def _task(job: tuple[Path, Path], config: ProjectionConfig, teacher: bool, preview: bool) -> FileResult:
    source, out = job
    return project_file(source, out, config, teacher, preview=preview)


__all__ = ["FileResult", "outputs_for", "preview_file", "project_file", "project_files", "teacher_path"]
