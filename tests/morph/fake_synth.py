"""Synthetic folders for tests, written directly in the SYNTH/ layout from real built items: their joints
as the "input" and the same joints shifted and jittered as the "refined" motion."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from physmotion.checkpoint import weights_sha256
from physmotion.diffusion.physdiff import joints_to_features
from physmotion.morph.selection import INDEX_FIELDS


def make_synth(built_dir: Path, model_dir: Path, out: Path, n: int = 8, failed: int = 2,
               licence_tags: tuple[str, ...] = ("NC", "open"), **info) -> Path:  # fmt: skip
    """A SYNTH/ folder of ``n`` train items of ``built_dir`` made "by" ``model_dir`` (its weights' sha);
    the last ``failed`` rows have an MPJPE over tau, so selection keeps their inputs."""
    ids = [i for i in (built_dir / "train.txt").read_text().split() if not i.startswith("M")][:n]
    for sub in ("new_joints", "new_joint_vecs", "input_joints", "input_joint_vecs", "texts"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    rows = []
    for k, mid in enumerate(ids):
        joints = np.load(built_dir / "new_joints" / f"{mid}.npy").astype(np.float32)
        refined = joints + np.array([0.0, 0.02, 0.0], np.float32) + rng.normal(0, 0.005, joints.shape).astype(np.float32)
        caption = (built_dir / "texts" / f"{mid}.txt").read_text().splitlines()[0].split("#")[0]
        sid = f"s{k:04d}"
        np.save(out / "input_joints" / f"{sid}.npy", joints)
        np.save(out / "input_joint_vecs" / f"{sid}.npy", joints_to_features(joints.astype(np.float64)).astype(np.float32))
        np.save(out / "new_joints" / f"{sid}.npy", refined)
        np.save(out / "new_joint_vecs" / f"{sid}.npy", joints_to_features(refined.astype(np.float64)).astype(np.float32))
        (out / "texts" / f"{sid}.txt").write_text(f"{caption}#{caption}#0.0#0.0\n")
        bad = k >= n - failed
        rows.append({"id": sid, "caption": caption, "frames": len(joints), "mpjpe_mean": 0.8 if bad else 0.05,
                     "mpjpe_max": 1.0 if bad else 0.1, "success": 0 if bad else 1, "resets": 0, "grounded": 1,
                     "licence_tag": licence_tags[0]})  # fmt: skip
    with open(out / "index.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=INDEX_FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    meta = {"model": str(model_dir), "model_sha256": weights_sha256(model_dir),
            "feature_dim": 263, "skeleton": "smpl22", "fps": 20, "data": str(built_dir), "split": "train",
            "per_caption": 1, "seed": 0, "tau": 0.5, "licence_tags": list(licence_tags), "preprocess": {},
            "projection": {}, "items_planned": n} | info  # fmt: skip
    (out / "synth.json").write_text(json.dumps(meta))
    return out
