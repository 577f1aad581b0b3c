"""Physical metrics of motions as HumanML3D features hold them, and after grounding them on the humanoid.

    python -m experiments.data_convention --data data_build/mocap [--synth runs/morph/round_1/synth ...]
        [--out results/data_convention]

HumanML3D's features put each clip's lowest joint at y = 0, which leaves the humanoid's soles under the
floor. `--physics none` is measured in that convention, the real rows of our tables grounded
(``ground_on_surface``). This prints both for the captured test and train splits and, per synthetic
folder of `physmotion morph synth`, for the motions Morph's imitation selection keeps (refined ones, and
the generated inputs they came from): what fine-tuning on them can teach plain sampling
(docs/decisions/morph.md, "what fine-tuning can do for --physics none"). Millimetres, humanoid surface.
Writes ``<out>.md`` and ``<out>.json``; no projection (the meta's preset is null).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from experiments._results import markdown_table, parse_args, run_meta, write_results
from physmotion.conventions import FPS
from physmotion.features.humanml3d import recover_from_ric
from physmotion.metrics.physical import physical_metrics
from physmotion.morph.selection import select
from physmotion.physics.humanoid import body_from_joints
from physmotion.physics.surface import HumanoidSurface, ground_on_surface

COLUMNS = ("penetrate", "float", "skate", "phys_err")


def measure(features: list[np.ndarray]) -> dict[str, float]:
    """Mean over motions of the metrics as the features hold them, and Phys-Err grounded."""
    rows = []
    for f in features:
        joints = recover_from_ric(f.astype(np.float64))
        body = body_from_joints(joints)
        as_is = physical_metrics(joints[None], FPS, body=HumanoidSurface(body))
        grounded, body = ground_on_surface(joints, body)
        row = {k: as_is[k] for k in COLUMNS}
        on_floor = physical_metrics(grounded[None], FPS, body=HumanoidSurface(body))
        row["phys_err_grounded"] = on_floor["phys_err"]
        rows.append(row)
    return {k: float(np.mean([r[k] for r in rows])) for k in rows[0]} | {"n": len(rows)}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("data_build/mocap"))
    parser.add_argument("--synth", type=Path, nargs="*", default=[])
    parser.add_argument("--out", default="results/data_convention", help="writes OUT.md and OUT.json")
    args = parse_args(parser, argv)
    sets: dict[str, list[np.ndarray]] = {}
    for split in ("test", "train"):
        ids = (args.data / f"{split}.txt").read_text().split()
        sets[f"captured, {split} split"] = [np.load(args.data / "new_joint_vecs" / f"{i}.npy") for i in ids]
    for synth in args.synth:
        kept = [it for it in select(synth).items if it.source == "refined"]
        sets[f"{synth}: refined, kept"] = [np.load(it.features_path) for it in kept]
        inputs = [synth / "input_joint_vecs" / f"{it.id}.npy" for it in kept]
        sets[f"{synth}: their generated inputs"] = [np.load(path) for path in inputs]
    measured = {}
    for name, feats in sets.items():
        measured[name] = measure(feats)
        print(f"{name}: {measured[name]}", flush=True)
    header = ("motions", "n", "Penetrate", "Float", "Skate", "Phys-Err", "Phys-Err grounded")
    rows = [(name, m["n"], *(f"{m[k]:.1f}" for k in (*COLUMNS, "phys_err_grounded"))) for name, m in measured.items()]
    md = "# Physical metrics in the data convention and grounded (mm)\n\n" + markdown_table(header, rows) + "\n"
    print(md)
    meta = run_meta(__file__, argv, args.tree, None, data=str(args.data))
    write_results(args.out, md, {"meta": meta, "sets": measured})

if __name__ == "__main__":
    main()
