"""The shipped Morph-tuned model (physmotion/weights/morph, the default): loads, says what it saw, and
generates."""

import numpy as np

from physmotion.checkpoint import weights_sha256
from physmotion.conventions import FLOOR_SURFACE
from physmotion.diffusion.model import BASE_MODEL_DIR, DEFAULT_MODEL_DIR, MotionDiffusion
from physmotion.generate import GenerateConfig, generate
from physmotion.text.vocabulary import load_vocabulary

MORPH_DIR = DEFAULT_MODEL_DIR  # generate uses it when no --model is given


def test_morph_model_card_facts_and_generation() -> None:
    model = MotionDiffusion.load(MORPH_DIR)
    info = model.info["morph"]
    assert info["rounds"] == 1 and info["selected"] == {"refined": 430, "input": 41}  # one round, as the card
    assert info["mix"] == 0.1 and info["synthetic_items"] == 471  # every synthetic motion long enough to train on
    # fine-tuned from the shipped base model, with its caption rewrites (the base run's settings)
    assert DEFAULT_MODEL_DIR.name == "morph"
    assert info["base_model_sha256"] == weights_sha256(BASE_MODEL_DIR)
    assert model.info["train"]["caption_aug"] == model.info["base_info"]["train"]["caption_aug"] == 0.5
    assert model.floor == FLOOR_SURFACE  # fine-tuned with the soles on the floor
    # the base's NC and SA data carry through, each tag on its own
    assert model.licence_tag == "NC,SA" and model.info["licence_tags"] == ["NC", "SA", "open"]
    vocabulary = load_vocabulary(MORPH_DIR)
    assert vocabulary is not None and load_vocabulary(BASE_MODEL_DIR) <= vocabulary
    cfg = GenerateConfig(seconds=2.0, physics="none", seed=0)
    cfg.sampler.steps = 5
    out = generate(["a person walks forward"], cfg, model)
    joints = out.motions[0].joints
    assert joints.shape == (40, 22, 3) and np.isfinite(joints).all() and out.motions[0].licence_tag == "NC,SA"
