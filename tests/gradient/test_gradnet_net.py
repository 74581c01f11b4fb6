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
                normal=rng.normal(size=(h, w, 3)).clip(-1, 1), depth=rng.random((h, w, 1)),
                variances=tuple(rng.gamma(1.0, 0.01, (h, w, 3)) for _ in range(3)))


@pytest.fixture(scope="module", params=["v1", "l2", "l1"])
def model(request):
    torch.manual_seed(0)
    if request.param == "v1":
        return gradnet.GradNet(width=4, blocks=1).eval()
    return gradnet.GradNet.v2(4, 1, residual=request.param).eval()


def _dense_l2(base, gx, gy, alpha):
    """The L2 screened Poisson solution of one channel from its normal equations, built as dense
    matrices: (alpha^2 I + Dx'Dx + Dy'Dy) u = alpha^2 b + Dx' gx + Dy' gy, forward differences
    inside the image (the last column of gx and the last row of gy unused)."""
    h, w = base.shape
    n = h * w
    idx = np.arange(n).reshape(h, w)
    rows = []
    for a, b in ((idx[:, :-1], idx[:, 1:]), (idx[:-1, :], idx[1:, :])):
        d = np.zeros((a.size, n))
        d[np.arange(a.size), a.ravel()] = -1.0
        d[np.arange(a.size), b.ravel()] = 1.0
        rows.append(d)
    dx, dy = rows
    lhs = alpha ** 2 * np.eye(n) + dx.T @ dx + dy.T @ dy
    rhs = alpha ** 2 * base.ravel() + dx.T @ gx[:, :-1].ravel() + dy.T @ gy[:-1, :].ravel()
    return np.linalg.solve(lhs, rhs).reshape(h, w)


def test_v2_starts_from_the_l2_solution():
    """With its last layer zeroed, a v2 network returns the L2 solution of each colour channel."""
    torch.manual_seed(1)
    net = gradnet.GradNet.v2(4, 1, residual="l2").eval()
    with torch.no_grad():
        net.out.weight.zero_()
        net.out.bias.zero_()
    b = _buffers(np.random.default_rng(3), 11, 14)
    out = gradnet.reconstruct(net, **b)
    for c in range(3):
        want = _dense_l2(b["indirect"][..., c], b["dx"][..., c], b["dy"][..., c], gradnet.L2_ALPHA)
        np.testing.assert_allclose(out[..., c], want, rtol=2e-4, atol=2e-5)


def test_v2_inputs_and_their_order():
    b = _buffers(np.random.default_rng(4), 9, 10)
    data, grads = gradnet.inputs(**b, residual="l2", noise=True)
    for c in range(3):  # channel 8: the compressed L2 solution
        l2 = _dense_l2(b["indirect"][..., c], b["dx"][..., c], b["dy"][..., c], gradnet.L2_ALPHA)
        np.testing.assert_allclose(data[c, 8].numpy(), np.sign(l2) * np.log1p(16.0 * np.abs(l2)) / np.log(17.0),
                                   rtol=1e-4, atol=1e-5)
    assert data.shape == (3, 10, 9, 10) and grads.shape == (3, 4, 9, 10)
    comp = lambda x: np.sign(x) * np.log1p(16.0 * np.abs(x)) / np.log(17.0)  # noqa: E731
    np.testing.assert_allclose(data[:, 9].numpy(), comp(np.sqrt(b["variances"][0])).transpose(2, 0, 1), rtol=1e-5)
    np.testing.assert_allclose(grads[:, 2].numpy(), comp(np.sqrt(b["variances"][1])).transpose(2, 0, 1), rtol=1e-5)
    np.testing.assert_allclose(grads[:, 3].numpy(), comp(np.sqrt(b["variances"][2])).transpose(2, 0, 1), rtol=1e-5)
    np.testing.assert_allclose(data[:, 0].numpy(), comp(b["indirect"]).transpose(2, 0, 1), rtol=1e-5)
    with pytest.raises(ValueError, match="variance buffers"):
        gradnet.reconstruct(gradnet.GradNet.v2(4, 1), **dict(b, variances=None))


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
    swapped["variances"] = tuple(v[..., perm] for v in b["variances"])
    # (the l1 residual's float32 IRLS solves the three channels as one system: permuting them reorders
    # its sums, a rounding change of about 1e-4 of the value after its iterations; a channel mix-up is O(1))
    tol = (1e-3, 1e-4) if model.residual == "l1" else (1e-5, 1e-6)
    np.testing.assert_allclose(gradnet.reconstruct(model, **swapped), out[..., perm], rtol=tol[0], atol=tol[1])


def test_mu_law_round_trip_and_g_branch(model):
    x = torch.tensor([-50.0, -1.0, -1e-3, 0.0, 1e-4, 0.3, 7.0, 1e3], dtype=torch.float64)
    np.testing.assert_allclose(gradnet.expand(gradnet.mu_law(x)).numpy(), x.numpy(), rtol=1e-12, atol=1e-15)
    data, grads = gradnet.inputs(**_buffers(np.random.default_rng(1), 16, 24), residual=model.residual,
                                 noise=model.noise)
    assert data.shape == (3, model.n_data, 16, 24) and grads.shape == (3, model.n_grad, 16, 24)
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
