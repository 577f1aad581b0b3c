"""BioMoDiffuse's physical network: the SPD inertia and its Woodbury solve, the Euler-Lagrange equation its
accelerations satisfy, shapes, units (m/s^2 against the 329-d build's joint_acc) and the statistics it
is saved with."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from physmotion.conventions import FPS
from physmotion.nets.backbone import DenoiserConfig
from physmotion.diffusion.model import MotionDiffusion
from physmotion.nets.physnet import ACCEL_DIM, INERTIA_RANK, MUSCLES, BioMoDenoiser, PhysicalNetwork
from physmotion.diffusion.schedule import DiffusionConfig
from physmotion.features.biomech import FEATURE_DIM_BIOMECH, SLICES_BIOMECH
from physmotion.features.normalize import Normalizer
from physmotion.skeleton import NUM_JOINTS
from physmotion.text.encoder import load_text_encoder

HIDDEN = 32


def _net(seed: int = 0) -> PhysicalNetwork:
    torch.manual_seed(seed)
    return PhysicalNetwork(hidden=HIDDEN).eval()


def _stats(root: Path) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.from_numpy(np.load(root / "Mean.npy")), torch.from_numpy(np.load(root / "Std.npy"))


@pytest.mark.parametrize("scale", [0.1, 1.0, 10.0])
def test_inertia_is_symmetric_positive_definite(scale: float) -> None:
    gen = torch.Generator().manual_seed(int(scale * 10))
    for seed in range(3):
        net = _net(seed)
        z = torch.randn(4, 7, HIDDEN, generator=gen) * scale
        with torch.no_grad():
            d, v = net.inertia(z)
        assert d.shape == (4, 7, ACCEL_DIM) and v.shape == (4, 7, ACCEL_DIM, INERTIA_RANK)
        assert torch.all(d > 0)
        m = PhysicalNetwork.inertia_matrix(d, v).double()
        assert m.shape == (4, 7, ACCEL_DIM, ACCEL_DIM)
        torch.testing.assert_close(m, m.transpose(-1, -2), rtol=0, atol=1e-6 * float(m.abs().max()))
        eig = torch.linalg.eigvalsh(m)
        assert float(eig.min()) > 0, float(eig.min())
        torch.linalg.cholesky(m)  # raises unless positive definite


def test_inertia_stays_positive_definite_when_the_diagonal_head_collapses() -> None:
    """softplus(d) -> 0 for a very negative raw diagonal; the eps floor keeps M invertible."""
    net = _net()
    with torch.no_grad():
        net.m_net.weight[:ACCEL_DIM] = 0.0
        net.m_net.bias[:ACCEL_DIM] = -80.0
        d, v = net.inertia(torch.randn(3, 5, HIDDEN))
    assert torch.all(d > 0) and float(d.min()) == pytest.approx(1e-3, rel=1e-3)
    eig = torch.linalg.eigvalsh(PhysicalNetwork.inertia_matrix(d, v).double())
    assert float(eig.min()) > 0.5e-3


def test_solve_runs_in_float32_under_bf16_autocast() -> None:
    """bf16 training (a GPU's default) autocasts the network, and CUDA's LU solve has no bf16 kernel: the
    solve leaves the autocast and works in float32 (decisions "the BioMoDiffuse ablation on a GPU")."""
    gen = torch.Generator().manual_seed(1)
    d = torch.nn.functional.softplus(torch.randn(4, ACCEL_DIM, generator=gen)) + 1e-3
    v = torch.randn(4, ACCEL_DIM, INERTIA_RANK, generator=gen)
    b = torch.randn(4, ACCEL_DIM, generator=gen)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        x = PhysicalNetwork.solve(d.bfloat16(), v.bfloat16(), b.bfloat16())
    assert x.dtype == torch.float32
    m = PhysicalNetwork.inertia_matrix(d.bfloat16().float(), v.bfloat16().float())
    dense = torch.linalg.solve(m, b.bfloat16().float()[..., None])[..., 0]
    torch.testing.assert_close(x, dense, rtol=1e-4, atol=1e-4)


def test_woodbury_solve_equals_the_dense_solve() -> None:
    gen = torch.Generator().manual_seed(0)
    d = torch.nn.functional.softplus(torch.randn(6, ACCEL_DIM, generator=gen, dtype=torch.float64)) + 1e-3
    v = torch.randn(6, ACCEL_DIM, INERTIA_RANK, generator=gen, dtype=torch.float64) * 3
    b = torch.randn(6, ACCEL_DIM, generator=gen, dtype=torch.float64)
    m = PhysicalNetwork.inertia_matrix(d, v)
    x = PhysicalNetwork.solve(d, v, b)
    dense = torch.linalg.solve(m, b[..., None])[..., 0]
    torch.testing.assert_close(x, dense, rtol=1e-9, atol=1e-9)
    torch.testing.assert_close((m @ x[..., None])[..., 0], b, rtol=1e-9, atol=1e-9)
    # and in float32 on the network's own factors, batched over frames
    net = _net(1)
    with torch.no_grad():
        d32, v32 = net.inertia(torch.randn(2, 9, HIDDEN, generator=gen))
    b32 = torch.randn(2, 9, ACCEL_DIM, generator=gen)
    x32 = PhysicalNetwork.solve(d32, v32, b32)
    ref = torch.linalg.solve(PhysicalNetwork.inertia_matrix(d32, v32).double(), b32.double()[..., None])[
        ..., 0
    ]
    torch.testing.assert_close(x32.double(), ref, rtol=1e-3, atol=1e-3 * float(ref.abs().max()))


def test_accelerations_satisfy_the_euler_lagrange_equation() -> None:
    """M(q) acc = F + C + R ⊙ A(u): the forward pass's acc, multiplied back by the dense M of its own
    inertia head, gives the sum of the F, C and muscle heads (read off with forward hooks)."""
    net = _net(2)
    seen: dict[str, torch.Tensor] = {}
    net.physics_decoder.register_forward_hook(lambda m, i, o: seen.__setitem__("trunk", o))
    net.muscle_decoder.register_forward_hook(lambda m, i, o: seen.__setitem__("internal", o))
    x = torch.randn(2, 10, FEATURE_DIM_BIOMECH)
    with torch.no_grad():
        acc, _ = net(x, torch.tensor([3, 700]))
        trunk = seen["trunk"]
        d, v = net.inertia(trunk)
        rhs = net.f_net(trunk) + net.c_net(trunk) + seen["internal"]
    m = PhysicalNetwork.inertia_matrix(d, v).double()
    lhs = (m @ acc.flatten(-2).double()[..., None])[..., 0]
    torch.testing.assert_close(lhs, rhs.double(), rtol=1e-3, atol=1e-4 * float(rhs.abs().max()))


def test_output_shapes_and_ranges() -> None:
    net = _net()
    x = torch.randn(3, 12, FEATURE_DIM_BIOMECH)
    with torch.no_grad():
        acc, u = net(x, torch.tensor([0, 500, 999]))
    assert acc.shape == (3, 12, NUM_JOINTS, 3) and u.shape == (3, 12, MUSCLES) == (3, 12, 8)
    assert torch.isfinite(acc).all() and torch.all(u > 0) and torch.all(u < 1)
    with torch.no_grad():  # the timestep is an input: another noise level, another answer
        other, _ = net(x, torch.tensor([999, 500, 0]))
    assert not torch.allclose(acc[0], other[0]) and torch.allclose(acc[1], other[1])


def test_padding_is_ignored_and_the_network_looks_one_frame_ahead_only() -> None:
    net = _net()
    x = torch.randn(2, 12, FEATURE_DIM_BIOMECH)
    t = torch.tensor([100, 100])
    mask = torch.arange(12)[None] < torch.tensor([9, 12])[:, None]
    y = x.clone()
    y[0, 9:] = torch.randn(3, FEATURE_DIM_BIOMECH) * 5  # padding of row 0
    with torch.no_grad():
        a, u = net(x, t, mask)
        b, w = net(y, t, mask)
    torch.testing.assert_close(a, b, rtol=0, atol=0)
    torch.testing.assert_close(u, w, rtol=0, atol=0)
    z = x.clone()
    z[:, 8] += 3.0  # frame 8 changes: frames up to 6 cannot see it (width-3 conv, then a causal GRU)
    with torch.no_grad():
        a, _ = net(x, t)
        c, _ = net(z, t)
    torch.testing.assert_close(a[:, :7], c[:, :7], rtol=0, atol=1e-6)
    assert not torch.allclose(a[:, 7], c[:, 7]) and not torch.allclose(a[:, 11], c[:, 11])


def test_feature_units_round_trip(built329_dir: Path) -> None:
    mean, std = _stats(built329_dir)
    net = _net()
    net.set_feature_stats(mean, std)
    part = SLICES_BIOMECH["joint_acc"]
    assert part == slice(263, 329)
    torch.testing.assert_close(net.acc_mean, mean[263:329], rtol=0, atol=0)
    torch.testing.assert_close(net.acc_std, std[263:329], rtol=0, atol=0)
    assert not torch.equal(net.acc_mean, torch.zeros(ACCEL_DIM))  # real statistics, not the defaults
    f = torch.randn(2, 5, ACCEL_DIM, generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(net.to_features(net.from_features(f)), f, rtol=1e-4, atol=1e-4)
    acc = torch.randn(2, 5, NUM_JOINTS, 3) * 20  # m/s^2
    torch.testing.assert_close(net.from_features(net.to_features(acc)), acc, rtol=1e-4, atol=1e-3)


def test_from_features_gives_metres_per_second_squared(built329_dir: Path) -> None:
    """The real build's normalised joint_acc, through from_features, is the raw joint_acc (metres per
    frame^2) times fps^2 = 400, and its per-joint magnitude is that of the second difference of the
    canonical joints the build stored, in m/s^2."""
    assert FPS == 20
    mean, std = _stats(built329_dir)
    net = _net()
    net.set_feature_stats(mean, std)
    norm = Normalizer.load(built329_dir)
    ids = sorted(p.stem for p in (built329_dir / "new_joint_vecs").glob("*.npy"))
    for mid in ids[:: max(1, len(ids) // 12)]:
        raw = np.load(built329_dir / "new_joint_vecs" / f"{mid}.npy")
        x = torch.from_numpy(norm.normalize(raw)).float()
        acc = net.from_features(x[None, :, 263:329])[0].double().numpy()
        expected = raw[:, 263:329].reshape(-1, NUM_JOINTS, 3).astype(np.float64) * 400.0
        np.testing.assert_allclose(acc, expected, rtol=1e-3, atol=1e-3 * np.abs(expected).max())
        joints = np.load(built329_dir / "new_joints" / f"{mid}.npy").astype(np.float64)
        second = (joints[2:] - 2 * joints[1:-1] + joints[:-2]) * FPS**2  # frames 1 .. T-2, m/s^2
        np.testing.assert_allclose(np.linalg.norm(acc[1:-1], axis=-1), np.linalg.norm(second, axis=-1),
                                   rtol=1e-3, atol=1e-2)  # fmt: skip


def test_feature_stats_travel_with_a_saved_model(built329_dir: Path, tmp_path: Path) -> None:
    """The statistics are buffers of the network: MotionDiffusion.save/load keeps them."""
    mean, std = _stats(built329_dir)
    cfg = DenoiserConfig(arch="biomo", feature_dim=FEATURE_DIM_BIOMECH, d_model=32, layers=2, phys_hidden=HIDDEN,
                         text_dim=load_text_encoder("minilm").dim)  # fmt: skip
    net = BioMoDenoiser(cfg).eval()
    net.physics.set_feature_stats(mean, std)
    assert "physics.acc_mean" in net.state_dict() and "physics.acc_std" in net.state_dict()
    MotionDiffusion(net, cfg, DiffusionConfig(), Normalizer.load(built329_dir)).save(tmp_path / "m")
    loaded = MotionDiffusion.load(tmp_path / "m")
    torch.testing.assert_close(loaded.net.physics.acc_mean, mean[263:329], rtol=0, atol=0)
    torch.testing.assert_close(loaded.net.physics.acc_std, std[263:329], rtol=0, atol=0)


def test_trained_biomo_model_carries_the_datas_statistics(tiny_biomo, small_built329_dir: Path) -> None:
    """train_denoiser fills the statistics from the data before training; the model it saves (the EMA
    weights) must carry them too, or sampling reads the physical network's m/s^2 in the wrong units.
    (tiny_biomo trains on the small 329-d build, tests/conftest.py.)"""
    mean, std = _stats(small_built329_dir)
    assert tiny_biomo.denoiser.arch == "biomo" and tiny_biomo.denoiser.feature_dim == 329
    torch.testing.assert_close(tiny_biomo.net.physics.acc_mean, mean[263:329], rtol=0, atol=0)
    torch.testing.assert_close(tiny_biomo.net.physics.acc_std, std[263:329], rtol=0, atol=0)


def test_biomo_denoiser_shapes_and_dropped_physics(tiny_biomo) -> None:
    net = tiny_biomo.net
    enc = load_text_encoder(tiny_biomo.text_encoder).encode(["a person walks", "a person runs"])
    x = torch.randn(2, 40, FEATURE_DIM_BIOMECH)
    t = torch.tensor([10, 900])
    mask = torch.ones(2, 40, dtype=torch.bool)
    with torch.no_grad():
        x0, acc, u = net(x, t, enc, mask, physics=True)
        assert x0.shape == (2, 40, 329) and acc.shape == (2, 40, 22, 3) and u.shape == (2, 40, 8)
        assert torch.equal(net(x, t, enc, mask), x0)  # physics=False: x0 only
        x0_none, acc_none, u_none = net(x, t, enc, mask, drop_phys=torch.tensor([True, True]), physics=True)
        assert acc_none is None and u_none is None and not torch.allclose(x0_none, x0)
        # one dropped row: that row is the all-dropped prediction, the other the physics one
        half = net(x, t, enc, mask, drop_phys=torch.tensor([True, False]))
    torch.testing.assert_close(half[0], x0_none[0], rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(half[1], x0[1], rtol=1e-4, atol=1e-5)


def test_biomo_needs_329_features() -> None:
    with pytest.raises(ValueError, match="329"):
        BioMoDenoiser(DenoiserConfig(arch="biomo", feature_dim=263, d_model=32, layers=2, phys_hidden=HIDDEN))
