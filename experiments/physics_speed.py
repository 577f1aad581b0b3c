"""Physics speed, one table, all figures from one run (the machine is shared: compare ratios).

Usage: python bench/physics.py [--batch 64] [--seconds 6]
- raw: mj_step rate of the humanoid holding a standing pose (no Python in the loop but the call);
- projection: sim steps per second inside project() (retarget, reference shaping, inverse dynamics,
  closed-loop tracking at the simulation rate, resampling), and its ratio to raw;
- latency of one motion (warm: best of three after a first call), also with the root residual
  recomputed at every simulation step instead of every ``residual_every``-th, and with iterative
  learning control (``project --ilc 2``: three simulations, the option for offline projection);
  throughput of a batch with 1 worker process and with one per core (mujoco.rollout cannot run this
  closed-loop controller; see physics/sim.py).
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace

import mujoco
import numpy as np
from rich.console import Console
from rich.table import Table

from physmotion.io.importer import import_clip, load_manifest
from physmotion.physics.humanoid import build_model, standing_height
from physmotion.physics.projection import ProjectionConfig, project

CLIP = "bandai2_dataset-2_walk_normal_001"


def raw_steps_per_second(cfg: ProjectionConfig, seconds: float = 3.0) -> float:
    model = build_model(None, cfg.humanoid)
    data = mujoco.MjData(model)
    data.qpos[2] = standing_height()
    n = int(seconds / model.opt.timestep)
    best = 0.0
    for _ in range(3):
        mujoco.mj_resetData(model, data)
        data.qpos[2] = standing_height()
        start = time.perf_counter()
        for _ in range(n):
            mujoco.mj_step(model, data)
        best = max(best, n / (time.perf_counter() - start))
    return best


def _best_latency(joints: np.ndarray, cfg: ProjectionConfig) -> float:
    """Best of three warm runs of one motion (the raw rate is a best of runs too)."""
    best = float("inf")
    for _ in range(3):
        start = time.perf_counter()
        project(joints, config=cfg)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--mocap", default="../shared/data/mocap")
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=6.0)
    args = parser.parse_args()
    cfg = ProjectionConfig()
    clips = {c.clip: c for c in load_manifest(args.mocap)}
    joints = import_clip(clips[CLIP], floor="frame0").joints[: int(args.seconds * 20)]  # P's input convention
    sim_steps = (len(joints) - 1) / 20 / cfg.humanoid.sim_dt

    raw = raw_steps_per_second(cfg)
    one = project(joints, config=cfg)  # warm-up: the first call also pays lazy imports (scipy.ndimage, ...)
    latency = _best_latency(joints, cfg)
    every_step = replace(cfg, humanoid=replace(cfg.humanoid, residual_every=1))
    latency_every_step = _best_latency(joints, every_step)
    latency_ilc = _best_latency(joints, replace(cfg, ilc_passes=2))
    batch = np.stack([joints] * args.batch)
    timings = {}
    for workers in (1, os.cpu_count() or 1):
        project(batch[:workers], config=ProjectionConfig(workers=workers))  # start the worker pool
        start = time.perf_counter()
        project(batch, config=ProjectionConfig(workers=workers))
        timings[workers] = time.perf_counter() - start

    table = Table(title=f"physics speed: {args.seconds:.0f} s walk, sim {1 / cfg.humanoid.sim_dt:.0f} Hz, "
                        f"control {1 / cfg.humanoid.control_dt:.0f} Hz")  # fmt: skip
    for col in ("measure", "value", "ratio to raw mj_step"):
        table.add_column(col)
    table.add_row("raw mj_step, standing (steps/s, 1 thread)", f"{raw:,.0f}", "1.00")
    table.add_row("projection loop, 1 motion (sim steps/s)", f"{sim_steps / latency:,.0f}",
                  f"{sim_steps / latency / raw:.2f}")
    table.add_row("latency, 1 motion, warm (s)", f"{latency:.2f}", f"tracked: {bool(one.success)}")
    table.add_row("  the same, root residual at every sim step (s)", f"{latency_every_step:.2f}",
                  f"{latency_every_step / latency:.2f}x the default's time")
    table.add_row("  the same, with ILC (--ilc 2) (s)", f"{latency_ilc:.2f}",
                  f"{latency_ilc / latency:.2f}x the default's time")
    for workers, secs in timings.items():
        table.add_row(f"batch {args.batch}, {workers} process(es): motions/s", f"{args.batch / secs:.2f}",
                      f"{args.batch * sim_steps / secs / raw:.2f}")
    Console(width=140).print(table)


if __name__ == "__main__":
    main()
