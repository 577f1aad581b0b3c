"""The projection P in feature space, on a real walk from the bundled data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from physmotion.diffusion.physdiff import FeatureProjector, ProjectionLog, joints_to_features
from physmotion.features.humanml3d import recover_from_ric
from physmotion.metrics.dynamics import largest_step
from physmotion.physics.projection import ProjectionConfig


def _walk(built_dir: Path) -> np.ndarray:
    ids = (built_dir / "test.txt").read_text().split() + (built_dir / "train.txt").read_text().split()
    pick = next(i for i in sorted(ids) if "walk_normal" in i and not i.startswith("M"))
    return np.load(built_dir / "new_joint_vecs" / f"{pick}.npy")[:80]


def test_joints_to_features_keeps_the_length_and_round_trips(built_dir: Path) -> None:
    feats = _walk(built_dir)
    joints = recover_from_ric(feats.astype(np.float64))
    again = joints_to_features(joints)
    assert again.shape == feats.shape
    back = recover_from_ric(again.astype(np.float64))
    floor = joints[..., 1].min() - back[..., 1].min()  # features put the lowest joint on the floor
    assert np.abs(back[:-1] + [0, floor, 0] - joints[:-1]).max() < 1e-3


def test_projector_simulates_a_real_walk(built_dir: Path, tiny_model) -> None:
    feats = _walk(built_dir)
    x0 = torch.from_numpy(tiny_model.normalizer.normalize(feats)).float()[None]
    x0 = torch.cat([x0, torch.zeros(1, 8, x0.shape[-1])], dim=1)  # padded as in a mixed-length batch
    config = ProjectionConfig.sampling(record_reference_step=True)
    out, done = FeatureProjector(tiny_model, config).project_features(x0, [80])
    assert out.shape == x0.shape and torch.equal(out[:, 80:], x0[:, 80:])
    assert done.selected == [True] and done.mpjpe_mm[0] < 100
    assert done.joints[0].shape == (80, 22, 3) and done.bodies[0].shape == (22, 3)
    log = ProjectionLog()
    assert log.add(done) is done and log.calls == 1 and log.selected == [True] and log.resets == done.resets
    # what P was given: the walk as recovered (a constant floor shift moves nothing between frames)
    walk = recover_from_ric(tiny_model.normalizer.denormalize(x0[0, :80].numpy()).astype(np.float64))
    assert log.last_input_steps(1) == done.input_steps
    assert done.input_steps[0] == pytest.approx(largest_step(walk), abs=1e-9) and done.input_steps[0] > 0.01
    assert ProjectionLog().last_input_steps(1) == []
    # the reference P tracked: the walk retargeted onto the humanoid and shaped, moving about as fast
    assert log.last_reference_steps(1) == done.reference_steps
    assert done.reference_steps[0] == pytest.approx(done.input_steps[0], abs=0.01)
    sim = recover_from_ric(tiny_model.normalizer.denormalize(out[0, :80].numpy()).astype(np.float64))
    ref = recover_from_ric(feats.astype(np.float64))
    err = np.linalg.norm((sim - sim[:, :1]) - (ref - ref[:, :1]), axis=-1).mean()
    assert 0.001 < err < 0.1  # the simulation changes the motion, but it is still the same walk
