"""Regenerate the behaviour pin, ``tests/data/pins/generate.npz``: motions the shipped default model
generates for a few fixed prompts and seeds, through the command line (``physmotion generate``).

    .venv/bin/python tests/make_pins.py          # rewrite the pin
    .venv/bin/python tests/make_pins.py --check  # compare only: prints what differs, exit 1 if anything

``tests/test_pins.py`` compares a fresh generation with the committed file. Work that changes the
generated motions on purpose reruns this script and says why in its commit message; work that should not
change them (refactoring, moving files) leaves the pin alone and the test passes unchanged.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # `python tests/make_pins.py` puts tests/ first on the path, not the root
    sys.path.insert(0, str(ROOT))

from experiments._results import cpu_model  # noqa: E402
from tests.cli_runner import invoke  # noqa: E402

PIN = ROOT / "tests" / "data" / "pins" / "generate.npz"

# (prompts, seed, physics mode, seconds): one `physmotion generate` call each, with the shipped model and
# its default sampler and steps (DPM-Solver++, 10 steps). Plain sampling of two prompts in one batch pins
# the network, the text encoder and the sampler; a short post:1 run pins the physics projection (P:
# MuJoCo tracking with its resets) on top. Short clips keep the test in the fast tier (about 20 s of CPU).
RUNS: tuple[tuple[tuple[str, ...], int, str, float], ...] = (
    (("a person walks forward", "a person waves the right hand"), 7, "none", 2.0),
    (("a person jumps in place",), 3, "post:1", 2.0),
)

def generate_pins(work: Path) -> dict[str, np.ndarray]:
    """``"<physics>/<file stem>" -> joints`` (T, 22, 3) float32 of every run in :data:`RUNS`."""
    joints: dict[str, np.ndarray] = {}
    for n, (prompts, seed, physics, seconds) in enumerate(RUNS):
        out = work / f"run{n}"
        res = invoke("generate", *prompts, "--seed", seed, "--physics", physics, "--seconds", seconds,
                     "--no-preview", "-o", out)  # fmt: skip
        if res.returncode != 0:
            raise RuntimeError(f"physmotion generate failed ({res.returncode}):\n{res.stderr}")
        for path in sorted(out.glob("*.npz")):
            with np.load(path) as data:
                joints[f"{physics}/{path.stem}"] = np.array(data["joints"])
    return joints


def provenance() -> str:
    """What made the pin (JSON): library versions and the CPU, for reading a mismatch."""
    import mujoco
    import torch

    return json.dumps({
        "runs": [list(r) for r in RUNS], "torch": torch.__version__, "numpy": np.__version__,
        "mujoco": mujoco.__version__, "python": platform.python_version(), "machine": platform.machine(),
        "processor": platform.processor(), "torch_threads": torch.get_num_threads(), "cpu": cpu_model(),
    }, sort_keys=True)  # fmt: skip


# Sampling alone (physics "none") is bit-identical whatever the thread count. P's output is not: with
# OMP_NUM_THREADS=1 instead of this machine's 2 threads, the post:1 motion moved by up to 1.07e-6 m (2,445
# of 2,640 values), float32 rounding in the simulation's inputs. Projected motions
# are compared to ATOL_PHYSICS metres (0.01 mm), far below any change in behaviour.
ATOL_PHYSICS = 1e-5
# Another CPU rounds torch's and MuJoCo's float arithmetic differently: on an Intel Xeon against a pin made
# on an AMD EPYC, plain sampling moved by up to 1.67e-6 m and the post:1 jump by 3.52e-5 m. A pin whose CPU
# is another's (or not recorded: pins before the provenance named it) is compared to these.
ATOL_OTHER_CPU = {"none": 1e-5, "physics": 1e-3}


def tolerance(key: str, same_cpu: bool = True) -> float:
    """On the CPU that made the pin: 0 (bit-identical) for plain sampling, :data:`ATOL_PHYSICS` for a motion
    that went through P; on another, :data:`ATOL_OTHER_CPU`."""
    plain = key.startswith("none/")
    if not same_cpu:
        return ATOL_OTHER_CPU["none" if plain else "physics"]
    return 0.0 if plain else ATOL_PHYSICS


def pinned_on_this_cpu(path: Path = PIN) -> bool:
    """Whether the pin's provenance names this machine's CPU (a pin that does not record its CPU: no)."""
    with np.load(path) as data:
        return json.loads(str(data["provenance"])).get("cpu") == cpu_model()


def compare(expected: dict[str, np.ndarray], got: dict[str, np.ndarray], same_cpu: bool = True) -> list[str]:
    """One line per motion that is missing, extra, or differs beyond :func:`tolerance` (with its largest
    difference)."""
    problems = [f"{k}: missing from the new generation" for k in sorted(set(expected) - set(got))]
    problems += [f"{k}: not in the pin" for k in sorted(set(got) - set(expected))]
    for key in sorted(set(expected) & set(got)):
        a, b = expected[key], got[key]
        if a.shape != b.shape or a.dtype != b.dtype:
            problems.append(f"{key}: {b.dtype}{b.shape} generated, {a.dtype}{a.shape} pinned")
        elif not np.array_equal(a, b):
            diff = np.abs(a.astype(np.float64) - b.astype(np.float64))
            allowed = tolerance(key, same_cpu)
            if diff.max() > allowed:
                problems.append(f"{key}: differs, max {diff.max():.3g} m (allowed {allowed:g}), "
                                f"{int((diff > 0).sum())} of {diff.size} values")  # fmt: skip
    return problems


def load_pin(path: Path = PIN) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        return {k: np.array(data[k]) for k in data.files if k != "provenance"}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed pin, write nothing")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        got = generate_pins(Path(tmp))
    if args.check:
        same = pinned_on_this_cpu()
        problems = compare(load_pin(), got, same)
        within = (f"plain sampling bit-identical, projected within {ATOL_PHYSICS:g} m" if same else
                  f"pinned on another CPU: plain sampling within {ATOL_OTHER_CPU['none']:g} m, projected "
                  f"within {ATOL_OTHER_CPU['physics']:g} m")  # fmt: skip
        print("\n".join(problems) or f"{len(got)} motions match {PIN.relative_to(ROOT)} ({within})")
        return 1 if problems else 0
    PIN.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(PIN, provenance=np.array(provenance()), **got)
    print(f"wrote {PIN.relative_to(ROOT)}: {len(got)} motions, {PIN.stat().st_size / 1e3:.0f} kB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
