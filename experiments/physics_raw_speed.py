"""Raw speed of the MuJoCo humanoid and of retargeting, one table from one run.

    python -m experiments.physics_raw_speed [--seconds 5] [--repeats 3] [--out results/physics_raw_speed]

Rows: ``mj_step`` of the default humanoid holding its standing rest pose under PD (single thread,
the set-up of P's ``plain`` preset: dt 1/360 s, implicitfast + Newton, feet in
contact), with and without the floor contacts
(pelvis hung 1 m up); ``mj_kinematics`` alone; ``joints_to_qpos`` / ``qpos_to_joints`` on a 196-frame
synthetic walk (HumanML3D's longest window). Best of ``--repeats`` wall-clock runs; the machine is
shared, so expect +-20-30 %. Writes ``<out>.md`` and ``<out>.json`` (the rows and the run's meta).
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

from experiments._results import markdown_table, parse_args, run_meta, write_results
from physmotion.physics.humanoid import build_model
from physmotion.physics.presets import preset
from physmotion.physics.retarget import joints_to_qpos, qpos_to_joints


def _best(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _walk(frames: int) -> np.ndarray:
    from physmotion.skeleton import REST_OFFSETS, forward_kinematics

    t = np.arange(frames) / 20.0
    rot = np.tile(np.eye(3), (frames, 22, 1, 1))
    for j, sign in ((1, 1.0), (2, -1.0), (4, 1.0), (5, -1.0)):
        a = 0.4 * sign * np.sin(2 * np.pi * t)
        c, s = np.cos(a), np.sin(a)
        rot[:, j, 1, 1], rot[:, j, 1, 2], rot[:, j, 2, 1], rot[:, j, 2, 2] = c, -s, s, c
    root = np.stack([0 * t, 0.93 + 0 * t, 1.3 * t], -1)
    return forward_kinematics(rot, root, REST_OFFSETS)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="results/physics_raw_speed", help="writes OUT.md and OUT.json")
    args = parse_args(ap, argv)

    model = build_model(None, preset("plain").humanoid)  # P's humanoid
    steps = int(round(args.seconds / model.opt.timestep))
    rows: list[tuple[str, float, str]] = []

    def stand(hung: bool) -> tuple[float, int]:
        data = mujoco.MjData(model)
        if hung:
            data.qpos[2] += 1.0
            model.opt.gravity[:] = 0.0
        mujoco.mj_forward(model, data)

        def run() -> None:
            mujoco.mj_resetData(model, data)
            if hung:
                data.qpos[2] += 1.0
            for _ in range(steps):
                mujoco.mj_step(model, data)

        dt = _best(run, args.repeats)
        model.opt.gravity[:] = (0.0, 0.0, -9.81)
        return steps / dt, data.ncon

    rate, ncon = stand(False)
    realtime = rate * model.opt.timestep
    rows.append(("mj_step, standing PD hold", rate, f"{realtime:.0f}x real time, {ncon} contacts"))
    rate, ncon = stand(True)
    realtime = rate * model.opt.timestep
    rows.append(("mj_step, no contacts (hung, no gravity)", rate, f"{realtime:.0f}x real time"))

    data = mujoco.MjData(model)
    n = 20000
    kin = _best(lambda: [mujoco.mj_kinematics(model, data) for _ in range(n)], args.repeats)
    rows.append(("mj_kinematics", n / kin, "calls/s"))

    walk = _walk(196)
    to_q = _best(lambda: joints_to_qpos(walk, model), args.repeats)
    qpos = joints_to_qpos(walk, model)
    to_j = _best(lambda: qpos_to_joints(qpos, model), args.repeats)
    rows.append(("joints_to_qpos (196 frames)", 196 / to_q, "frames/s"))
    rows.append(("qpos_to_joints fk (196 frames)", 196 / to_j, "frames/s"))

    title = (f"mujoco {mujoco.__version__}, dt {model.opt.timestep:.6f} s, {args.seconds:g} s runs, "
             f"best of {args.repeats}, single thread")
    table = markdown_table(("what", "per second", "note"), [(w, f"{r:,.0f}", n) for w, r, n in rows])
    md = f"# Raw physics speed\n\n{title}\n\n{table}\n"
    print(md)
    meta = run_meta(__file__, argv, args.tree, "plain", mujoco=mujoco.__version__, sim_dt=model.opt.timestep)
    write_results(args.out, md, {"meta": meta, "rows": [{"what": w, "per_second": r, "note": n} for w, r, n in rows]})


if __name__ == "__main__":
    main()
