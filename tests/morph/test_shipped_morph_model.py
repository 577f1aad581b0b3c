"""The shipped Morph-tuned model (physmotion/weights/morph): loads, says what it saw, and generates."""

from pathlib import Path

import numpy as np

from physmotion.checkpoint import weights_sha256
from physmotion.conventions import FLOOR_SURFACE
from physmotion.diffusion.model import DEFAULT_MODEL_DIR, MotionDiffusion
from physmotion.generate import GenerateConfig, generate
from physmotion.text.vocabulary import load_vocabulary

MORPH_DIR = Path(DEFAULT_MODEL_DIR).parent / "morph"


def test_morph_model_card_facts_and_generation() -> None:
    model = MotionDiffusion.load(MORPH_DIR)
    info = model.info["morph"]
    assert info["rounds"] == 1 and info["selected"] == {"refined": 430, "input": 41}  # one round, as the card
    assert info["mix"] == 0.1 and info["synthetic_items"] == 471  # every synthetic motion long enough to train on
    # fine-tuned from the shipped default, with its caption rewrites (the base run's settings)
    assert info["base_model_sha256"] == weights_sha256(DEFAULT_MODEL_DIR)
    assert model.info["train"]["caption_aug"] == model.info["base_info"]["train"]["caption_aug"] == 0.5
    assert model.floor == FLOOR_SURFACE  # fine-tuned with the soles on the floor
    # the base's NC and SA data carry through, each tag on its own
    assert model.licence_tag == "NC,SA" and model.info["licence_tags"] == ["NC", "SA", "open"]
    vocabulary = load_vocabulary(MORPH_DIR)
    assert vocabulary is not None and load_vocabulary(DEFAULT_MODEL_DIR) <= vocabulary
    cfg = GenerateConfig(seconds=2.0, physics="none", seed=0)
    cfg.sampler.steps = 5
    out = generate(["a person walks forward"], cfg, model)
    joints = out.motions[0].joints
    assert joints.shape == (40, 22, 3) and np.isfinite(joints).all() and out.motions[0].licence_tag == "NC,SA"
