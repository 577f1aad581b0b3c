"""The first motion as a user meets it (issue 51): cold command line, warm library, served request; one table.

Usage: python -m experiments.first_motion [--runs 3] [--prompts 16] [--seconds 6] [--modes none,physdiff,morph]
       [--threads N] [--cold-cache] [--out results/first_motion]

Every row is timed by wall clock, min and median over ``--runs`` rounds; the rounds interleave the rows,
so a slow spell of the shared machine hits all of them alike. Three ways in, each for every physics mode
of ``--modes``, at batch 1 (one prompt) and batch N (``--prompts``, N different prompts):

- **cold CLI**: a fresh process from outside: ``physmotion --help``, an argument error
  (``generate ... --seconds 20``), ``generate PROMPT --physics MODE --no-preview --seconds 6`` (batch 1),
  ``generate --prompts FILE`` with the N prompts (batch N), and for ``none`` the same N prompts as N
  separate cold calls; ``python -c pass`` is the interpreter's own start;
- **warm library**: ``generate()`` in this process, with the model loaded and warmed up once before;
- **served**: ``physmotion serve --port 0`` started in its own process (its time from launch to
  answering is a row), then one ``POST /api/generate`` (batch 1) or N of them at once (batch N; the
  server makes one motion at a time, with ``--waiting N``), timed at the client.

The ratio column is each row's median over this run's baseline, the warm library's plain motion
(``generate()``, ``none``, batch 1): compare ratios within a run, the machine's speed drifts between
runs. The last lines check the issue's acceptance figures that this table holds. Prompt features come
from a cache folder of this run, filled by an untimed warm-up (``--cold-cache``: a fresh, empty cache
for every cold process instead). ``--threads 1`` sets ``OMP_NUM_THREADS=1`` in every process: on a 2-core
machine shared with other work, torch's two threads can make sampling several times slower
(docs/decisions/tools.md). Writes ``<out>.md`` and ``<out>.json`` (with a ``meta`` block) after every
round, so an interrupted run keeps the rounds it finished.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from experiments._results import cpu_model, markdown_table, parse_args, run_meta, write_results

PROMPTS = ["a person walks forward", "a person jumps in place", "a person waves the right hand",
           "a person runs in a circle", "a person sits down", "a person kicks with the left leg",
           "a person turns around", "a person walks backwards", "a person jogs forward", "a person hops on one leg",
           "a person bows", "a person claps", "a person steps to the side", "a person crouches", "a person stretches",
           "a person throws a ball"]  # fmt: skip
BASELINE = "warm library: generate(), none, batch 1"


@dataclass
class Row:
    """One timed row: ``run()`` returns its wall seconds for one round."""

    label: str
    run: Callable[[], float]
    times: list[float] = field(default_factory=list)


def _timed(argv: list[str], env: dict[str, str]) -> float:
    """Wall seconds of a process run to its end (exit code 0, or 1 for the argument error)."""
    start = time.perf_counter()
    res = subprocess.run(argv, env=env, capture_output=True, text=True, check=False)
    took = time.perf_counter() - start
    if res.returncode not in (0, 1):
        raise RuntimeError(f"{' '.join(argv)} failed ({res.returncode}):\n{res.stderr}")
    return took


def _post(url: str, body: dict) -> dict:
    """POST JSON to ``url``; the JSON answer (RuntimeError on any answer but 200)."""
    req = urllib.request.Request(url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=900) as res:
            return json.loads(res.read())
    except urllib.error.HTTPError as exc:
        raise RuntimeError(f"{url}: {exc.code} {exc.read().decode(errors='replace')}") from None


class _Server:
    """``physmotion serve`` in its own process on a free port; ``started_s``: launch to answering."""

    def __init__(self, cli: list[str], env: dict[str, str], waiting: int) -> None:
        start = time.perf_counter()
        self.proc = subprocess.Popen([*cli, "serve", "--port", "0", "--physics", "none", "--waiting", str(waiting)],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     env=dict(env, PYTHONUNBUFFERED="1"))  # fmt: skip
        self.url = ""
        for line in self.proc.stdout:  # type: ignore[union-attr]
            if found := re.search(r"serving on (http://\S+/)", line):
                self.url = found[1]
                break
        if not self.url:
            raise RuntimeError(f"physmotion serve did not start (exit {self.proc.wait()})")
        with urllib.request.urlopen(self.url + "api/health", timeout=30):
            pass
        self.started_s = time.perf_counter() - start

    def request(self, texts: list[str], physics: str, seconds: float) -> float:
        """Wall seconds until every one of ``texts`` (POSTed at once) is answered."""
        bodies = [{"text": t, "physics": physics, "seconds": seconds} for t in texts]
        start = time.perf_counter()
        with ThreadPoolExecutor(len(bodies)) as pool:
            list(pool.map(lambda b: _post(self.url + "api/generate", b), bodies))
        return time.perf_counter() - start

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(30)


def _rows(args: argparse.Namespace, work: Path, env: dict[str, str]) -> tuple[list[Row], Callable[[], None]]:
    """The table's rows in order, and a function that stops what they started."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.generate import GenerateConfig, generate

    py, cli = sys.executable, [sys.executable, "-m", "physmotion.cli"]
    prompts = PROMPTS[: args.prompts]
    n = len(prompts)
    prompt_file = work / "prompts.txt"
    prompt_file.write_text("\n".join(prompts) + "\n", encoding="utf-8")
    out = str(work / "out")

    def cold_env() -> dict[str, str]:
        fresh = str(work / f"cold-{time.monotonic_ns()}")
        return dict(env, PHYSMOTION_CACHE_DIR=fresh) if args.cold_cache else env

    def cold(*argv: str) -> Callable[[], float]:
        return lambda: _timed(list(argv), cold_env())

    def gen(mode: str, *given: str) -> list[str]:
        return [*cli, "generate", *given, "--physics", mode, "--no-preview", "--seconds", f"{args.seconds:g}",
                "--overwrite", "-o", out]  # fmt: skip

    net = MotionDiffusion.load()
    generate(prompts, GenerateConfig(seconds=args.seconds, physics="none"), net)  # warm-up, fills the prompt cache

    def warm(texts: list[str], mode: str) -> Callable[[], float]:
        def run() -> float:
            start = time.perf_counter()
            generate(texts, GenerateConfig(seconds=args.seconds, physics=mode), net)
            return time.perf_counter() - start

        return run

    server: list[_Server] = []

    def start_server() -> float:  # a fresh server each round: its start is a cold row
        if server:
            server.pop().close()
        server.append(_Server(cli, env, waiting=n))
        return server[0].started_s

    def served(texts: list[str], mode: str) -> Callable[[], float]:
        return lambda: server[0].request(texts, mode, args.seconds)

    rows = [Row("cold CLI: python -c pass", cold(py, "-c", "pass")),
            Row("cold CLI: physmotion --help", cold(*cli, "--help")),
            Row("cold CLI: argument error (--seconds 20)", cold(*cli, "generate", "a person walks", "--seconds", "20"))]
    for mode in args.modes:
        rows.append(Row(f"cold CLI: generate, {mode}, batch 1", cold(*gen(mode, prompts[0]))))
        rows.append(Row(f"cold CLI: generate --prompts, {mode}, batch {n}", cold(*gen(mode, "--prompts", str(prompt_file)))))
    if "none" in args.modes:
        calls = [gen("none", p) for p in prompts]
        rows.append(Row(f"cold CLI: {n} separate calls, none", lambda: sum(_timed(c, cold_env()) for c in calls)))
    for mode in args.modes:
        rows.append(Row(f"warm library: generate(), {mode}, batch 1", warm(prompts[:1], mode)))
        rows.append(Row(f"warm library: generate(), {mode}, batch {n}", warm(prompts, mode)))
    rows.append(Row("served: physmotion serve, launch to answering", start_server))
    for mode in args.modes:
        rows.append(Row(f"served: POST, {mode}, batch 1", served(prompts[:1], mode)))
        rows.append(Row(f"served: {n} POSTs at once, {mode}", served(prompts, mode)))
    return rows, lambda: server.pop().close() if server else None


def _acceptance(stats: dict[str, dict[str, float]], n: int) -> list[str]:
    """The issue's acceptance lines this table measures, with the run's medians (min)."""

    def cell(label: str) -> str:
        s = stats.get(label)
        return f"{s['median']:.2f} s (min {s['min']:.2f})" if s else "not timed"

    lines = [f"- cold one 6 s motion, none: {cell('cold CLI: generate, none, batch 1')} (issue: at most 3 s, goal 2 s)",
             f"- argument error: {cell('cold CLI: argument error (--seconds 20)')} (issue: at most 0.5 s)",
             f"- --help: {cell('cold CLI: physmotion --help')} (issue: at most 0.3 s)",
             f"- warm plain motion: {cell(BASELINE)} (issue: at most 0.2 s)",
             (f"- served plain motion, at the client: {cell('served: POST, none, batch 1')} (issue: shown in the "
              "browser within 2 s; tests/test_serve.py times the page)")]  # fmt: skip
    plain, phys = stats.get(BASELINE), stats.get("warm library: generate(), physdiff, batch 1")
    if plain and phys:
        lines.append(f"- PhysDiff / plain, warm: {phys['median'] / plain['median']:.2f} (issue: at most 1.5)")
    batch, separate = stats.get(f"cold CLI: generate --prompts, none, batch {n}"), stats.get(f"cold CLI: {n} separate calls, none")
    if batch and separate:
        lines.append(f"- --prompts {n} / {n} cold calls: {batch['median'] / separate['median']:.2f} (issue: at most 0.33)")
    return lines


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--runs", type=int, default=3, help="rounds over all rows; min and median count")
    parser.add_argument("--prompts", type=int, default=16, help="the batch size N (at most 16)")
    parser.add_argument("--seconds", type=float, default=6.0, help="length of every motion")
    parser.add_argument("--modes", default="none,physdiff,morph", help="physics modes, comma-separated")
    parser.add_argument("--cold-cache", action="store_true", help="an empty prompt cache for every cold process")
    parser.add_argument("--threads", type=int, default=0,
                        help="torch threads in every process (OMP_NUM_THREADS; 0: torch's default)")
    parser.add_argument("--out", default="results/first_motion", help="writes OUT.md and OUT.json")
    args = parse_args(parser, argv)
    args.modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    args.prompts = max(1, min(args.prompts, len(PROMPTS)))
    work = Path(tempfile.mkdtemp(prefix="first_motion-"))
    os.environ["PHYSMOTION_CACHE_DIR"] = str(work / "cache")  # this process's generate() and every child's
    if args.threads:  # before torch is imported here; the children inherit it
        os.environ["OMP_NUM_THREADS"] = str(args.threads)
    env = dict(os.environ)
    rows, stop = _rows(args, work, env)
    try:
        for run in range(max(1, args.runs)):
            for row in rows:
                row.times.append(row.run())
                print(f"  round {run + 1}: {row.label}: {row.times[-1]:.2f} s", file=sys.stderr, flush=True)
            _write(args, argv, rows, run + 1)  # a round at a time: an interrupted run keeps what it measured
    finally:
        stop()


def _write(args: argparse.Namespace, argv: list[str] | None, rows: list[Row], rounds: int) -> None:
    """Print the table and write ``args.out``'s .md and .json, from the ``rounds`` rounds done."""
    stats = {r.label: {"min": min(r.times), "median": statistics.median(r.times), "times": r.times} for r in rows}
    base = stats[BASELINE]["median"]
    load = os.getloadavg()
    threads = os.environ.get("OMP_NUM_THREADS", "torch's default")
    title = (f"first motion: cold CLI, warm library, served; {args.seconds:g} s motions, the default model and "
             f"sampler; {cpu_model()}, {os.cpu_count()} cores, torch threads: {threads}; {rounds} round(s); load "
             f"average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1 / 5 / 15 min)")  # fmt: skip
    table = markdown_table(("row", "min s", "median s", "x baseline (median)"),
                           [(label, f"{s['min']:.2f}", f"{s['median']:.2f}", f"{s['median'] / base:.3g}")
                            for label, s in stats.items()])  # fmt: skip
    md = (f"# {title}\n\nBaseline: {BASELINE} ({base:.2f} s median).\n\n{table}\n\nAcceptance lines of issue 51 "
          "this run measures (medians):\n\n" + "\n".join(_acceptance(stats, args.prompts)) + "\n")
    print(md, flush=True)
    meta = run_meta(__file__, argv, args.tree, {"physdiff": "sampling", "morph": "plain"}, runs=args.runs,
                    rounds_done=rounds, prompts=args.prompts, seconds=args.seconds, modes=args.modes,
                    cold_cache=args.cold_cache,
                    cores=os.cpu_count(), torch_threads=threads, load_average=[round(x, 2) for x in load])  # fmt: skip
    write_results(args.out, md, {"meta": meta, "baseline": BASELINE, "seconds": stats})

if __name__ == "__main__":
    main()
