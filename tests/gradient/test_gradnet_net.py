"""The GradNet network's inference (tracer/gradient/gradnet.py), untrained weights.

What each test can detect: an image whose size is not a multiple of 8 failing or coming back in
the wrong shape; colour channels mixed up in the batch (permuting R, G, B of every input must
permute the output the same way, since each channel is one example); padding leaking into the
crop's shape; the mu-law and its inverse not inverse to each other (signed values too); a
G-branch of the wrong shape; an energy correction (eq. 13) that does not return the base image
from any positive multiple of it, moves energy between channels, or divides by zero.
"""
import numpy as np
import pytest
import torch

from tracer.gradient import gradnet


def _buffers(rng, h, w):
    return dict(indirect=rng.gamma(1.0, 0.5, (h, w, 3)), dx=rng.normal(0, 0.2, (h, w, 3)),
                dy=rng.normal(0, 0.2, (h, w, 3)), albedo=rng.random((h, w, 3)),
                normal=rng.normal(size=(h, w, 3)).clip(-1, 1), depth=rng.random((h, w, 1)))


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return gradnet.GradNet(width=4, blocks=1).eval()


@pytest.mark.parametrize("h,w", [(29, 37), (8, 16), (1, 3)])
def test_any_size(model, h, w):
    b = _buffers(np.random.default_rng(h * w), h, w)
    out = gradnet.reconstruct(model, **b)
    assert out.shape == (h, w, 3) and out.dtype == np.float32 and np.isfinite(out).all()


def test_channels_are_independent_examples(model):
    b = _buffers(np.random.default_rng(5), 13, 21)
    perm = [2, 0, 1]
    out = gradnet.reconstruct(model, **b)
    swapped = {k: (v[..., perm] if k in ("indirect", "dx", "dy") else v) for k, v in b.items()}
    np.testing.assert_allclose(gradnet.reconstruct(model, **swapped), out[..., perm], rtol=1e-5, atol=1e-6)


def test_mu_law_round_trip_and_g_branch(model):
    x = torch.tensor([-50.0, -1.0, -1e-3, 0.0, 1e-4, 0.3, 7.0, 1e3], dtype=torch.float64)
    np.testing.assert_allclose(gradnet.expand(gradnet.mu_law(x)).numpy(), x.numpy(), rtol=1e-12, atol=1e-15)
    data, grads = gradnet.inputs(**_buffers(np.random.default_rng(1), 16, 24))
    assert data.shape == (3, 8, 16, 24) and grads.shape == (3, 2, 16, 24)
    with torch.inference_mode():
        assert model.derivatives(data, grads).shape == (3, 7, 16, 24)


def test_energy_correction():
    rng = np.random.default_rng(9)
    base = rng.gamma(1.0, 1.0, (40, 50, 3))
    scale = np.array([0.5, 2.0, 3.0])  # a reconstruction off by a factor per channel
    np.testing.assert_allclose(gradnet.energy_correction(base * scale, base), base, rtol=1e-5)
    # a smooth bias is taken out: the corrected image's local means are the base's
    ramp = 1.0 + np.linspace(0, 1, 50)[None, :, None]
    out = gradnet.energy_correction(base * ramp, base, radius=6, sigma=2.0)
    assert np.abs(out.mean(axis=(0, 1)) / base.mean(axis=(0, 1)) - 1).max() < 0.02
    zero = np.zeros_like(base)
    np.testing.assert_array_equal(gradnet.energy_correction(zero, base), zero)  # nothing to scale: kept
