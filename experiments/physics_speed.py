"""Physics speed, one table, all figures from one run (the machine is shared: compare ratios).

Usage: python -m experiments.physics_speed [--batch 64] [--seconds 6] [--preset plain] [--out results/physics_speed]
- raw: mj_step rate of the humanoid holding a standing pose (no Python in the loop but the call);
- projection: sim steps per second inside project() (retarget, reference shaping, inverse dynamics,
  closed-loop tracking at the simulation rate, resampling), and its ratio to raw;
- latency of one motion (warm: best of three after a first call), also with the root residual
  recomputed at every simulation step instead of every ``residual_every``-th, and with iterative
  learning control (``project --ilc 2``: three simulations, the option for offline projection);
  throughput of a batch with 1 worker process and with one per core (mujoco.rollout cannot run this
  closed-loop controller; see physics/sim.py).
P is the preset ``--preset`` (physmotion/physics/presets.py). Writes ``<out>.md`` and ``<out>.json``.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace

import mujoco
import numpy as np

from experiments._results import markdown_table, parse_args, run_meta, write_results
from physmotion.io.importer import import_clip, load_manifest
from physmotion.physics.humanoid import build_model, standing_height
from physmotion.physics.presets import preset, preset_names
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


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--mocap", default="../shared/data/mocap")
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--preset", default="plain", choices=preset_names(), help="P's preset")
    parser.add_argument("--out", default="results/physics_speed", help="writes OUT.md and OUT.json")
    args = parse_args(parser, argv)
    cfg = preset(args.preset)
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
        project(batch[:workers], config=replace(cfg, workers=workers))  # start the worker pool
        start = time.perf_counter()
        project(batch, config=replace(cfg, workers=workers))
        timings[workers] = time.perf_counter() - start

    title = (f"physics speed: {args.seconds:.0f} s walk, sim {1 / cfg.humanoid.sim_dt:.0f} Hz, "
             f"control {1 / cfg.humanoid.control_dt:.0f} Hz, P's preset {args.preset}")
    rows = [("raw mj_step, standing (steps/s, 1 thread)", f"{raw:,.0f}", "1.00"),
            ("projection loop, 1 motion (sim steps/s)", f"{sim_steps / latency:,.0f}",
             f"{sim_steps / latency / raw:.2f}"),
            ("latency, 1 motion, warm (s)", f"{latency:.2f}", f"tracked: {bool(one.success)}"),
            ("  the same, root residual at every sim step (s)", f"{latency_every_step:.2f}",
             f"{latency_every_step / latency:.2f}x the default's time"),
            ("  the same, with ILC (--ilc 2) (s)", f"{latency_ilc:.2f}", f"{latency_ilc / latency:.2f}x the default's time")]
    rows += [(f"batch {args.batch}, {workers} process(es): motions/s", f"{args.batch / secs:.2f}",
              f"{args.batch * sim_steps / secs / raw:.2f}") for workers, secs in timings.items()]  # fmt: skip
    md = f"# {title}\n\n" + markdown_table(("measure", "value", "ratio to raw mj_step"), rows) + "\n"
    print(md)
    figures = {"raw_steps_per_second": raw, "latency_s": latency, "latency_residual_every_step_s": latency_every_step,
               "latency_ilc_s": latency_ilc, "sim_steps": sim_steps, "tracked": bool(one.success),
               "batch": args.batch, "batch_seconds": {str(w): s for w, s in timings.items()}}  # fmt: skip
    meta = run_meta(__file__, argv, args.tree, args.preset, clip=CLIP, seconds=args.seconds)
    write_results(args.out, md, {"meta": meta, "figures": figures})

if __name__ == "__main__":
    main()
