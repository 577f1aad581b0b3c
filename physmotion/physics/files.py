"""P over motion files: one output per input, written atomically, on this machine or on Ray.

What ``physmotion project`` runs. One motion is one task (its projection, its output file and, for the
search, its teacher records): a task writes its files through a temporary file renamed into place, so a
killed worker loses that motion only, and a re-run skips the motions whose output is already there.
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
from physmotion.physics.projection import ProjectionConfig, project

TEACHER_SUFFIX = ".teacher.npz"


@dataclass
class FileResult:
    """What projecting one file did. ``skipped``: its output existed (a finished motion of an earlier run)."""

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
                 on_step: Callable[[int, int], None] | None = None) -> FileResult:  # fmt: skip
    """Project the motion in ``source`` (.npz) and write the result to ``out`` (.npz, or .bvh by its suffix;
    and, with ``teacher`` under the search, its teacher records beside it), atomically. The input kept by
    imitation selection carries none of the simulation's records."""
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
    from physmotion.io.export import save_motion  # by suffix: .npz (with the records above) or .bvh

    save_motion(replace(motion, joints=result.joints, rotations=None, offsets=None, **sim), out)
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
) -> list[FileResult]:
    """Project every file of ``sources`` into ``out_dir`` (``<stem>.npz``), skipping those already written.

    workers: local processes (0: one per core); ray: a Ray address ("local": start a Ray on this machine)
    to run one task per motion there instead. on_done(result): after each motion, in the order they finish.
    Returns the results in the order of ``sources``. A motion that fails raises; those finished stay written.
    """
    sources = [Path(s) for s in sources]
    out_dir = Path(out_dir)
    outs = outputs_for(sources, out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results: list[FileResult | None] = [None] * len(sources)
    todo = []
    for i, (s, o) in enumerate(zip(sources, outs)):
        if o.exists() and (not teacher or teacher_path(o).exists()):
            results[i] = FileResult(s, o, skipped=True, summary="already written: skipped")
            if on_done is not None:
                on_done(results[i])
        else:
            todo.append(i)
    # Each motion is one task: the search's own rollout threads get one core each.
    task_config = config
    if config.controller == "search" and not config.search.threads:
        task_config = replace(config, search=replace(config.search, threads=1), workers=1)
    fn = partial(_task, config=replace(task_config, workers=1), teacher=teacher)
    jobs = [(sources[i], outs[i]) for i in todo]
    if ray is not None:
        from physmotion.physics.cluster import map_on_ray

        finished: Iterator[tuple[int, FileResult]] = map_on_ray(fn, jobs, ray)
    else:
        from physmotion.physics.workers import imap_in_workers

        finished = imap_in_workers(fn, jobs, workers)
    for j, result in finished:
        results[todo[j]] = result
        if on_done is not None:
            on_done(result)
    return [r for r in results if r is not None]


def _task(job: tuple[Path, Path], config: ProjectionConfig, teacher: bool) -> FileResult:
    source, out = job
    return project_file(source, out, config, teacher)


__all__ = ["FileResult", "outputs_for", "project_file", "project_files", "teacher_path"]
