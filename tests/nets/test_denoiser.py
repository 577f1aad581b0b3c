"""Both backbones: shapes, padding masks, classifier-free text dropout."""

from __future__ import annotations

import pytest
import torch

from physmotion.nets.denoiser import DenoiserConfig, build_denoiser
from physmotion.text.encoder import TextFeatures


def _text(b: int, seed: int = 0) -> TextFeatures:
    g = torch.Generator().manual_seed(seed)
    mask = torch.ones(b, 5, dtype=torch.bool)
    mask[0, 3:] = False
    return TextFeatures(torch.randn(b, 5, 384, generator=g), mask, torch.randn(b, 384, generator=g))


@pytest.fixture(params=["transformer", "unet"])
def net(request):
    torch.manual_seed(0)
    return build_denoiser(DenoiserConfig(arch=request.param, d_model=64, layers=2, heads=4)).eval()


def test_shape(net) -> None:
    x = torch.randn(3, 37, 263)
    mask = torch.ones(3, 37, dtype=torch.bool)
    out = net(x, torch.tensor([0, 500, 999]), _text(3), mask)
    assert out.shape == x.shape and torch.isfinite(out).all()


def test_padding_content_is_ignored(net) -> None:
    """Whatever fills the padded frames, the real frames get the same x0."""
    x = torch.randn(1, 40, 263)
    t, text = torch.tensor([300]), _text(1)
    mask = torch.arange(64)[None] < 40
    zeros = net(torch.cat([x, torch.zeros(1, 24, 263)], dim=1), t, text, mask)
    garbage = net(torch.cat([x, 5 * torch.randn(1, 24, 263)], dim=1), t, text, mask)
    assert (zeros[:, :40] - garbage[:, :40]).abs().max() < 1e-5


def test_transformer_padding_equals_the_motion_alone() -> None:
    """Attention masks make the transformer exact under padding (the UNet's GroupNorm sees the zeros)."""
    torch.manual_seed(0)
    net = build_denoiser(DenoiserConfig(d_model=64, layers=2)).eval()
    x, t, text = torch.randn(1, 40, 263), torch.tensor([300]), _text(1)
    alone = net(x, t, text, torch.ones(1, 40, dtype=torch.bool))
    padded = net(torch.cat([x, torch.randn(1, 24, 263)], dim=1), t, text, torch.arange(64)[None] < 40)
    assert (padded[:, :40] - alone).abs().max() < 1e-4


def test_text_changes_output_and_drop_removes_it(net) -> None:
    x, t, mask = torch.randn(2, 40, 263), torch.tensor([10, 10]), torch.ones(2, 40, dtype=torch.bool)
    a, b = _text(2, seed=1), _text(2, seed=2)
    assert not torch.allclose(net(x, t, a, mask), net(x, t, b, mask))
    drop = torch.ones(2, dtype=torch.bool)
    assert torch.allclose(net(x, t, a, mask, drop), net(x, t, b, mask, drop), atol=1e-6)


def test_too_long_for_the_transformer() -> None:
    net = build_denoiser(DenoiserConfig(d_model=32, layers=1, max_frames=50))
    with pytest.raises(ValueError, match="more than"):
        net(torch.randn(1, 51, 263), torch.tensor([1]), _text(1), torch.ones(1, 51, dtype=torch.bool))


def test_unknown_arch() -> None:
    with pytest.raises(ValueError, match="unknown denoiser"):
        build_denoiser(DenoiserConfig(arch="lstm"))
