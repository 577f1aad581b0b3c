"""The learned imitation controller: a policy network that corrects the model-based tracker's PD targets.

PhysDiff's P and Morph's motion physics refinement are learned imitation policies acting through the
body's joints. Ours is residual over the tracker (``physics/tracking.py``): the network adds bounded
offsets (``action_scale`` rad) to the tracker's PD targets, so a zero output is the tracker exactly and
training starts from it (docs/decisions/projection.md: "a learned residual policy over the tracker").
The tracker's root residual stays, capped at ``cap`` x its default bounds; the policy sees the cap, is
trained over a range of caps, and P runs it at a small one (``PolicySettings.cap``).

Inference is numpy only: P runs in worker processes that must not import torch (``physics/workers.py``),
and one observation per control step costs about 0.1 ms through three small matrices.

Observation (:func:`observe`), all in the pelvis heading frame (yaw taken out), MuJoCo axes:
root height (1), gravity in the pelvis frame (3), root linear (3) and angular (3) velocity, the 63 hinge
angles and their velocities x 0.1, the 22 bodies relative to the pelvis (66); for each of the reference
steps k+1, k+2, k+4: reference bodies minus simulated bodies (66), reference minus simulated hinges (63),
the reference root velocity (3); the cap (1). 599 numbers.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.paths import WEIGHTS_DIR
from physmotion.physics.humanoid import layout
from physmotion.physics.tracking import ModelBasedTracker, Reference, TrackingConfig

LOOKAHEAD = (1, 2, 4)  # reference control steps ahead that the policy sees
NUM_ACTIONS = 63  # one offset per hinge
OBS_DIM = 1 + 3 + 3 + 3 + 63 + 63 + 66 + len(LOOKAHEAD) * (66 + 63 + 3) + 1


@dataclass(frozen=True)
class PolicySettings:
    """How a policy acts; stored with its weights (``settings.json``) so P runs it as it was trained."""

    action_scale: float = 0.15  # rad: an action of 1 moves a PD target by this much
    cap: float = 0.25  # P's root residual bound as a multiple of TrackingConfig's (0.25: 0.05 W)
    tracking: TrackingConfig = TrackingConfig()


def capped_tracking(tracking: TrackingConfig, cap: float) -> TrackingConfig:
    """``tracking`` with its root residual bounds (force, torque, lift) multiplied by ``cap`` >= 0."""
    return replace(tracking, residual_force=tracking.residual_force * cap,
                   residual_torque=tracking.residual_torque * cap,
                   residual_lift=tracking.residual_lift * cap)  # fmt: skip


def _heading(xmat_pelvis: np.ndarray) -> np.ndarray:
    """(3, 3) rotation world -> heading frame: the pelvis's yaw about z taken out."""
    fwd_x, fwd_y = xmat_pelvis[0], xmat_pelvis[3]  # world x, y of the pelvis's local x axis (row-major)
    yaw = math.atan2(fwd_y, fwd_x)
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def observe(model, data, ref: Reference, k: int, cap: float) -> np.ndarray:
    """The policy's observation (599,) float32 of the simulation ``data`` at control step ``k`` of ``ref``."""
    lay = layout(model)
    pelvis = lay.body_ids[0]
    rot = data.xmat[pelvis]
    head = _heading(rot)
    r = rot.reshape(3, 3)
    xpos = data.xpos[lay.body_ids]  # (22, 3)
    hinges, hvel = data.qpos[7:], data.qvel[6:]
    parts = [
        data.qpos[2:3],
        -r[2],  # gravity (0, 0, -1) in the pelvis frame: R^T g
        head @ data.qvel[:3],
        data.qvel[3:6],  # the free joint's angular velocity is already local
        hinges,
        0.1 * hvel,
        ((xpos - xpos[0]) @ head.T).ravel(),
    ]
    last = len(ref.qpos) - 1
    for ahead in LOOKAHEAD:
        j = min(k + ahead, last)
        parts += [((ref.joints_mj[j] - xpos) @ head.T).ravel(), ref.qpos[j, 7:] - hinges, head @ ref.qvel[j, :3]]
    parts.append(np.array([cap]))
    return np.concatenate(parts).astype(np.float32)


class PolicyNetwork:
    """The actor's mean as numpy: observation normalisation, then an ELU MLP.

    weights: ``obs_mean`` (599,), ``obs_std`` (599,), ``layers.{i}.weight`` (out, in), ``layers.{i}.bias``.
    """

    def __init__(self, weights: dict[str, np.ndarray]) -> None:
        self.mean = weights["obs_mean"].astype(np.float32)
        self.std = weights["obs_std"].astype(np.float32)
        n = len({k.split(".")[1] for k in weights if k.startswith("layers.")})
        self.layers = [(weights[f"layers.{i}.weight"].T.astype(np.float32).copy(),
                        weights[f"layers.{i}.bias"].astype(np.float32)) for i in range(n)]  # fmt: skip
        if self.mean.shape != (OBS_DIM,) or self.layers[-1][1].shape != (NUM_ACTIONS,):
            raise PhysmotionError(
                f"policy weights do not fit this humanoid: {self.mean.shape[0]} observations and "
                f"{self.layers[-1][1].shape[0]} actions, expected {OBS_DIM} and {NUM_ACTIONS}"
            )

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Actions (..., 63) for observations (..., 599)."""
        h = (obs - self.mean) / self.std
        for i, (w, b) in enumerate(self.layers):
            h = h @ w + b
            if i < len(self.layers) - 1:
                h = np.where(h > 0, h, np.expm1(np.minimum(h, 0)))  # ELU
        return h


@dataclass
class Policy:
    """A trained imitation policy: its network and how it acts."""

    network: PolicyNetwork
    settings: PolicySettings
    card: dict

    def controller(self, model, cap: float | None = None) -> PolicyController:
        """A :class:`~physmotion.physics.tracking.Controller` for ``model`` (at the settings' cap unless
        ``cap`` is given)."""
        return PolicyController(model, self, self.settings.cap if cap is None else cap)


class PolicyController:
    """The tracker with the policy's offsets added to its PD targets; the root residual capped at ``cap``."""

    def __init__(self, model, policy: Policy, cap: float) -> None:
        self.model = model
        self.policy = policy
        self.cap = float(cap)
        self.tracker = ModelBasedTracker(model, capped_tracking(policy.settings.tracking, self.cap))
        self.joints_through_actuators = self.tracker.joints_through_actuators

    def act(self, data, ref: Reference, k: int) -> tuple[np.ndarray, np.ndarray]:
        ctrl, qfrc = self.tracker.act(data, ref, k)
        action = self.policy.network(observe(self.model, data, ref, k, self.cap))
        return ctrl + self.policy.settings.action_scale * np.clip(action, -1.0, 1.0), qfrc

    def residual(self, data, ref: Reference, step: int, substeps: int) -> np.ndarray:
        return self.tracker.residual(data, ref, step, substeps)

    def caps(self) -> tuple[float, float, float]:
        return self.tracker.caps()


DEFAULT_POLICY = WEIGHTS_DIR / "imitator"


def load_policy(path: str | Path | None = None) -> Policy:
    """A policy folder (``policy.safetensors``, ``settings.json``, ``card.json``); the shipped one by default.

    Raises PhysmotionError naming what is missing or malformed.
    """
    from safetensors.numpy import load_file

    folder = Path(path) if path is not None else DEFAULT_POLICY
    weights_file, settings_file = folder / "policy.safetensors", folder / "settings.json"
    for f in (weights_file, settings_file):
        if not f.is_file():
            raise PhysmotionError(f"not an imitation policy folder: {f} is missing")
    try:
        weights = load_file(str(weights_file))
        raw = json.loads(settings_file.read_text())
        settings = PolicySettings(action_scale=float(raw["action_scale"]), cap=float(raw["cap"]),
                                  tracking=TrackingConfig(**raw["tracking"]))  # fmt: skip
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise PhysmotionError(f"cannot read the imitation policy in {folder}: {e}") from None
    card_file = folder / "card.json"
    card = json.loads(card_file.read_text()) if card_file.is_file() else {}
    return Policy(PolicyNetwork(weights), settings, card)


def settings_dict(settings: PolicySettings) -> dict:
    """``settings.json``'s content for ``settings``."""
    return asdict(settings)
