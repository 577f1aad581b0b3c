"""A trained text-to-motion model as one object: denoiser + its configs + the data's Mean/Std.

On disk a model is a folder: ``model.safetensors`` (the EMA weights, plus ``normalizer.mean`` and
``normalizer.std``) and ``config.json`` (denoiser and diffusion configs, text encoder, training data and
its licence tags). The shipped default lives in ``physmotion/models/default``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from physmotion.diffusion.denoiser import DenoiserConfig, build_denoiser
from physmotion.diffusion.schedule import DiffusionConfig
from physmotion.errors import PhysmotionError
from physmotion.features.normalize import Normalizer
from physmotion.motion import write_atomic

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
DEFAULT_MODEL_DIR = Path(__file__).resolve().parent.parent / "models" / "default"


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
        """"NC" when any training clip was non-commercial, else "open"."""
        return "NC" if "NC" in self.info.get("licence_tags", []) else "open"

    def save(self, folder: str | Path) -> None:
        """Write weights and config atomically into ``folder``."""
        from safetensors.torch import save

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        tensors = {k: v.detach().float().cpu().contiguous() for k, v in self.net.state_dict().items()}
        tensors["normalizer.mean"] = torch.from_numpy(self.normalizer.mean.astype(np.float32))
        tensors["normalizer.std"] = torch.from_numpy(self.normalizer.std.astype(np.float32))
        write_atomic(folder / WEIGHTS_FILE, lambda f: f.write(save(tensors)))
        config = {"denoiser": self.denoiser.to_dict(), "diffusion": self.diffusion.to_dict(),
                  "text_encoder": self.text_encoder, "info": self.info}  # fmt: skip
        write_atomic(folder / CONFIG_FILE, lambda f: f.write(json.dumps(config, indent=2)), "w")

    @classmethod
    def load(cls, folder: str | Path | None = None, device: str = "cpu") -> MotionDiffusion:
        """Load a model folder (default: the shipped model). Raises PhysmotionError if it is missing or broken."""
        from safetensors import SafetensorError
        from safetensors.torch import load_file

        folder = Path(folder) if folder is not None else DEFAULT_MODEL_DIR
        weights, config_path = folder / WEIGHTS_FILE, folder / CONFIG_FILE
        if not weights.is_file() or not config_path.is_file():
            raise PhysmotionError(f"{folder}: no model checkpoint ({WEIGHTS_FILE} and {CONFIG_FILE} expected)")
        try:
            config = json.loads(config_path.read_text())
            tensors = load_file(str(weights), device=device)
            mean, std = tensors.pop("normalizer.mean"), tensors.pop("normalizer.std")
            den = DenoiserConfig(**config["denoiser"])
            net = build_denoiser(den)
            net.load_state_dict(tensors)
        except (SafetensorError, json.JSONDecodeError, KeyError, TypeError, RuntimeError, OSError) as exc:
            first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise PhysmotionError(f"{folder}: unreadable model checkpoint ({first})") from None
        return cls(net=net.to(device).eval(), denoiser=den, diffusion=DiffusionConfig(**config["diffusion"]),
                   normalizer=Normalizer(mean.cpu().numpy(), std.cpu().numpy()),
                   text_encoder=config.get("text_encoder", "minilm"), info=config.get("info", {}))  # fmt: skip
