"""Model folders on disk: ``model.safetensors`` (weights plus the feature normaliser) and ``config.json``.

One format for every network we ship (the denoiser, the evaluator), so that loading errors read alike and
writes are atomic in one place.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from physmotion.errors import PhysmotionError
from physmotion.features.normalize import Normalizer
from physmotion.motion import write_atomic

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"


def weights_sha256(folder: str | Path) -> str:
    """Hex sha256 of a model folder's weights file: the identity of a model (Morph's synthetic sets name
    the model that made them by it)."""
    import hashlib

    h = hashlib.sha256()
    with open(Path(folder) / WEIGHTS_FILE, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def save_folder(folder: str | Path, net: torch.nn.Module, normalizer: Normalizer, config: dict) -> None:
    """Write ``net``'s weights with ``normalizer.mean``/``normalizer.std`` and ``config`` atomically."""
    from safetensors.torch import save

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().float().cpu().contiguous() for k, v in net.state_dict().items()}
    tensors["normalizer.mean"] = torch.from_numpy(normalizer.mean.astype(np.float32))
    tensors["normalizer.std"] = torch.from_numpy(normalizer.std.astype(np.float32))
    write_atomic(folder / WEIGHTS_FILE, lambda f: f.write(save(tensors)))
    write_atomic(folder / CONFIG_FILE, lambda f: f.write(json.dumps(config, indent=2)), "w")


def load_folder(folder: str | Path, build, device: str = "cpu") -> tuple[torch.nn.Module, Normalizer, dict]:
    """Read a model folder. ``build(config) -> nn.Module`` makes the empty network the weights go into.

    Returns (network in eval mode on ``device``, normaliser, config). A missing, truncated or mismatched
    folder raises :class:`PhysmotionError` with one line naming it.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    folder = Path(folder)
    weights, config_path = folder / WEIGHTS_FILE, folder / CONFIG_FILE
    if not weights.is_file() or not config_path.is_file():
        raise PhysmotionError(f"{folder}: no model checkpoint ({WEIGHTS_FILE} and {CONFIG_FILE} expected)")
    try:
        config = json.loads(config_path.read_text())
        tensors = load_file(str(weights), device=device)
        mean, std = tensors.pop("normalizer.mean"), tensors.pop("normalizer.std")
        net = build(config)
        net.load_state_dict(tensors)
    except (SafetensorError, json.JSONDecodeError, KeyError, TypeError, RuntimeError, OSError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise PhysmotionError(f"{folder}: unreadable model checkpoint ({first})") from None
    return net.to(device).eval(), Normalizer(mean.cpu().numpy(), std.cpu().numpy()), config
