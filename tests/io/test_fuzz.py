"""Fuzz every reader (BVH, ASF/AMC, motion .npz, rig mapping JSON) with mutations of the bundled clips.

Each input must end in a valid Motion (finite joints (T, 22, 3)) or a PhysmotionError with a
one-line message; never another exception, never more than 5 s, never a partial output file. The
mutations are drawn from a fixed seed, so a failure reproduces; the test prints how many inputs
each mutation kind produced and how they ended.
"""

from __future__ import annotations

import io
import json
import random
import re
import signal
import time
import zipfile
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from physmotion.errors import PhysmotionError
from physmotion.io import import_clip, save_motion
from physmotion.motion import Motion
from tests.cli_runner import invoke

SEED = 24
LIMIT_S = 5.0  # CPU seconds a case may take
WALL_STOP = 4  # x LIMIT_S of wall time ends a case as a hang
REPO = Path(__file__).resolve().parents[2]
MAPPING = REPO / "docs" / "examples" / "mapping_bandai.json"
BANDAI = "bandai/Bandai-Namco-Research-Motiondataset-1/data/dataset-1_dash_normal_001.bvh"
BVH_SEEDS = {  # clip -> (path, rig, frames kept): a few frames keep each import in milliseconds
    "bandai": (BANDAI, "bandai", 8),
    "cgspeed": ("cmu_bvh_cgspeed/resources/131_01.bvh", "cmu_bvh_cgspeed_max", 14),
    "iclone": ("cmu_iclone/subjects/002/002_03.bvh", "cmu_iclone_cc_base", 8),
}
AMC, ASF = "cmu_amc/subjects/02/02_03.amc", "cmu_amc/subjects/02/02.asf"
BAD_NUMBERS = (
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e-320",
    "0",
    "-0",
    "abc",
    "",
    "1e999",
    "9" * 40,
)
NUMBER = re.compile(r"(?<![\w.])-?\d+\.?\d*(?:[eE][-+]?\d+)?")


class _Timeout(Exception):
    pass


@dataclass
class Case:
    reader: str  # bvh, amc, asf, npz, mapping
    kind: str  # the mutation
    data: bytes


def _shrink_bvh(text: str, frames: int) -> str:
    head, body = re.split(r"^\s*MOTION\s*$", text, maxsplit=1, flags=re.MULTILINE)
    lines = [ln for ln in body.strip().splitlines()]
    frame_time = lines[1].split(":")[1].strip()
    return (
        f"{head}MOTION\nFrames: {frames}\nFrame Time: {frame_time}\n"
        + "\n".join(lines[2 : 2 + frames])
        + "\n"
    )


def _shrink_amc(text: str, frames: int) -> str:
    starts = [m.start() for m in re.finditer(r"^\d+\s*$", text, flags=re.MULTILINE)]
    return text[: starts[frames]]


# ------------------------------------------------------------------------------------------------
# Mutations


def _truncate(rng: random.Random, data: bytes) -> bytes:
    return data[: rng.randrange(len(data))]


def _flip(rng: random.Random, data: bytes) -> bytes:
    out = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        out[rng.randrange(len(out))] = rng.randrange(256)
    return bytes(out)


def _number(rng: random.Random, data: bytes) -> bytes:
    text = data.decode()
    spots = list(NUMBER.finditer(text))
    for m in rng.sample(spots, min(len(spots), rng.randint(1, 3))):
        text = text[: m.start()] + rng.choice(BAD_NUMBERS) + text[m.end() :]
        spots = list(NUMBER.finditer(text))
    return text.encode()


def _lines(rng: random.Random, data: bytes) -> bytes:
    """Delete, duplicate or swap a random line."""
    lines = data.decode().split("\n")
    i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
    op = rng.choice(("delete", "duplicate", "swap"))
    if op == "delete":
        del lines[i]
    elif op == "duplicate":
        lines.insert(i, lines[j])
    else:
        lines[i], lines[j] = lines[j], lines[i]
    return "\n".join(lines).encode()


TEXT_MUTATIONS: dict[str, Callable[[random.Random, bytes], bytes]] = {
    "truncate": _truncate, "flip": _flip, "number": _number, "lines": _lines,
}  # fmt: skip


def _bvh_structures(text: str) -> Iterator[tuple[str, str]]:
    """Hand-made malformed BVH files derived from a real one."""
    head, body = re.split(r"^\s*MOTION\s*$", text, maxsplit=1, flags=re.MULTILINE)
    body_lines = body.strip().splitlines()
    yield "zero_joints", "HIERARCHY\nMOTION\nFrames: 1\nFrame Time: 0.03\n0 0 0\n"
    yield (
        "root_only",
        (
            "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n}\n"
            "MOTION\nFrames: 2\nFrame Time: 0.03\n0 0 0\n1 1 1\n"
        ),
    )
    chain = "".join(
        f"JOINT J{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n" for i in range(100_000)
    )
    yield (
        "joints_100k_chain",
        (
            "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\n"
            "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
            "Yrotation\n"
            + chain
            + "}\n" * 100_001
            + "MOTION\nFrames: 1\nFrame Time: 0.03\n"
            + "0 " * 300_006
            + "\n"
        ),
    )
    flat = "".join(f"JOINT K{i}\n{{\nOFFSET 0 1 0\n}}\n" for i in range(100_000))
    yield (
        "joints_100k_flat",
        head.replace("ROOT joint_Root\n{", "ROOT joint_Root\n{\n" + flat, 1) + "MOTION\n" + body,
    )
    yield "duplicate_names", head.replace("JOINT Spine", "JOINT Hips", 1) + "MOTION\n" + body
    yield "empty_motion", head + "MOTION\n"
    yield "motion_no_values", head + "MOTION\n" + "\n".join(body_lines[:2]) + "\n"
    yield "frames_1e9", head + "MOTION\nFrames: 1000000000\n" + "\n".join(body_lines[1:]) + "\n"
    yield "frames_negative", head + "MOTION\nFrames: -5\n" + "\n".join(body_lines[1:]) + "\n"
    for bad in ("0", "-0.03", "nan", "inf", "1e-320", "1e308"):
        yield (
            f"frame_time_{bad}",
            head + "MOTION\n" + body_lines[0] + f"\nFrame Time: {bad}\n" + "\n".join(body_lines[2:]),
        )
    yield "channels_1e6", head.replace("CHANNELS 6", "CHANNELS 1000000", 1) + "MOTION\n" + body
    yield "channels_bad_name", head.replace("Zrotation", "Wrotation", 1) + "MOTION\n" + body
    yield "braces_deep", "HIERARCHY\nROOT A\n" + "{\n" * 100_000 + "MOTION\n" + body
    yield "offset_nan", head.replace("OFFSET", "OFFSET nan nan nan #", 1) + "MOTION\n" + body
    yield "two_roots", head + head.replace("HIERARCHY", "", 1) + "MOTION\n" + body
    yield "motion_twice", head + "MOTION\n" + body + "MOTION\n" + body


def _asf_structures(text: str) -> Iterator[tuple[str, str]]:
    hier = text.index(":hierarchy")
    head = text[:hier]
    yield "cycle", text.replace("lfemur ltibia", "lfemur ltibia\n    ltibia lfemur", 1)
    yield (
        "cycle_detached",
        text.replace(
            "    root lhipjoint rhipjoint lowerback", "    root rhipjoint lowerback\n    lfemur lhipjoint", 1
        ),
    )
    yield "self_parent", text.replace("lfemur ltibia", "lfemur lfemur ltibia", 1)
    yield "duplicate_bone", text.replace("name lfemur", "name ltibia", 1)
    yield "no_hierarchy", head
    yield "empty_hierarchy", head + ":hierarchy\n  begin\n  end\n"
    yield "bone_no_name", text.replace("name lfemur", "", 1)
    yield "dof_translation", text.replace("dof rx ry rz", "dof tx ry rz", 1)
    yield "dof_repeated", text.replace("dof rx ry rz", "dof rx rx rx", 1)
    yield "axis_order_bad", text.replace("axis 0 0 20  XYZ", "axis 0 0 20  XXQ", 1)
    yield "units_zero", text.replace("length 0.45", "length 0", 1)
    yield "units_nan", text.replace("length 0.45", "length nan", 1)
    yield "angle_rad", text.replace("angle deg", "angle rad", 1)
    bones = "".join(
        f"  begin\n     name b{i}\n     direction 0 1 0\n     length 1\n"
        "     axis 0 0 0 XYZ\n    dof rx\n  end\n"
        for i in range(100_000)
    )
    chain = "".join(f"    b{i} b{i + 1}\n" for i in range(99_999))
    # listed leaf first, so a parents-first sort that places one level per pass is quadratic
    yield (
        "bones_100k_chain",
        (
            head.replace(":bonedata\n", ":bonedata\n" + bones, 1)
            + ":hierarchy\n  begin\n    root b0\n"
            + "".join(reversed(chain.splitlines(keepends=True)))
            + "  end\n"
        ),
    )
    yield (
        "bones_100k_under_head",
        text.replace(":bonedata\n", ":bonedata\n" + bones, 1).replace(
            "    upperneck head\n", "    upperneck head\n    head b0\n" + chain, 1
        ),
    )


def _amc_structures(text: str) -> Iterator[tuple[str, str]]:
    first = re.search(r"^1\s*$", text, flags=re.MULTILINE)
    assert first is not None
    header, body = text[: first.start()], text[first.start() :]
    yield "no_frames", header
    yield "frame_numbers_only", header + "".join(f"{i}\n" for i in range(1, 1000))
    yield "frame_1e9", header + body.replace("1\n", "1000000000\n", 1)
    yield (
        "bone_order_shuffled",
        header + body.replace("lowerback", "@").replace("upperback", "lowerback").replace("@", "upperback"),
    )
    yield "missing_bone_in_frame", header + re.sub(r"^lhand .*\n", "", body, count=1, flags=re.MULTILINE)
    yield "extra_values", header + body.replace("\nlowerback ", "\nlowerback 1 ", 1)
    yield "values_before_frame", header + "root 0 0 0 0 0 0\n" + body
    yield "unknown_bone", header + body.replace("lowerback", "tailbone", 1)


def _mapping_structures(text: str) -> Iterator[tuple[str, str]]:
    data = json.loads(text)

    def with_(**changes: object) -> str:
        out = json.loads(text)
        out.update(changes)
        return json.dumps(out)

    joints = data["joints"]
    yield "empty", ""
    yield "not_object", "[1, 2, 3]"
    yield "deep_nesting", "[" * 100_000 + "]" * 100_000
    yield "nan_constant", text.replace('"fps": 30', '"fps": NaN')
    yield "no_joints", json.dumps({"units": "cm"})
    yield "joints_list", with_(joints=list(joints))
    yield "unknown_our_joint", with_(joints={**joints, "tail": "Hips"})
    yield "missing_our_joint", with_(joints={k: v for k, v in joints.items() if k != "head"})
    yield "file_joint_absent", with_(joints={**joints, "left_knee": "LeftLeg"})
    yield "zero_length_bone", with_(joints={**joints, "left_knee": "UpperLeg_L"})
    yield "blend_bad_weights", with_(joints={**joints, "spine2": [["Spine", 0.9], ["Chest", 0.9]]})
    yield "blend_bad_shape", with_(joints={**joints, "spine2": [["Spine"], 3]})
    yield "joint_number", with_(joints={**joints, "neck": 3})
    yield "units_word", with_(units="furlongs")
    yield "units_negative", with_(units=-1)
    yield "units_bool", with_(units=True)
    yield "up_axis_bad", with_(up_axis="W")
    yield "up_axis_z", with_(up_axis="z")
    yield "fps_zero", with_(fps=0)
    yield "fps_string", with_(fps="30")
    yield "fps_huge_int", text.replace('"fps": 30', '"fps": 1' + "0" * 400)
    yield "unknown_key", with_(scale=2)
    yield "binary", "\x00\x01\x02" * 10


def _npz_bytes(**arrays: object) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # type: ignore[arg-type]
    return buf.getvalue()


def _npz_structures(motion: Motion) -> Iterator[tuple[str, bytes]]:
    j = motion.joints
    t = j.shape[0]
    yield "joints_missing", _npz_bytes(fps=np.float32(20))
    for name, arr in {
        "joints_nan": np.where(np.arange(j.size).reshape(j.shape) == 5, np.nan, j),
        "joints_inf": np.where(np.arange(j.size).reshape(j.shape) == 7, np.inf, j),
        "joints_1e308": np.full(j.shape, 1e308),
        "joints_empty": j[:0],
        "joints_2d": j[:, :, 0],
        "joints_21": j[:, :21],
        "joints_scalar": np.float32(1),
        "joints_text": np.array(["a"] * 3),
        "joints_complex": j.astype(np.complex64),
        "joints_int": j.astype(np.int64),
        "joints_bool": j > 0,
    }.items():
        yield name, _npz_bytes(joints=arr)
    for name, extra in {
        "fps_nan": {"fps": np.float32(np.nan)},
        "fps_zero": {"fps": np.float32(0)},
        "fps_vector": {"fps": np.ones(3)},
        "fps_text": {"fps": np.array("fast")},
        "rotations_shape": {"rotations": np.ones(3)},
        "rotations_nan": {"rotations": np.full((t, 22, 3, 3), np.nan, np.float32)},
        "offsets_shape": {"offsets": np.ones((5, 5))},
        "humanoid_shape": {"humanoid": np.ones(2)},
        "resets_vector": {"resets": np.arange(3)},
        "resets_text": {"resets": np.array("x")},
        "residual_shape": {"residual": np.ones(3)},
        "residual_nan": {"residual": np.full((t, 2), np.nan, np.float32)},
        "text_numbers": {"text": np.arange(3)},
        "licence_bytes": {"licence_tag": np.frombuffer(b"\xff\xfe", dtype=np.uint8)},
    }.items():
        yield name, _npz_bytes(joints=j, **extra)
    yield "object_array", _npz_bytes(joints=np.array([j, None], dtype=object))
    yield "not_zip", b"PK\x03\x04 this is not a zip"
    yield (
        "npy_not_npz",
        b"\x93NUMPY\x01\x00v\x00{'descr': '<f4', 'fortran_order': False, 'shape': (1, 22, 3), }",
    )
    header = "{'descr': '<f4', 'fortran_order': False, 'shape': (1000000000, 22, 3), }"
    npy = (
        b"\x93NUMPY\x01\x00"
        + len(header.ljust(117) + "\n").to_bytes(2, "little")
        + (header.ljust(117) + "\n").encode()
    )
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("joints.npy", npy + b"\0" * 64)
    yield "shape_1e9_frames", buf.getvalue()


def generate_cases(mocap_dir: Path, rng: random.Random, per_seed: int) -> list[Case]:
    """Every fuzz input, deterministic for a given rng state."""
    cases: list[Case] = []

    def mutate(reader: str, seed: bytes, n: int) -> None:
        kinds = list(TEXT_MUTATIONS)
        for k in range(n):
            kind = kinds[k % len(kinds)]
            cases.append(Case(reader, kind, TEXT_MUTATIONS[kind](rng, seed)))

    for name, (rel, _, frames) in BVH_SEEDS.items():
        text = _shrink_bvh((mocap_dir / rel).read_text(), frames)
        mutate(f"bvh:{name}", text.encode(), per_seed)
        if name == "bandai":
            cases += [Case("bvh:bandai", kind, t.encode()) for kind, t in _bvh_structures(text)]
    asf_text = (mocap_dir / ASF).read_text()
    amc_text = _shrink_amc((mocap_dir / AMC).read_text(), 12)
    mutate("amc", amc_text.encode(), per_seed)
    mutate("asf", asf_text.encode(), per_seed)
    cases += [Case("amc", kind, t.encode()) for kind, t in _amc_structures(amc_text)]
    cases += [Case("asf", kind, t.encode()) for kind, t in _asf_structures(asf_text)]
    mapping_text = MAPPING.read_text()
    mutate("mapping", mapping_text.encode(), per_seed)
    cases += [Case("mapping", kind, t.encode()) for kind, t in _mapping_structures(mapping_text)]
    motion = import_clip(mocap_dir / BANDAI, rig="bandai")
    seed_npz = io.BytesIO()
    arrays = {"joints": motion.joints, "rotations": motion.rotations, "offsets": motion.offsets}
    np.savez(
        seed_npz, **arrays, fps=np.float32(20), text=np.array("a person dashes"), source=np.array("dash")
    )
    for k in range(per_seed):  # a zip's bytes: only truncation and flips make sense
        kind = ("truncate", "flip")[k % 2]
        cases.append(Case("npz", kind, TEXT_MUTATIONS[kind](rng, seed_npz.getvalue())))
    cases += [Case("npz", kind, data) for kind, data in _npz_structures(motion)]
    return cases


# ------------------------------------------------------------------------------------------------
# Running one case


def _read(case: Case, folder: Path, mocap_dir: Path) -> Motion:
    """The reader the case targets, on the case's bytes written to a file."""
    reader = case.reader.split(":")[0]
    if reader == "npz":
        path = folder / "motion.npz"
        path.write_bytes(case.data)
        return Motion.load(path)
    if reader == "bvh":
        name = case.reader.split(":")[1]
        path = folder / f"{name}.bvh"
        path.write_bytes(case.data)
        return import_clip(path, rig=BVH_SEEDS[name][1])
    if reader in ("amc", "asf"):
        amc, asf = folder / "take.amc", folder / "skel.asf"
        amc.write_bytes(
            case.data if reader == "amc" else _shrink_amc((mocap_dir / AMC).read_text(), 12).encode()
        )
        asf.write_bytes(case.data if reader == "asf" else (mocap_dir / ASF).read_bytes())
        return import_clip(amc, asf=asf, fps=120)
    path = folder / "map.json"
    path.write_bytes(case.data)
    return import_clip(mocap_dir / BANDAI, mapping=path)


def _valid(motion: Motion) -> str:
    """'' for a valid motion, else what is wrong with it."""
    j = motion.joints
    if j.ndim != 3 or j.shape[1:] != (22, 3) or j.shape[0] < 1 or not np.all(np.isfinite(j)):
        return f"invalid joints {j.shape}"
    if motion.rotations is not None and (
        motion.rotations.shape != (j.shape[0], 22, 3, 3) or not np.all(np.isfinite(motion.rotations))
    ):
        return f"invalid rotations {np.shape(motion.rotations)}"
    if motion.offsets is not None and (
        motion.offsets.shape != (22, 3) or not np.all(np.isfinite(motion.offsets))
    ):
        return f"invalid offsets {np.shape(motion.offsets)}"
    return ""


def _alarm(signum: int, frame: object) -> None:
    raise _Timeout


def run_case(case: Case, folder: Path, mocap_dir: Path, to_file: bool) -> tuple[str, float, str]:
    """(outcome, seconds, detail): outcome ok, error, crash, invalid, slow or partial."""
    for f in folder.iterdir():
        if f.is_file():
            f.unlink()
    out_dir = folder / "out"
    previous = signal.signal(signal.SIGALRM, _alarm)
    # A case is judged by the CPU time it takes (what it costs alone: CI shares its 2 cores with nothing,
    # a developer's machine may not); a hang is stopped by the wall clock at WALL_STOP.
    signal.setitimer(signal.ITIMER_REAL, WALL_STOP * LIMIT_S)
    start = time.process_time()
    try:
        motion = _read(case, folder, mocap_dir)
        problem = _valid(motion)
        if not problem and to_file:
            save_motion(motion, out_dir / "motion.npz")
        outcome, detail = ("invalid", problem) if problem else ("ok", "")
    except _Timeout:
        outcome, detail = "slow", f"over {WALL_STOP * LIMIT_S} s of wall time"
    except PhysmotionError as exc:
        message = str(exc)
        outcome, detail = (
            ("error", message) if message and "\n" not in message else ("crash", f"bad message {message!r}")
        )
    except Exception as exc:  # noqa: BLE001 - the point: any other exception is a reader bug
        outcome, detail = "crash", f"{type(exc).__name__}: {str(exc)[:200]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    seconds = time.process_time() - start
    if seconds > LIMIT_S:
        outcome, detail = "slow", f"{seconds:.1f} s of CPU time"
    if to_file and out_dir.exists():  # nothing, or whole files only
        left = sorted(p.name for p in out_dir.iterdir())
        whole = (
            outcome == "ok" and left == ["motion.npz"] and _valid(Motion.load(out_dir / "motion.npz")) == ""
        )
        if left and not whole:
            outcome, detail = "partial", f"output folder holds {left}"
        for f in out_dir.iterdir():
            f.unlink()
    return outcome, seconds, detail


# ------------------------------------------------------------------------------------------------
# The tests


@pytest.mark.slow  # 2,000+ mutated inputs through every reader (30-60 s on 2 cores)
def test_fuzz_every_reader(mocap_dir: Path, tmp_path: Path) -> None:
    rng = random.Random(SEED)
    cases = generate_cases(mocap_dir, rng, per_seed=320)
    assert len(cases) >= 2000
    outcomes: Counter[str] = Counter()
    by_kind: Counter[tuple[str, str, str]] = Counter()
    failures: list[str] = []
    slowest = (0.0, "")
    start = time.perf_counter()
    for n, case in enumerate(cases):
        outcome, seconds, detail = run_case(case, tmp_path, mocap_dir, to_file=n % 10 == 0)
        outcomes[outcome] += 1
        by_kind[(case.reader.split(":")[0], case.kind, outcome)] += 1
        slowest = max(slowest, (seconds, f"{case.reader} {case.kind}"))
        if seconds > 0.5:
            print(f"  slow-ish: {case.reader} {case.kind} {outcome} {seconds:.2f} s {detail[:100]}")
        if outcome not in ("ok", "error"):
            failures.append(f"#{n} {case.reader} {case.kind}: {outcome}: {detail}")
    total = time.perf_counter() - start
    print(
        f"\nfuzz: {len(cases)} inputs in {total:.1f} s; outcomes {dict(outcomes)}; "
        f"slowest {slowest[0]:.2f} s ({slowest[1]})"
    )
    for (reader, kind, outcome), count in sorted(by_kind.items()):
        print(f"  {reader:8s} {kind:24s} {outcome:8s} {count}")
    assert not failures, "\n".join(failures[:30])
    # the mutations must reach both outcomes in every reader, or the fuzzer tests nothing
    for reader in ("bvh", "amc", "asf", "npz", "mapping"):
        assert by_kind_total(by_kind, reader, "error") > 0 and by_kind_total(by_kind, reader, "ok") > 0, (
            reader
        )


def by_kind_total(by_kind: Counter[tuple[str, str, str]], reader: str, outcome: str) -> int:
    return sum(c for (r, _, o), c in by_kind.items() if r == reader and o == outcome)




@pytest.mark.parametrize("kind", ["flip", "joints_100k_chain", "duplicate_names", "frames_1e9", "mapping"])
def test_cli_one_line_errors(kind: str, mocap_dir: Path, tmp_path: Path) -> None:
    """The console script's main: one 'error:' line on stderr, exit 1, no traceback, no output."""
    text = _shrink_bvh((mocap_dir / BANDAI).read_text(), 8)
    bvh = tmp_path / "in.bvh"
    args = ["--rig", "bandai"]
    if kind == "flip":
        bvh.write_text(text.replace("CHANNELS 6", "CHANNELS 7", 1))
    elif kind == "mapping":
        bvh.write_text(text)
        (tmp_path / "map.json").write_text(MAPPING.read_text().replace('"LowerLeg_L"', '"LeftLeg"'))
        args = ["--mapping", str(tmp_path / "map.json")]
    else:
        bvh.write_text(dict(_bvh_structures(text))[kind])
    out = tmp_path / "out" / "motion.npz"
    res = invoke("import", bvh, "-o", out, *args)  # main() in this process (tests/cli_runner.py)
    lines = res.stderr.splitlines()
    assert res.returncode == 1 and len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    assert "Traceback" not in res.stderr
    assert not out.parent.exists() or not list(out.parent.iterdir())
    if kind == "mapping":
        assert "left_knee -> 'LeftLeg' not found in in.bvh (joints: " in lines[0]
