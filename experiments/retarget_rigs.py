"""A generated motion exported onto other skeletons (``export --rig-from``) and imported back (issue 64).

Usage: python -m experiments.retarget_rigs [--out results/retarget_rigs]
The default model's "a person walks forward", 4 s, seed 0 (P's output, generate's default) is exported onto
three rigs of different proportions and imported back with the same rig table or mapping:

- mixamo: a Mixamo-named rig (``mixamorig:Hips`` ...) written by :func:`mixamo_rig_bvh`: our rest body
  re-proportioned (legs x1.12, arms x0.9, trunk x1.05), in cm, T-pose rest, with finger, forearm-twist,
  head-top and toe-end joints we lack; ``--rig mixamo``;
- cmu_asf: CMU subject 01's ASF skeleton (``../shared/data/mocap/cmu_amc``) at rest, written as BVH in cm
  by :func:`cmu_asf_bvh`; ``--rig cmu_asf --units cm``;
- bandai_mapping: a Bandai Namco BVH (``../shared/data/mocap/bandai``, rest pose with every bone along +X)
  with a user's mapping JSON (``docs/examples/mapping_bandai.json`` without its ``fps``: the file written
  has the motion's 20 fps).

Per rig: the leg ratio, the mean joint error after scaling back to our proportions
(:func:`~physmotion.io.retarget_rig.error_at_our_proportions`), Skate / Penetrate / Float (mm, the
humanoid surface as ``physmotion metrics``) of ours and of the import, with the feet pinned and without
(``pin_feet=False``), so the pinning's share shows. Also ``--in-place``'s horizontal root travel and
``--loop``'s frames and pose distance. Writes ``<out>.md`` and ``<out>.json``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from experiments._results import heading, markdown_table, parse_args, run_meta, write_results
from physmotion.io.amc import read_amc
from physmotion.io.bvh import write_bvh
from physmotion.io.importer import import_clip
from physmotion.io.in_place import best_loop, horizontal_travel, in_place
from physmotion.io.retarget_rig import RetargetConfig, error_at_our_proportions, load_target, retarget
from physmotion.io.rigs import RIGS, RigMotion
from physmotion.motion import Motion
from physmotion.skeleton import JOINT_NAMES, PARENTS, REST_OFFSETS

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / ".." / "shared" / "data" / "mocap"
PROMPT = "a person walks forward"

# our joint -> the Mixamo joint (without the prefix), from the mixamo rig table
_MIXAMO_NAMES = {j: str(src).removeprefix("mixamorig:") for j, src in RIGS["mixamo"].joints.items()}
_SCALE = {"hip": 1.12, "knee": 1.12, "ankle": 1.12, "foot": 1.0, "shoulder": 0.9, "elbow": 0.9, "wrist": 0.9}


def mixamo_rig_bvh(path: str | Path, prefix: str = "mixamorig:") -> None:
    """Write a one-frame BVH of a Mixamo-named skeleton (cm, T-pose rest, Y up, facing +Z): our rest body
    re-proportioned (legs x1.12, arms x0.9, trunk x1.05), each forearm split by a twist joint, three finger
    chains per hand and end joints (HeadTop_End, toe ends) that our 22 joints lack."""
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []

    def add(name: str, parent: int, offset: np.ndarray) -> int:
        names.append(prefix + name)
        parents.append(parent)
        offsets.append(np.asarray(offset, dtype=np.float64) * 100.0)  # cm
        return len(names) - 1

    node: dict[int, int] = {}
    for j, joint in enumerate(JOINT_NAMES):
        part = joint.split("_", 1)[-1]
        offset = REST_OFFSETS[j] * _SCALE.get(part, 1.05)
        if part == "wrist":  # forearm split by a twist joint halfway
            side = "Left" if joint.startswith("left") else "Right"
            twist = add(f"{side}ForeArmTwist", node[PARENTS[j]], offset / 2)
            node[j] = add(_MIXAMO_NAMES[joint], twist, offset / 2)
            sign = 1.0 if side == "Left" else -1.0
            for finger, z in (("Thumb", 0.03), ("Index", 0.02), ("Middle", 0.0)):
                k = node[j]
                for n in range(1, 4):
                    k = add(f"{side}Hand{finger}{n}", k, [sign * (0.04 if n == 1 else 0.03), 0.0, z if n == 1 else 0.0])
            continue
        node[j] = add(_MIXAMO_NAMES[joint], node[PARENTS[j]] if j else -1, offset)
    add("HeadTop_End", node[JOINT_NAMES.index("head")], [0.0, 0.12, 0.0])
    for side in ("left", "right"):
        add(f"{side.title()}Toe_End", node[JOINT_NAMES.index(f"{side}_foot")], [0.0, 0.0, 0.05])
    count = len(names)
    translations = np.array(offsets)[None].copy()
    translations[0, 0] = [0.0, 100.0, 0.0]
    rig = RigMotion(names=tuple(names), parents=np.array(parents), rotations=np.broadcast_to(np.eye(3), (1, count, 3, 3)).copy(),
                    translations=translations)  # fmt: skip
    write_bvh(path, rig, 30.0)


def cmu_asf_bvh(path: str | Path, amc: str | Path, asf: str | Path) -> None:
    """Write the skeleton of a CMU ASF at rest (every rotation the identity: the ASF's rest pose) as a
    one-frame BVH in cm: node names as the ``cmu_asf`` table reads them (``root``, ``lfemur`` ...)."""
    rig = read_amc(amc, asf).frames(slice(0, 1))
    metres = float(rig.units or 1.0)
    translations = rig.translations * metres * 100.0
    translations[:, 0] = 0.0
    rest = RigMotion(names=rig.names, parents=rig.parents, rotations=np.broadcast_to(np.eye(3), rig.rotations.shape).copy(),
                     translations=translations, is_end=rig.is_end)  # fmt: skip
    write_bvh(path, rest, 30.0)


def _metrics(joints: np.ndarray, fps: float) -> dict[str, float]:
    from physmotion.metrics import physical_metrics
    from physmotion.physics.surface import HumanoidSurface

    m = physical_metrics(np.asarray(joints, dtype=np.float64), fps=fps, body=HumanoidSurface())
    return {k: float(m[k]) for k in ("skate", "penetrate", "float")}


def _rigs(tmp: Path) -> dict[str, dict]:
    """Per rig: the BVH file and how export and import name its table."""
    mixamo = tmp / "mixamo.bvh"
    mixamo_rig_bvh(mixamo)
    cmu = tmp / "cmu_asf.bvh"
    cmu_asf_bvh(cmu, DATA / "cmu_amc" / "subjects" / "01" / "01_01.amc", DATA / "cmu_amc" / "subjects" / "01" / "01.asf")
    mapping = json.loads((REPO / "docs" / "examples" / "mapping_bandai.json").read_text(encoding="utf-8"))
    mapping.pop("fps")
    user_map = tmp / "mapping.json"
    user_map.write_text(json.dumps(mapping), encoding="utf-8")
    bandai = sorted((DATA / "bandai").glob("*/data/*.bvh"))[0]
    return {
        "mixamo": {"file": mixamo, "rig": "mixamo"},
        "cmu_asf": {"file": cmu, "rig": "cmu_asf", "units": "cm"},
        "bandai_mapping": {"file": bandai, "mapping": user_map},
    }


def main(argv: list[str] | None = None) -> None:
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.generate import GenerateConfig, generate

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results/retarget_rigs", help="writes OUT.md and OUT.json")
    args = parse_args(parser, argv)
    motion = generate([PROMPT], GenerateConfig(num=1, seed=0, seconds=4), MotionDiffusion.load()).motions[0]
    ours = _metrics(motion.joints, motion.fps)
    rows, table = {}, []
    with tempfile.TemporaryDirectory() as folder:
        tmp = Path(folder)
        for name, spec in _rigs(tmp).items():
            target = load_target(spec["file"], rig=spec.get("rig"), mapping=spec.get("mapping"), units=spec.get("units"))
            row: dict[str, object] = {"file": spec["file"].name, "joints": len(target.rest.names)}
            for pinned in (True, False):
                result = retarget(motion, target, RetargetConfig(pin_feet=pinned))
                out = tmp / f"{name}_{pinned}.bvh"
                write_bvh(out, result.rig, motion.fps)
                back = import_clip(out, rig=spec.get("rig"), mapping=spec.get("mapping"), units=spec.get("units"))
                err, yaw = error_at_our_proportions(motion.joints, back.joints, result.leg_ratio)
                key = "pinned" if pinned else "unpinned"
                row[key] = {"error_cm": 100 * err, "fit_yaw_deg": yaw, **_metrics(back.joints, back.fps),
                            "frames": back.num_frames, "max_correction_cm": 100 * float(result.correction.max())}  # fmt: skip
                row["leg_ratio"] = result.leg_ratio
            rows[name] = row
            p, u = row["pinned"], row["unpinned"]
            passes = p["error_cm"] <= 2 and p["skate"] <= ours["skate"] + 1 and p["penetrate"] <= 2
            table.append((name, row["joints"], f"{row['leg_ratio']:.3f}", f"{p['error_cm']:.2f}", f"{u['error_cm']:.2f}",
                          f"{p['skate']:.2f}", f"{u['skate']:.2f}", f"{p['penetrate']:.2f}", f"{p['float']:.2f}",
                          "yes" if passes else "no"))  # fmt: skip
    loop = best_loop(motion.joints)
    still = in_place(motion)
    extra = {"travel_m": horizontal_travel(motion.joints), "in_place_travel_m": horizontal_travel(still.joints),
             "loop": {"start": loop.start, "end": loop.end, "distance_cm": 100 * loop.distance}}  # fmt: skip
    meta = run_meta(__file__, argv, args.tree, "sampling", prompt=PROMPT, seconds=4, seed=0)
    header = ("rig", "joints", "leg ratio", "error cm (pinned)", "error cm (unpinned)", "Skate mm (pinned)",
              "Skate (unpinned)", "Penetrate mm", "Float mm", "meets issue 64")  # fmt: skip
    md = heading("A generated motion on three other skeletons, imported back", meta)
    md += f"Ours ({PROMPT!r}, 4 s, seed 0): Skate {ours['skate']:.2f} mm, Penetrate {ours['penetrate']:.2f} mm, "
    md += f"Float {ours['float']:.2f} mm.\n\n" + markdown_table(header, table) + "\n\n"
    md += (f"In place: root travel {100 * extra['travel_m']:.1f} cm -> {100 * extra['in_place_travel_m']:.2f} cm. "
           f"Loop: frames {loop.start}..{loop.end - 1}, pose distance {100 * loop.distance:.1f} cm.\n")  # fmt: skip
    print(md)
    write_results(args.out, md, {"meta": meta, "ours": ours, "rigs": rows, **extra})


if __name__ == "__main__":
    main()
