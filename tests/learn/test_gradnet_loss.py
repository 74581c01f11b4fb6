"""GradNet's losses (learn/gradnet_loss.py, equations 6-11 and 14 of Guo et al. 2019).

What each test can detect:
- a slow twin (Python loops over pixels and neighbours, written here from the equations) gives
  the same loss on random inputs: a wrong difference direction, a border pixel counted, a missing
  neighbour, a weight on the wrong image, a sign dropped from the mu-law;
- on a known image with exact gradients, base = the image, and compressed values linear in the
  features with derivative G, the loss is 0 and every small perturbation of the image raises it
  (the minimum is there), and the analytic gradient of a smooth point matches finite differences
  (torch.autograd.gradcheck, float64);
- the lambda schedule of eq. 14 at its corners.
"""
import math

import numpy as np
import pytest
import torch

from learn.gradnet_loss import (MU, SIGMA_B2, data_loss, first_order_loss, g_loss, grad_loss, lambda_schedule,
                                total_loss)


def _t(x):
    return math.copysign(math.log1p(MU * abs(x)) / math.log1p(MU), x)


def _twin(image, base, gx, gy, feats, G, alpha, lam):
    I, B, X, Y, F, D = (a[0].numpy().astype(np.float64) for a in (image, base, gx, gy, feats, G))
    H, W = I.shape[1:]
    data = np.mean([abs(_t(I[0, y, x]) - _t(B[0, y, x])) for y in range(H) for x in range(W)])
    gxs = [abs(_t(I[0, y, x + 1] - I[0, y, x]) - _t(X[0, y, x])) for y in range(H) for x in range(W - 1)]
    gys = [abs(_t(I[0, y + 1, x] - I[0, y, x]) - _t(Y[0, y, x])) for y in range(H - 1) for x in range(W)]
    terms = []
    for y in range(H):
        for x in range(W):
            for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
                v, u = y + dy, x + dx
                if not (0 <= v < H and 0 <= u < W):
                    continue
                w = math.exp(-(_t(B[0, y, x]) - _t(B[0, v, u])) ** 2 / (2 * SIGMA_B2))
                r = _t(I[0, v, u]) - _t(I[0, y, x]) - float(D[:, y, x] @ (F[:, v, u] - F[:, y, x]))
                terms.append(w * abs(r))
    return np.mean(gxs) + np.mean(gys) + alpha * data + lam * np.mean(terms)


def _random(rng, h=5, w=6, c=7):
    def t(*shape, scale=1.0, signed=False):
        a = rng.normal(size=shape) if signed else rng.gamma(1.0, 1.0, size=shape)
        return torch.tensor(a * scale, dtype=torch.float64)
    return (t(1, 1, h, w), t(1, 1, h, w), t(1, 1, h, w, signed=True), t(1, 1, h, w, signed=True),
            torch.tensor(rng.random((1, c, h, w))), t(1, c, h, w, signed=True, scale=0.3))


def test_losses_match_a_slow_twin():
    rng = np.random.default_rng(1)
    for alpha, lam in ((1.0, 0.0), (0.5, 2.0), (1.0, 0.7)):
        args = _random(rng)
        got = float(total_loss(*args, alpha=alpha, lam=lam))
        np.testing.assert_allclose(got, _twin(*args, alpha, lam), rtol=1e-10)


def _minimum(h=6, w=7):
    """An image whose gradients, base and features agree: T(I) = 0.4 + a . F, F smooth."""
    y, x = np.mgrid[0:h, 0:w] / 6.0
    feats = np.stack([0.5 + 0.4 * np.sin(1.3 * x + k) * np.cos(0.7 * y - k) for k in range(7)])
    a = np.linspace(-0.05, 0.05, 7)
    t = 0.4 + np.tensordot(a, feats, axes=1)
    image = (np.expm1(t * math.log1p(MU)) / MU)[None, None]  # the inverse of T (t > 0)
    gx = np.zeros_like(image)
    gx[..., :, :-1] = image[..., :, 1:] - image[..., :, :-1]
    gy = np.zeros_like(image)
    gy[..., :-1, :] = image[..., 1:, :] - image[..., :-1, :]
    G = np.broadcast_to(a[:, None, None], feats.shape)[None].copy()
    return tuple(torch.tensor(v) for v in (image, image.copy(), gx, gy, feats[None], G))


def test_the_loss_is_at_its_minimum_on_a_consistent_image():
    image, base, gx, gy, feats, G = _minimum()
    assert float(total_loss(image, base, gx, gy, feats, G, alpha=1.0, lam=2.0)) < 1e-12
    assert float(g_loss(base, feats, G)) < 1e-12
    rng = np.random.default_rng(2)
    for _ in range(20):
        d = torch.tensor(rng.normal(size=image.shape)) * 1e-3
        assert float(total_loss(image + d, base, gx, gy, feats, G, alpha=1.0, lam=2.0)) > 1e-6


def test_gradient_matches_finite_differences():
    rng = np.random.default_rng(3)
    image, base, gx, gy, feats, G = _random(rng, 4, 5)
    image.requires_grad_(True)
    G.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda i, g: total_loss(i, base, gx, gy, feats, g, alpha=0.8, lam=1.5),
                                    (image, G), eps=1e-7, atol=1e-6)


@pytest.mark.parametrize("epoch,want", [(1, 0.0), (5, 0.0), (6, 0.11), (15, 0.1 * 1.1 ** 10), (100, 2.0)])
def test_lambda_schedule(epoch, want):
    assert lambda_schedule(epoch) == pytest.approx(want)


def test_terms_vanish_separately():
    image, base, gx, gy, feats, G = _minimum()
    assert float(data_loss(image, base)) == 0.0
    assert float(grad_loss(image, gx, gy)) < 1e-12
    assert float(first_order_loss(image, base, feats, G)) < 1e-12


def test_lambda_schedule_cap():
    """--lambda-max moves the cap, not the growth: 0.1 x 1.1^35 at epoch 40 under a cap of 20."""
    assert lambda_schedule(40, top=20.0) == pytest.approx(0.1 * 1.1 ** 35)
    assert lambda_schedule(100, top=20.0) == pytest.approx(20.0)
    assert lambda_schedule(40) == pytest.approx(2.0)
