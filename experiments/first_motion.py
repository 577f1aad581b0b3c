"""Time the command line from cold, as a user meets it (issue 51, items 1 and 3): one table.

Usage: python experiments/first_motion.py [--runs 3] [--steps N] [--prompts 16] [--cold-cache]

Rows, each a fresh process started from outside and timed by wall clock (min and median of --runs):
the bare interpreter (``python -c pass``, this run's baseline), ``physmotion --help``, an argument error
(``generate ... --seconds 20``), one 6 s motion (``generate ... --physics none --no-preview``), then
``--prompts`` with N prompts in one process against the same N prompts as N separate cold calls.
The last column is each row's median over the baseline's; the last line is the --prompts ratio the
issue's acceptance asks about (at most 1/3). Prompt features come from a cache folder of this run, filled
by an untimed warm-up (--cold-cache: a fresh, empty cache for every timed process instead).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PROMPTS = ["a person walks forward", "a person jumps in place", "a person waves the right hand",
           "a person runs in a circle", "a person sits down", "a person kicks with the left leg",
           "a person turns around", "a person walks backwards", "a person jogs forward", "a person hops on one leg",
           "a person bows", "a person claps", "a person steps to the side", "a person crouches", "a person stretches",
           "a person throws a ball"]  # fmt: skip


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def timed(argv: list[str], env: dict[str, str]) -> float:
    start = time.perf_counter()
    res = subprocess.run(argv, env=env, capture_output=True, text=True, check=False)
    took = time.perf_counter() - start
    if res.returncode not in (0, 1):
        raise RuntimeError(f"{' '.join(argv)} failed ({res.returncode}):\n{res.stderr}")
    return took


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--steps", type=int, default=None, help="sampling steps (default: the model's)")
    ap.add_argument("--prompts", type=int, default=16, help="how many prompts for the batch rows (<= 16)")
    ap.add_argument("--cold-cache", action="store_true", help="an empty prompt cache for every process")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="first_motion-"))
    env = dict(os.environ, PHYSMOTION_CACHE_DIR=str(work / "cache"))
    py, cli = sys.executable, [sys.executable, "-m", "physmotion.cli"]
    steps = ["--steps", str(args.steps)] if args.steps else []
    prompts = PROMPTS[: args.prompts]
    (work / "prompts.txt").write_text("\n".join(prompts) + "\n", encoding="utf-8")

    def gen(*extra: str) -> list[str]:
        return [*cli, "generate", *extra, "--physics", "none", "--no-preview", "--seconds", "6", *steps,
                "--overwrite", "-o", str(work / "out")]  # fmt: skip

    rows: list[tuple[str, list[list[str]]]] = [
        ("python -c pass (baseline)", [[py, "-c", "pass"]]),
        ("physmotion --help", [[*cli, "--help"]]),
        ("argument error (--seconds 20)", [[*cli, "generate", "a person walks", "--seconds", "20"]]),
        ("one 6 s motion, --physics none", [gen(prompts[0])]),
        (f"{len(prompts)} separate cold calls", [gen(p) for p in prompts]),
        (f"--prompts with {len(prompts)}", [gen("--prompts", str(work / "prompts.txt"))]),
    ]
    if not args.cold_cache:
        timed(gen("--prompts", str(work / "prompts.txt")), env)  # warm-up: fills the prompt cache
    results = []
    for label, commands in rows:
        times = []
        for run in range(args.runs):
            total = 0.0
            for argv in commands:
                run_env = (
                    dict(env, PHYSMOTION_CACHE_DIR=str(work / f"cold{run}-{time.monotonic_ns()}"))
                    if args.cold_cache
                    else env
                )
                total += timed(argv, run_env)
            times.append(total)
        results.append((label, min(times), statistics.median(times)))
        print(f"  {label}: {', '.join(f'{t:.2f}' for t in times)} s", file=sys.stderr, flush=True)
    base = results[0][2]
    print(f"first_motion: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {cpu_name()}, "
          f"{os.cpu_count()} cores, {args.runs} runs, steps {args.steps or 'default'}, "
          f"{'cold' if args.cold_cache else 'warm'} prompt cache")  # fmt: skip
    print(f"| {'command':34s} | {'min s':>7s} | {'median s':>8s} | {'x baseline':>10s} |")
    print(f"|{'-' * 36}|{'-' * 9}|{'-' * 10}|{'-' * 12}|")
    for label, lo, med in results:
        print(f"| {label:34s} | {lo:7.2f} | {med:8.2f} | {med / base:10.1f} |")
    print(f"--prompts {len(prompts)} / {len(prompts)} cold calls (medians): {results[-1][2] / results[-2][2]:.2f} "
          "(issue 51: at most 0.33)")  # fmt: skip


if __name__ == "__main__":
    main()
