"""A trained text-to-motion model as one object: denoiser + its configs + the data's Mean/Std.

On disk a model is a folder: ``model.safetensors`` (the EMA weights, plus ``normalizer.mean`` and
``normalizer.std``) and ``config.json`` (denoiser and diffusion configs, text encoder, training data and
its licence tags). The shipped default lives in ``physmotion/weights/morph``, the model it was fine-tuned
from in ``physmotion/weights/base``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import torch

from physmotion.checkpoint import load_folder, save_folder
from physmotion.conventions import FLOOR_JOINTS, FLOORS
from physmotion.nets.denoiser import DenoiserConfig, build_denoiser
from physmotion.diffusion.schedule import DiffusionConfig
from physmotion.errors import PhysmotionError
from physmotion.motion import joined_licence_tag
from physmotion.paths import BASE_MODEL, DEFAULT_MODEL, WEIGHTS_DIR
from physmotion.features.normalize import Normalizer

DEFAULT_MODEL_DIR = WEIGHTS_DIR / DEFAULT_MODEL  # what generate uses without --model
BASE_MODEL_DIR = WEIGHTS_DIR / BASE_MODEL  # trained on the captured data alone; Morph fine-tuned the default from it


@dataclass
class MotionDiffusion:
    """Denoiser network (eval mode), how it was built, and how to (de)normalise its features."""

    net: torch.nn.Module
    denoiser: DenoiserConfig
    diffusion: DiffusionConfig
    normalizer: Normalizer
    text_encoder: str = "minilm"
    info: dict = field(default_factory=dict)  # data, licence tags, training summary

    @property
    def licence_tag(self) -> str:
        """Every restriction of the training data's licences ("NC", "SA", or "NC,SA"), else "open"."""
        return joined_licence_tag(self.info.get("licence_tags", []))

    @property
    def trained_max_length(self) -> int:
        """The length filter of the model's training run (``train --max-length``; motions under it + 4
        frames were kept), else its ``max_frames``. Morph's synthetic and real data keep to it."""
        limit = self.info.get("train", {}).get("max_length", self.denoiser.max_frames)
        return min(int(limit), self.denoiser.max_frames)

    @property
    def floor(self) -> str:
        """The floor convention its samples stand in (:data:`~physmotion.conventions.FLOORS`): HumanML3D's
        lowest joint on y = 0, unless the model was fine-tuned on motions with the soles on the floor."""
        return self.info.get("floor", FLOOR_JOINTS)

    def save(self, folder: str | Path) -> None:
        """Write weights and config atomically into ``folder``."""
        config = {"denoiser": self.denoiser.to_dict(), "diffusion": self.diffusion.to_dict(),
                  "text_encoder": self.text_encoder, "info": self.info}  # fmt: skip
        save_folder(folder, self.net, self.normalizer, config)

    @classmethod
    def load(cls, folder: str | Path | None = None, device: str = "cpu") -> MotionDiffusion:
        """Load a model folder (default: the shipped model). Raises PhysmotionError if it is missing or broken."""
        folder = Path(folder) if folder is not None else DEFAULT_MODEL_DIR
        net, normalizer, config = load_folder(folder, _build, device)
        floor = config.get("info", {}).get("floor", FLOOR_JOINTS)
        if floor not in FLOORS:
            raise PhysmotionError(f"{folder}: unknown floor convention {floor!r} in config.json (expected one of "
                                  f"{', '.join(FLOORS)})")  # fmt: skip
        return cls(net=net, denoiser=DenoiserConfig(**config["denoiser"]),
                   diffusion=DiffusionConfig(**config["diffusion"]), normalizer=normalizer,
                   text_encoder=config.get("text_encoder", "minilm"), info=config.get("info", {}))  # fmt: skip


def _build(config: dict) -> torch.nn.Module:
    DiffusionConfig(**config["diffusion"])  # a broken diffusion section fails here, inside load_folder's guard
    return build_denoiser(DenoiserConfig(**config["denoiser"]))
