"""Teacher data: the searching controller (``physics/search.py``) run over many motions, for a policy to learn
from (docs/decisions/projection.md: "learning from the search").

Motions are cut into segments of at most ``segment_seconds``; each segment is searched from its first frame
and, ``perturbed`` times, from a perturbed start (a random push of the root's velocity), so that the data
covers recoveries as well as the motion. Jobs are ordered by a seeded shuffle, so the first N of them are a
random sample of the whole set and a run stopped at any point is a fair subset; a re-run skips every job whose
file is written (one ``.npz`` per job, written atomically), so a killed run loses one job per process.

Per job (``<id>.npz``), per control step 0..N-1 (30 Hz):
``observations`` (N, 599) float32, what a policy sees (:func:`physmotion.physics.policy.observe`, cap 0);
``offsets`` (N, 63) float32, the committed offsets of the joint targets, rad; ``effort`` (N,) the search's
retry level; ``qpos`` (N, nq), ``qvel`` (N, nv) the searched trajectory; ``ref_qpos`` (N, nq) and
``ref_joints`` (N, 22, 3) the reference (MuJoCo frame, metres, Z up); ``joints`` and ``fps``, the segment as
given, from which :func:`physmotion.physics.projection.prepare_motion` rebuilds the same humanoid; ``completed``, ``failed_at``, ``push``, ``cpu_seconds``,
``rollouts``, ``licence_tag``, ``origin``, ``source``. ``index.json`` lists every job written, with its cost.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.imitator.clips import ClipSource
from physmotion.physics.projection import ProjectionConfig
from physmotion.physics.search import SearchConfig, effort


@dataclass(frozen=True)
class TeacherConfig:
    """What the teacher data covers and at what search effort."""

    search: SearchConfig = field(default_factory=lambda: effort("default"))
    segment_seconds: float = 4.0  # motions are cut into segments of at most this
    min_seconds: float = 1.5  # a shorter tail segment is dropped
    perturbed: int = 1  # searches per segment from a perturbed start, besides the plain one
    push_linear: float = 0.4  # m/s: spread of the horizontal push of the root at a perturbed start
    push_angular: float = 0.8  # rad/s: spread of the push of the root's angular velocity
    seed: int = 0

    def projection(self) -> ProjectionConfig:
        """P's configuration whose humanoid, shaping and tracking the search runs with (the plain preset's,
        every outside help off: :func:`physmotion.physics.search.no_hand`). The humanoid keeps the plain
        preset's pyramidal cone, not the elliptic one ``with_controller("search")`` gives P's search: it is
        the humanoid a student then runs on under ``--controller policy``."""
        return ProjectionConfig(controller="search", search=replace(self.search, threads=1))


@dataclass(frozen=True)
class TeacherJob:
    """One search: a segment of a motion, from a plain or a perturbed start."""

    source: str  # the motion's name
    origin: str  # "captured" or "generated"
    licence_tag: str
    start: int  # first frame of the segment in the motion
    joints: np.ndarray  # (T, 22, 3) float64, metres, Y up, at fps
    fps: float
    push: np.ndarray  # (6,) root velocity added at the start (zeros: a plain start)

    @property
    def id(self) -> str:
        """A file name unique to the motion, segment and push."""
        tag = hashlib.sha1(self.push.tobytes()).hexdigest()[:6]
        return f"{self.source}_f{self.start}_{'plain' if not self.push.any() else 'push' + tag}"


def teacher_jobs(clips: Sequence[ClipSource], config: TeacherConfig) -> list[TeacherJob]:
    """Every job for ``clips`` (segments x starts), in a seeded random order."""
    rng = np.random.default_rng(config.seed)
    jobs = []
    for clip in clips:
        seg = int(round(config.segment_seconds * clip.fps))
        for start in range(0, len(clip.joints), seg):
            part = clip.joints[start : start + seg].astype(np.float64)
            if len(part) < config.min_seconds * clip.fps:
                continue
            pushes = [np.zeros(6)]
            for _ in range(config.perturbed):
                lin = np.r_[rng.normal(0.0, config.push_linear, 2), 0.0]  # MuJoCo z is up: horizontal only
                pushes.append(np.r_[lin, rng.normal(0.0, config.push_angular, 3)])
            jobs += [TeacherJob(clip.name, clip.origin, clip.licence_tag, start, part, clip.fps, p) for p in pushes]
    order = rng.permutation(len(jobs))
    return [jobs[i] for i in order]


def search_job(job: TeacherJob, config: TeacherConfig) -> dict[str, np.ndarray]:
    """Search one job (no outside hand) and return its records (the module docstring lists them)."""
    from physmotion.physics.projection import prepare_motion
    from physmotion.physics.search import SearchController
    from physmotion.physics.tracking import prepare_reference

    pconf = config.projection()
    t0 = time.process_time()
    prep = prepare_motion(job.joints, job.fps, pconf)
    ref = prepare_reference(prep.model, prep.target, pconf.humanoid.control_dt, pconf.tracking)
    search = SearchController(prep.model, pconf.search, pconf.humanoid, pconf.tracking)
    roll, record = search.run(ref, push=job.push)
    return {
        "observations": record.observations, "offsets": record.offsets.astype(np.float32),
        "effort": record.effort, "qpos": record.qpos, "qvel": record.qvel, "ref_qpos": ref.qpos,
        "ref_joints": ref.joints_mj,
        "completed": np.array(roll.failed_at is None),
        "failed_at": np.array(-1 if roll.failed_at is None else roll.failed_at),
        "push": job.push, "cpu_seconds": np.array(time.process_time() - t0), "rollouts": np.array(record.rollouts),
        "licence_tag": np.array(job.licence_tag), "origin": np.array(job.origin), "source": np.array(job.source),
        "joints": job.joints.astype(np.float32), "fps": np.array(job.fps),
    }  # fmt: skip


def build_teacher_set(jobs: Sequence[TeacherJob], out: str | Path, config: TeacherConfig, workers: int = 0,
                      ray: str | None = None, progress: bool = True) -> dict:  # fmt: skip
    """Search every job not yet written to ``out`` (``<id>.npz`` each, atomically; processes or, with ``ray``
    an address or "local", Ray tasks) and rewrite ``out/index.json``. Returns the index: per job its
    source, origin, licence tag, push, control steps, completed, CPU seconds and rollouts; totals."""
    from physmotion.motion import write_atomic

    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    todo = [j for j in jobs if not (root / f"{j.id}.npz").is_file()]
    fn = partial(_search_and_write, root=str(root), config=config)
    if ray is not None:
        from physmotion.physics.cluster import map_on_ray

        done = map_on_ray(fn, todo, ray)
    else:
        from physmotion.physics.workers import imap_in_workers

        done = imap_in_workers(fn, todo, workers)
    bar = _bar(progress, len(todo))
    for _ in done:
        bar()
    rows = [_row(root / f"{j.id}.npz") for j in jobs if (root / f"{j.id}.npz").is_file()]
    index = {"config": asdict(config), "jobs": len(jobs), "written": len(rows),
             "control_steps": sum(r["steps"] for r in rows), "completed": sum(r["completed"] for r in rows),
             "cpu_seconds": round(sum(r["cpu_seconds"] for r in rows), 1),
             "licence_tags": sorted({r["licence_tag"] for r in rows if r["licence_tag"]}), "items": rows}  # fmt: skip
    write_atomic(root / "index.json", lambda f: f.write(json.dumps(index, indent=1).encode()))
    return index


def load_teacher_set(folder: str | Path) -> list[dict[str, np.ndarray]]:
    """Every job's records in a teacher folder (sorted by name)."""
    root = Path(folder)
    files = sorted(root.glob("*.npz"))
    if not files:
        raise PhysmotionError(f"no teacher records in {root} (make them with `physmotion train teacher`)")
    out = []
    for f in files:
        with np.load(f) as z:
            out.append({k: z[k] for k in z.files} | {"id": f.stem})
    return out


def _search_and_write(job: TeacherJob, root: str, config: TeacherConfig) -> str:
    from physmotion.motion import write_atomic

    rec = search_job(job, config)
    path = Path(root) / f"{job.id}.npz"
    write_atomic(path, lambda f: np.savez_compressed(f, **rec))
    return job.id


def _row(path: Path) -> dict:
    with np.load(path) as z:
        return {"id": path.stem, "source": str(z["source"]), "origin": str(z["origin"]),
                "licence_tag": str(z["licence_tag"]), "push": np.round(z["push"], 3).tolist(),
                "steps": len(z["offsets"]), "completed": bool(z["completed"]),
                "cpu_seconds": round(float(z["cpu_seconds"]), 2), "rollouts": int(z["rollouts"])}  # fmt: skip


def _bar(enabled: bool, total: int):
    """A callable advancing a progress bar with ETA (rich) over ``total`` jobs; a no-op when disabled."""
    if not enabled or total == 0:
        return lambda: None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    prog = Progress("searching", BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), transient=True)
    prog.start()
    task = prog.add_task("", total=total)
    state = {"n": 0}

    def advance() -> None:
        prog.advance(task)
        state["n"] += 1
        if state["n"] == total:
            prog.stop()

    return advance
