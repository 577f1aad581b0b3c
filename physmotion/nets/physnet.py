"""BioMoDiffuse's physical network (Sec. 3.2, Eq. 3-5; App. C Table 7) and the denoiser built around it.

The physical network reads the noisy 329-d motion and predicts its joint accelerations through a learned
Euler-Lagrange equation (Eq. 3/5)::

    acc = M^-1 (F + C + R ⊙ A(u))

- an **autoregressive block**: a causal GRU over the frames (each step sees frames t-1..t+1 through a
  width-3 convolution first, since an acceleration is a central difference), with the diffusion timestep
  added to its input (the network reads x_t at every noise level);
- **Motion MLP** -> z, the per-frame state the heads read; **Physics Decoder** -> the trunk of the M, F and
  C heads;
- **M_Net**: the inertia matrix, symmetric positive definite by construction: M = diag(softplus(d) + eps)
  + V V^T with V of rank ``INERTIA_RANK`` (66 x 66);
- **F_Net** (external and contact forces) and **C_Net** (Coriolis and gravity), 66 each;
- **Pose2EMG** -> u, 8 muscle activations per frame. The paper pre-trains it on MIA's EMG; we supervise it
  with our inverse-dynamics stand-ins (:mod:`physmotion.physics.activations`), so it learns the joint
  effort our humanoid needs. **Muscle MLP** embeds the 8 channels as 8 tokens, and the frame's state
  attends to them (cross-attention, as the paper models R ⊙ A(u)); the **Muscle Decoder** maps the result
  to the 66-d internal force.

The acceleration comes out in m/s^2, in the root frame of each frame, the same quantity as the 329-d
vector's ``joint_acc`` group (:mod:`physmotion.features.biomech`, which is in metres per frame^2).

:class:`BioMoDenoiser` (``arch="biomo"``) feeds the network's acceleration, times the speed control
signal (Sec. 3.4: 1 in training, ``--speed`` at inference), and a "physics present" channel to the 1D
UNet beside x_t (the paper's Fig. 2). Training drops the physical network with probability P_c, which
zeroes both channels, so the sampler can form physics guidance as CFG does with the text
(:mod:`physmotion.diffusion.samplers`).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from physmotion.conventions import FPS
from physmotion.nets.backbone import DenoiserConfig, timestep_embedding
from physmotion.nets.unet import UNetDenoiser
from physmotion.features.biomech import FEATURE_DIM_BIOMECH, SLICES_BIOMECH
from physmotion.physics.activations import ACTIVATION_CHANNELS
from physmotion.skeleton import NUM_JOINTS
from physmotion.text.encoder import TextFeatures

ACCEL_DIM = NUM_JOINTS * 3  # 66
MUSCLES = len(ACTIVATION_CHANNELS)  # 8
INERTIA_RANK = 8
_EPS = 1e-3


def _mlp(din: int, dout: int, hidden: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(din, hidden), nn.SiLU(), nn.Linear(hidden, dout))


class PhysicalNetwork(nn.Module):
    """x_t (B, T, 329) normalised, t (B,) -> acc (B, T, 22, 3) m/s^2 and activations u (B, T, 8).

    ``acc_mean`` / ``acc_std`` (66,) are the ``joint_acc`` part of the data's Mean/Std (metres per frame^2),
    saved with the weights; :meth:`set_feature_stats` fills them before training.
    """

    def __init__(self, feature_dim: int = FEATURE_DIM_BIOMECH, hidden: int = 128, fps: float = FPS) -> None:
        super().__init__()
        self.hidden, self.fps = hidden, fps
        self.in_conv = nn.Conv1d(feature_dim, hidden, 3, padding=1)
        self.time_mlp = nn.Sequential(nn.Linear(hidden, hidden), nn.SiLU())
        self.gru = nn.GRU(hidden, hidden, batch_first=True)
        self.motion_mlp = _mlp(hidden, hidden, hidden)
        self.pose2emg = _mlp(hidden, MUSCLES, hidden)
        self.muscle_mlp = nn.Linear(1, hidden)
        self.muscle_token = nn.Parameter(torch.randn(MUSCLES, hidden) * 0.02)  # which channel a token is
        self.attn = nn.MultiheadAttention(hidden, 4, batch_first=True)
        self.muscle_decoder = nn.Linear(hidden, ACCEL_DIM)
        self.physics_decoder = _mlp(hidden, hidden, hidden)
        self.m_net = nn.Linear(hidden, ACCEL_DIM * (1 + INERTIA_RANK))
        self.f_net = _mlp(hidden, ACCEL_DIM, hidden)
        self.c_net = _mlp(hidden, ACCEL_DIM, hidden)
        self.register_buffer("acc_mean", torch.zeros(ACCEL_DIM))
        self.register_buffer("acc_std", torch.ones(ACCEL_DIM))

    def set_feature_stats(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Take the ``joint_acc`` statistics from the data's (329,) Mean/Std."""
        part = SLICES_BIOMECH["joint_acc"]
        self.acc_mean.copy_(torch.as_tensor(mean)[part])
        self.acc_std.copy_(torch.as_tensor(std)[part])

    def inertia(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The inertia factors of states z (..., hidden): diagonal d (..., 66) > 0 and V (..., 66, r)."""
        raw = self.m_net(z)
        d = F.softplus(raw[..., :ACCEL_DIM]) + _EPS
        v = raw[..., ACCEL_DIM:].unflatten(-1, (ACCEL_DIM, INERTIA_RANK)) / INERTIA_RANK**0.5
        return d, v

    @staticmethod
    def inertia_matrix(d: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """M = diag(d) + V V^T (..., 66, 66): symmetric, and positive definite since d > 0."""
        return torch.diag_embed(d) + v @ v.transpose(-1, -2)

    @staticmethod
    def solve(d: torch.Tensor, v: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        """M^-1 b for M = diag(d) + V V^T, by the Woodbury identity (an r x r solve instead of 66 x 66:
        the network evaluates it for every frame of every step, where a dense solve costs 100x more).
        d, b: (..., 66), v: (..., 66, r). Computed in float32 whatever the autocast: the LU solve has no
        bf16 kernel on CUDA, and a bf16 Woodbury correction would lose the small terms anyway."""
        with torch.autocast(d.device.type, enabled=False):
            wide = torch.promote_types(d.dtype, torch.float32)  # float64 stays float64
            d, v, b = d.to(wide), v.to(wide), b.to(wide)
            dinv_b, dinv_v = b / d, v / d[..., None]
            small = torch.eye(v.shape[-1], dtype=v.dtype, device=v.device) + v.transpose(-1, -2) @ dinv_v
            y = torch.linalg.solve(small, (v.transpose(-1, -2) @ dinv_b[..., None]))
            return dinv_b - (dinv_v @ y)[..., 0]

    def forward(
        self, x: torch.Tensor, t: torch.Tensor, mask: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """x (B, T, 329), t (B,), mask (B, T) -> acc (B, T, 22, 3) m/s^2, u (B, T, 8) in (0, 1)."""
        if mask is not None:
            x = x * mask[..., None].to(x)
        h = self.in_conv(x.transpose(1, 2)).transpose(1, 2)
        h = h + self.time_mlp(timestep_embedding(t, self.hidden))[:, None]
        h, _ = self.gru(h)
        z = self.motion_mlp(h)
        u = torch.sigmoid(self.pose2emg(z))
        b, n = z.shape[:2]
        tokens = self.muscle_mlp(u[..., None]) + self.muscle_token  # (B, T, 8, hidden)
        query = z.reshape(b * n, 1, self.hidden)
        attended, _ = self.attn(query, tokens.reshape(b * n, MUSCLES, self.hidden),
                                tokens.reshape(b * n, MUSCLES, self.hidden), need_weights=False)  # fmt: skip
        internal = self.muscle_decoder(attended.reshape(b, n, self.hidden))  # R ⊙ A(u)
        trunk = self.physics_decoder(z)
        d, v = self.inertia(trunk)
        acc = self.solve(d, v, self.f_net(trunk) + self.c_net(trunk) + internal)
        return acc.unflatten(-1, (NUM_JOINTS, 3)), u

    def to_features(self, acc: torch.Tensor) -> torch.Tensor:
        """Accelerations (B, T, 22, 3) m/s^2 -> the normalised ``joint_acc`` features (B, T, 66)."""
        per_frame = acc.flatten(-2) / self.fps**2  # m/s^2 -> metres per frame^2
        return (per_frame - self.acc_mean) / self.acc_std

    def from_features(self, feats: torch.Tensor) -> torch.Tensor:
        """Normalised ``joint_acc`` features (B, T, 66) -> accelerations (B, T, 22, 3) m/s^2."""
        return ((feats * self.acc_std + self.acc_mean) * self.fps**2).unflatten(-1, (NUM_JOINTS, 3))


class BioMoDenoiser(nn.Module):
    """BioMoDiffuse: the 1D UNet conditioned on the physical network's accelerations (``arch="biomo"``).

    x0 = f(x_t, t, text, acc(x_t)); x (B, T, 329) normalised features, mask (B, T) True on real frames.
    ``drop_phys`` (B,) bool removes the physical network's input for those rows (P_c dropout, and the
    "without physics" half of physics guidance); ``speed`` scales its accelerations (the speed control
    signal, 1 in training).
    """

    def __init__(self, config: DenoiserConfig) -> None:
        super().__init__()
        if config.feature_dim != FEATURE_DIM_BIOMECH:
            raise ValueError(
                f"the biomo denoiser needs {FEATURE_DIM_BIOMECH}-d features, got {config.feature_dim}"
            )
        self.config = config
        self.unet = UNetDenoiser(config, extra_channels=ACCEL_DIM + 1)
        self.physics = PhysicalNetwork(config.feature_dim, config.phys_hidden)

    def forward(
        self,
        x: torch.Tensor,
        t: torch.Tensor,
        text: TextFeatures,
        mask: torch.Tensor,
        drop_text: torch.Tensor | None = None,
        drop_phys: torch.Tensor | None = None,
        speed: float = 1.0,
        physics: bool = False,
    ) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
        """x0 (B, T, 329); with ``physics=True`` (training) also acc (B, T, 22, 3) m/s^2 and u (B, T, 8),
        both None when every row's physics is dropped (the physical network is then not run at all)."""
        keep = torch.ones(len(x), dtype=torch.bool, device=x.device) if drop_phys is None else ~drop_phys
        acc = u = None
        extra = torch.zeros(*x.shape[:2], ACCEL_DIM + 1, dtype=x.dtype, device=x.device)
        if keep.any():
            # Training runs the network on every row (its output feeds L_phys even where P_c drops it from
            # the UNet's input); sampling only on the rows that use it (one pass in three under guidance).
            rows = slice(None) if physics else keep
            acc, u = self.physics(x[rows], t[rows], mask[rows])
            feats = self.physics.to_features(acc * speed)
            feats = torch.cat([feats, torch.ones_like(feats[..., :1])], dim=-1)
            if physics:
                extra = feats * keep[:, None, None]
            else:
                extra[keep] = feats.to(extra.dtype)
        x0 = self.unet(x, t, text, mask, drop_text, extra=extra)
        return (x0, acc, u) if physics else x0
