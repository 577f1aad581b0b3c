"""Fine-tuning data on the physical floor (morph/floor.py) and the model's floor convention downstream."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from physmotion.conventions import FLOOR_JOINTS, FLOOR_SURFACE
from physmotion.data.dataset import MotionDataset
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.physdiff import FeatureProjector
from physmotion.errors import PhysmotionError
from physmotion.features.humanml3d import SLICES, extract_features, recover_from_ric
from physmotion.metrics.physical import phys_err
from physmotion.morph.finetune import FinetuneConfig, finetune, selected_items
from physmotion.morph.floor import on_surface, selected_on_surface, features_lift
from physmotion.morph.selection import select
from physmotion.physics.humanoid import body_from_joints
from physmotion.physics.surface import HumanoidSurface
from tests.morph.fake_synth import make_synth

ROOT_Y = SLICES["root_y"].start


@pytest.fixture(scope="module")
def synth_dir(built_dir: Path, tiny_model_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_synth(built_dir, tiny_model_dir, tmp_path_factory.mktemp("synth_floor") / "synth")


@pytest.fixture(scope="module")
def test_items(built_dir: Path) -> list:
    return MotionDataset(built_dir, "test", normalize=False).items[:6]


def test_captured_motions_rise_onto_the_soles(test_items) -> None:
    # HumanML3D's floor (lowest joint at y = 0) leaves the humanoid's soles under the floor: grounding on the
    # surface lifts every captured clip by centimetres and lowers its Phys-Err on that surface.
    grounded = on_surface(test_items)
    for before, after in zip(test_items, grounded):
        lift = float(after.features[0, ROOT_Y] - before.features[0, ROOT_Y])
        assert 0.01 < lift < 0.06, (before.id, lift)
        assert lift == pytest.approx(features_lift(before.features), abs=1e-6)
        joints = recover_from_ric(before.features.astype(np.float64))
        body = HumanoidSurface(body_from_joints(joints))
        up = recover_from_ric(after.features.astype(np.float64))
        assert phys_err(up, body=body) < 0.7 * phys_err(joints, body=body), before.id
        np.testing.assert_allclose(up - joints, np.broadcast_to([0.0, lift, 0.0], up.shape), atol=1e-5)


def test_refined_keep_the_simulated_heights_and_inputs_are_grounded(synth_dir: Path) -> None:
    selection = select(synth_dir)
    items = selected_items(selection, 263)
    refined = {s.id: synth_dir / "new_joints" / f"{s.id}.npy" for s in selection.items if s.source == "refined"}
    assert 0 < len(refined) < len(items)  # the fake folder holds both kinds
    out = selected_on_surface(items, refined)
    for before, after in zip(items, out):
        if before.id in refined:
            # the simulated joints' own heights, not re-floored on their lowest joint
            sim = np.load(refined[before.id]).astype(np.float64)
            np.testing.assert_array_equal(after.features, extract_features(sim, floor=False)[0])
        else:
            lift = after.features[:, ROOT_Y] - before.features[:, ROOT_Y]
            assert np.allclose(lift, features_lift(before.features), atol=1e-6) and lift[0] > 0.01


def test_finetuned_model_records_its_floor(tiny_model_dir, synth_dir, built_dir, tmp_path) -> None:
    cfg = FinetuneConfig(model=str(tiny_model_dir), synth=str(synth_dir), data=str(built_dir),
                         out=str(tmp_path / "surface"), steps=2, checkpoint_minutes=60.0)  # fmt: skip
    assert cfg.floor == FLOOR_SURFACE
    finetune(cfg, progress=False)
    assert MotionDiffusion.load(tmp_path / "surface").floor == FLOOR_SURFACE
    finetune(replace(cfg, out=str(tmp_path / "joints"), floor=FLOOR_JOINTS), progress=False)
    assert MotionDiffusion.load(tmp_path / "joints").floor == FLOOR_JOINTS
    assert MotionDiffusion.load(tiny_model_dir).floor == FLOOR_JOINTS  # a model without the key: HumanML3D's
    with pytest.raises(PhysmotionError, match="--floor must be one of"):
        finetune(replace(cfg, out=str(tmp_path / "bad"), floor="feet"), progress=False)
    assert not (tmp_path / "bad").exists()


def test_unknown_floor_in_a_model_folder_is_one_line(tiny_model_dir: Path, tmp_path: Path) -> None:
    folder = tmp_path / "model"
    shutil.copytree(tiny_model_dir, folder)
    config = json.loads((folder / "config.json").read_text())
    config["info"]["floor"] = "ceiling"
    (folder / "config.json").write_text(json.dumps(config))
    with pytest.raises(PhysmotionError, match="unknown floor convention 'ceiling'") as err:
        MotionDiffusion.load(folder)
    assert "\n" not in str(err.value)


def test_projection_input_is_the_data_convention(tiny_model, test_items) -> None:
    joints = [recover_from_ric(it.features.astype(np.float64)) for it in test_items[:2]]
    lifted = [j + [0.0, 0.03, 0.0] for j in joints]
    assert all(a is b for a, b in zip(FeatureProjector(tiny_model).data_floor(joints), joints))
    surface_model = replace(tiny_model, info={**tiny_model.info, "floor": FLOOR_SURFACE})
    for back, j in zip(FeatureProjector(surface_model).data_floor(lifted), joints):
        np.testing.assert_allclose(back, j - [0.0, j[..., 1].min(), 0.0], atol=1e-9)
