"""Inversion refinement: DDIM-invert a motion part of the way into the diffusion, then denoise it back.

BioMoDiffuse Sec. 3.5, Eq. 10-11: a motion x_0 (e.g. a pose estimator's jittery output) is mapped by
deterministic DDIM inversion to x_t at t = strength * T, and the deterministic DDIM sampler (eta 0, with
classifier-free guidance) brings it back to a refined x_0. With a BioMoDiffuse model (``arch="biomo"``)
both directions also use its physics guidance (:func:`physmotion.diffusion.samplers.guided_x0`), as the
paper's "forward diffusion with our physics guidance"; other models have no physical network.

The schedules mirror :func:`physmotion.diffusion.schedule.sampling_scheduler`'s ``ddim`` (cosine betas,
x0 prediction, trailing spacing, alpha 1 at the end): inversion runs on diffusers' ``DDIMInverseScheduler``
with the same settings, so both directions visit the same timesteps (19, 39, ... for 50 steps).

Conventions: the model works on 20 fps features; input at another rate is resampled by linear
interpolation of the joints in time. The features re-target the motion onto the dataset's uniform
skeleton and canonicalise it (floor, origin, facing +Z); the refined joints are put back into the
input's frame by the yaw + translation that best maps the canonical input onto the input. HumanML3D's
root is integrated from per-frame velocities, so small errors in them drift the refined path away from
the input's (tens of centimetres over a clip); the slow part of the heading and of the ground-plane root
path is therefore taken from the input (``anchor_hz``, a complementary filter: the model refines the fast
part, where jitter lives, and the input keeps the slow part, where it has none).

By default refine also treats the input as a noisy observation (``smooth_hz``): it is low-passed before
inversion, the model's result is placed frame by frame onto the smoothed input (yaw + translation), and
the two are averaged joint by joint with inverse-variance weights estimated from the motion itself: the
smoothed input's noise from what the filter removed, the model's error from how far it lands from the
smoothed input (a Wiener-style fusion of two estimates, as the data-consistency step of diffusion
inverse solvers). The paper's plain inversion (``smooth_hz=None``) loses to the low-pass filter alone on
jittery clips (docs/decisions/biomodiffuse.md: "refine fused with the smoothed input").
Motions longer than the model's ``max_frames`` (196 frames, 9.8 s at 20 fps) are refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np
import torch
from scipy.signal import butter, filtfilt, freqz

from physmotion.conventions import FLOOR_SURFACE, FPS, MIN_FRAMES
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.physdiff import joints_to_features
from physmotion.diffusion.samplers import SamplerConfig, default_sampler, guided_x0
from physmotion.diffusion.schedule import DiffusionConfig, sampling_scheduler
from physmotion.errors import PhysmotionError, ShapeError
from physmotion.features.humanml3d import raise_features, recover_from_ric
from physmotion.physics.humanoid import body_from_joints
from physmotion.physics.surface import surface_lift
from physmotion.skeleton import facing_direction
from physmotion.text.encoder import load_text_encoder


@dataclass
class RefineConfig:
    """strength: share of the DDIM steps inverted, in [0, 1] (0 returns the input, re-targeted onto the
    dataset's skeleton); steps: DDIM steps of the full schedule; cfg_scale: guidance of the denoising
    half; text: caption to condition on ("" = unconditional); phys_scale: physics guidance of a
    BioMoDiffuse model (None: the model's sampling default, Eq. 11's "forward diffusion with our physics
    guidance"; other models have none); smooth_hz: cut-off (Hz) of the low-pass applied to the input
    before inversion, whose result is then fused with the model's (None: the paper's plain inversion;
    docs/decisions/biomodiffuse.md "refine fused with the smoothed input"); anchor_hz: without smoothing, the
    cut-off below which heading and root path follow the input (None: only one yaw + translation for the whole
    clip; docs/decisions/biomodiffuse.md "refine keeps the input's path")."""

    strength: float = 0.3
    steps: int = 50
    cfg_scale: float = 2.5
    text: str = ""
    phys_scale: float | None = None
    smooth_hz: float | None = 4.0
    anchor_hz: float | None = 1.0

    def check(self) -> None:
        if not (np.isfinite(self.strength) and 0.0 <= self.strength <= 1.0):
            raise PhysmotionError(f"strength must be in [0, 1], got {self.strength:g}")
        for name in ("smooth_hz", "anchor_hz"):
            hz = getattr(self, name)
            if hz is not None and not (np.isfinite(hz) and 0.0 < hz < FPS / 2):
                raise PhysmotionError(f"{name} must be between 0 and {FPS / 2:g} (Nyquist), got {hz:g}")
        if not 1 <= self.steps <= 1000:
            raise PhysmotionError(f"steps must be between 1 and 1000, got {self.steps}")
        SamplerConfig(cfg_scale=self.cfg_scale, phys_scale=self.phys_scale).check()  # the guidance scales

    @property
    def inverted_steps(self) -> int:
        """Steps inverted and denoised again: round(strength * steps), at least 1 unless strength is 0."""
        return max(1, round(self.strength * self.steps)) if self.strength > 0 else 0


def check_motion(joints: np.ndarray, fps: float, model: MotionDiffusion) -> np.ndarray:
    """Validate a motion for :func:`refine`; returns its joints (T', 22, 3) float64 at the model's 20 fps."""
    joints = np.asarray(joints)
    if joints.ndim != 3 or joints.shape[1:] != (22, 3):
        raise ShapeError(f"joints must be (T, 22, 3), got {joints.shape}")
    if not np.isfinite(joints).all():
        raise ShapeError("the motion has NaN or infinite joint positions")
    if not (np.isfinite(fps) and fps > 0):
        raise ShapeError(f"fps must be positive, got {fps}")
    out = _resample(joints.astype(np.float64), float(fps), FPS)
    hi = model.denoiser.max_frames
    if not MIN_FRAMES <= len(out) <= hi:
        raise ShapeError(f"the motion has {len(out)} frames at {FPS} fps; refine takes {MIN_FRAMES}..{hi} "
                         f"({MIN_FRAMES / FPS:g}..{hi / FPS:g} s)")  # fmt: skip
    return out


@torch.no_grad()
def refine(model: MotionDiffusion, joints: np.ndarray, fps: float, config: RefineConfig | None = None) -> np.ndarray:
    """Refine a motion by DDIM inversion to ``strength`` and deterministic DDIM denoising back.

    joints: (T, 22, 3) metres, Y up, at ``fps``. Returns (T', 22, 3) float32 at 20 fps (T' = T for 20 fps
    input), in the input's frame: on the dataset's uniform skeleton, or with ``smooth_hz`` the fusion of
    the model's motion on it and the smoothed input. Deterministic.
    Raises PhysmotionError / ShapeError (one line) for NaN, a wrong shape, a length outside
    MIN_FRAMES..max_frames at 20 fps, or a strength outside [0, 1].
    """
    cfg = config or RefineConfig()
    cfg.check()
    SamplerConfig(phys_scale=cfg.phys_scale).check_model(model)
    pos = check_motion(joints, fps, model)
    k = cfg.inverted_steps
    smooth = cfg.smooth_hz is not None and k > 0
    src = low_pass(pos, cfg.smooth_hz) if smooth else pos
    dim = model.denoiser.feature_dim
    feats = joints_to_features(src, dim)  # T rows: the last one extrapolated (physdiff's convention)
    if model.floor == FLOOR_SURFACE:  # a model that learned the soles on the floor sees the input so too
        lowest = recover_from_ric(feats.astype(np.float64))
        feats = raise_features(feats, surface_lift(lowest, body_from_joints(lowest)))
    # the input as the features hold it (canonical frame; the extrapolated frame can move the floor)
    canonical = recover_from_ric(feats.astype(np.float64))
    rot, shift = _yaw_fit(canonical, src)
    if not k:  # strength 0: nothing to refine, the input as the features hold it, back in its frame
        return (canonical @ rot.T + shift).astype(np.float32)
    device = next(model.net.parameters()).device
    x = torch.from_numpy(model.normalizer.normalize(feats)).float()[None].to(device)
    phys = cfg.phys_scale if cfg.phys_scale is not None else default_sampler(model).phys_scale
    guide = _Guide(model, cfg.text, device, len(pos), phys)
    x = _invert(x, guide, k, cfg.steps, model.diffusion)
    x = _denoise(x, guide, k, cfg.steps, cfg.cfg_scale, model.diffusion)
    out = recover_from_ric(model.normalizer.denormalize(x[0].float().cpu().numpy()).astype(np.float64))
    out = out @ rot.T + shift
    if smooth:
        out = fuse(out, src, pos, cfg.smooth_hz)
    elif cfg.anchor_hz is not None:
        out = _anchor_path(out, pos, cfg.anchor_hz)
    return out.astype(np.float32)


def low_pass(joints: np.ndarray, cutoff_hz: float, fps: float = FPS) -> np.ndarray:
    """(T, 22, 3) -> the same, zero-phase 4th-order Butterworth low-pass along time (scipy's filtfilt):
    no delay, and the usual smoother of captured trajectories (the baseline of results/refine.md)."""
    b, a = butter(4, cutoff_hz / (fps / 2))
    return filtfilt(b, a, joints, axis=0, padlen=min(3 * max(len(a), len(b)), len(joints) - 1))


def fuse(model_out: np.ndarray, smooth: np.ndarray, raw: np.ndarray, cutoff_hz: float,
         fps: float = FPS) -> np.ndarray:  # fmt: skip
    """Inverse-variance fusion of the model's motion with the smoothed input, all (T, 22, 3).

    ``model_out`` is placed frame by frame onto ``smooth`` (yaw + translation, least squares), then
    ``w * placed + (1 - w) * smooth`` with w = v_s / max(d^2, v_s): v_s is the smoothed input's noise
    variance (the white noise that ``raw - smooth`` implies, times the share of it the filter passes) and
    d^2 the mean squared distance of the placed motion from ``smooth``, which is v_s plus the model's own
    error variance if the two errors are independent. A clean input gives w near 0 (the input stays), a
    jittery one hands more of the motion to the model.
    """
    placed = _place_frames(model_out, smooth)
    passed, removed = _noise_shares(cutoff_hz, fps)
    v_s = float(np.mean((raw - smooth) ** 2)) / removed * passed
    d2 = float(np.mean((placed - smooth) ** 2))
    w = v_s / d2 if d2 > v_s else 1.0
    return w * placed + (1.0 - w) * smooth


def _noise_shares(cutoff_hz: float, fps: float) -> tuple[float, float]:
    """Of white noise, the variance shares that :func:`low_pass` keeps and removes (its zero-phase gain
    |H|^2 averaged over frequency: mean |H|^4 and mean (1 - |H|^2)^2)."""
    b, a = butter(4, cutoff_hz / (fps / 2))
    gain = np.abs(freqz(b, a, worN=4096)[1]) ** 2
    return float(np.mean(gain**2)), float(np.mean((1.0 - gain) ** 2))


def _place_frames(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """``src`` (T, 22, 3) turned about Y and shifted, each frame on its own, to best match ``dst``."""
    a = src - src.mean(axis=1, keepdims=True)
    b = dst - dst.mean(axis=1, keepdims=True)
    theta = _best_yaw(a, b)[:, None]  # (T, 1)
    c, s = np.cos(theta), np.sin(theta)
    turned = np.stack([c * a[..., 0] + s * a[..., 2], a[..., 1], -s * a[..., 0] + c * a[..., 2]], axis=-1)
    return turned + dst.mean(axis=1, keepdims=True)


class _Guide:
    """The model's x0 prediction for one motion, guided: uncond + s (cond - uncond); uncond only for "";
    physics guidance on top for a BioMoDiffuse model (:func:`guided_x0`)."""

    def __init__(self, model: MotionDiffusion, text: str, device: torch.device, frames: int,
                 phys_scale: float | None = None) -> None:  # fmt: skip
        self.model, self.text, self.phys_scale = model, text.strip(), phys_scale
        # with no caption every pass drops the text (the null condition); any caption fills the slot
        self.enc = load_text_encoder(model.text_encoder).encode([self.text or "a person"]).to(device)
        self.mask = torch.ones(1, frames, dtype=torch.bool, device=device)
        self.device = device

    def __call__(self, x: torch.Tensor, t: int, scale: float) -> torch.Tensor:
        tt = torch.full((1,), int(t), device=self.device)
        with_text = bool(self.text) and scale != 0.0
        return guided_x0(self.model.net, x, tt, self.enc, self.mask, scale, with_text=with_text,
                         phys_scale=self.phys_scale)  # fmt: skip


def _inverse_scheduler(steps: int, diffusion: DiffusionConfig):
    """diffusers' DDIMInverseScheduler with the settings of schedule.sampling_scheduler's ``ddim``."""
    from diffusers import DDIMInverseScheduler

    sched = DDIMInverseScheduler(num_train_timesteps=diffusion.num_train_timesteps,
                                 beta_schedule=diffusion.beta_schedule, prediction_type="sample",
                                 clip_sample=False, set_alpha_to_one=True, timestep_spacing="trailing")  # fmt: skip
    sched.set_timesteps(steps)
    return sched


def _invert(x: torch.Tensor, guide: _Guide, k: int, steps: int, diffusion: DiffusionConfig) -> torch.Tensor:
    """x_0 (1, T, D) normalised -> x at the k-th timestep of the schedule (deterministic DDIM inversion).

    Each step x_t -> x_t' reads the model's x0 at the current level t, as Eq. 10 writes it (diffusers'
    pipelines read it at t' instead). The first step starts at alpha = 1, where an x0-predicting model's
    noise (x - sqrt(a) x0) / sqrt(1 - a) is 0/0 and the library would divide by zero: there the input is
    its own x0 and the noise is taken as 0, i.e. x_t1 = sqrt(a_t1) x_0.
    """
    sched = _inverse_scheduler(steps, diffusion)
    ts = [int(t) for t in sched.timesteps[:k]]
    x = sched.alphas_cumprod[ts[0]].sqrt().to(x) * x
    for prev, t in pairwise(ts):
        x0 = guide(x, prev, 1.0)  # inversion with the plain (conditional or unconditional) prediction
        x = sched.step(x0, t, x).prev_sample
    return x


def _denoise(x: torch.Tensor, guide: _Guide, k: int, steps: int, scale: float, diffusion: DiffusionConfig) -> torch.Tensor:
    """x at the k-th timestep -> x_0 by the last k steps of deterministic DDIM (eta 0), guided (Eq. 11)."""
    sched = sampling_scheduler("ddim", steps, diffusion)
    for t in sched.timesteps[len(sched.timesteps) - k :]:
        x0 = guide(x, int(t), scale)
        x = sched.step(x0, t, x, eta=0.0).prev_sample
    return x


def _anchor_path(out: np.ndarray, ref: np.ndarray, hz: float) -> np.ndarray:
    """``out`` (T, 22, 3) with the slow part of ``ref``'s (T, 22, 3) heading and ground-plane root path.

    The per-frame heading difference (HumanML3D's facing direction) and root offset in x, z are low-passed
    below ``hz`` (zero-phase Butterworth, order 2) and applied: each frame turned about its root, then
    shifted. Root height and the pose about the root stay the model's.
    """
    b, a = butter(2, hz / (FPS / 2))
    f_ref, f_out = facing_direction(ref), facing_direction(out)
    turn = np.unwrap(np.arctan2(f_ref[:, 0], f_ref[:, 2])) - np.unwrap(np.arctan2(f_out[:, 0], f_out[:, 2]))
    turn = filtfilt(b, a, turn)
    c, s = np.cos(turn)[:, None], np.sin(turn)[:, None]
    rel = out - out[:, :1]
    x, z = c * rel[..., 0] + s * rel[..., 2], -s * rel[..., 0] + c * rel[..., 2]
    turned = out[:, :1] + np.stack([x, rel[..., 1], z], axis=-1)
    shift = filtfilt(b, a, ref[:, 0] - turned[:, 0], axis=0)
    shift[:, 1] = 0.0
    return turned + shift[:, None]


def _resample(joints: np.ndarray, fps: float, target: float) -> np.ndarray:
    """(T, 22, 3) at fps -> (T', 22, 3) at target, linear in time over the same duration."""
    if abs(fps - target) < 1e-9:
        return joints
    src = np.arange(len(joints)) / fps
    dst = np.arange(int(np.floor(src[-1] * target + 1e-9)) + 1) / target
    flat = joints.reshape(len(joints), -1)
    out = np.stack([np.interp(dst, src, flat[:, c]) for c in range(flat.shape[1])], axis=1)
    return out.reshape(len(dst), 22, 3)


def _yaw_fit(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation about Y (3, 3) and shift (3,) minimising sum |R src + s - dst|^2 over frames and joints."""
    a = src.reshape(-1, 3) - src.reshape(-1, 3).mean(0)
    b = dst.reshape(-1, 3) - dst.reshape(-1, 3).mean(0)
    theta = _best_yaw(a, b)
    c, s = np.cos(theta), np.sin(theta)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    shift = dst.reshape(-1, 3).mean(0) - src.reshape(-1, 3).mean(0) @ rot.T
    return rot, shift


def _best_yaw(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The angle about Y that best turns the centred points ``a`` onto ``b`` (..., P, 3), over the P axis.

    R = [[c, 0, s], [0, 1, 0], [-s, 0, c]]: maximise c * sum(ax bx + az bz) + s * sum(az bx - ax bz)."""
    return np.arctan2(np.sum(a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2], axis=-1),
                      np.sum(a[..., 0] * b[..., 0] + a[..., 2] * b[..., 2], axis=-1))  # fmt: skip
