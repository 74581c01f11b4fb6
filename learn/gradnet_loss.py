"""The unsupervised losses of GradNet (Guo et al. 2019, section 4.3, equations 6-11 and 14).

Images are one colour channel per example, (B, 1, H, W) torch tensors, linear radiance; the
gradients follow tracer.gradient.poisson: forward differences, (dx I)[y, x] = I[y, x+1] - I[y, x],
the last column of dx and the last row of dy left out. Features F are (B, C, H, W) in [0, 1]
(albedo, normal as (N + 1) / 2, depth scaled to [0, 1]: 7 channels), G the per-pixel derivative of
the image with respect to them, (B, C, H, W).

    T(x)        = sign(x) log(1 + mu |x|) / log(1 + mu), mu = 16                      (eq. 6)
    L_data      = mean |T(I) - T(I_b)|                                                 (eq. 8)
    L_grad      = mean over the dx pixels of |T(dx I) - T(I_dx)|
                  + mean over the dy pixels of |T(dy I) - T(I_dy)|                     (eq. 9)
    L_1st       = mean over ordered 4-neighbour pairs (i, j) of
                  w_ij |T(I_j) - T(I_i) - G_i . (F_j - F_i)|                           (eq. 10)
    L_G         = the same with I_b in place of I (the G-branch's loss)                (eq. 11)
    L_all       = L_grad + alpha L_data + lambda L_1st                                 (eq. 7)

with w_ij = exp(-(T(I_b,i) - T(I_b,j))^2 / (2 sigma_b^2)), sigma_b^2 = 1/18 (the paper's weight,
taken on the compressed base image, whose range the bandwidth fits), and lambda's schedule
`lambda_schedule` (eq. 14). Each term is 0 exactly when its constraint holds, so L_all is at its
minimum, 0, at an image whose gradients are the given ones, equal to the base, and whose
compressed values are a linear function of the features with derivative G.
"""
import torch

from tracer.gradient.gradnet import MU, mu_law  # noqa: F401 (MU re-exported)

SIGMA_B2 = 1.0 / 18.0


def data_loss(image, base):
    return (mu_law(image) - mu_law(base)).abs().mean()


def grad_loss(image, gx, gy):
    dx = image[..., :, 1:] - image[..., :, :-1]
    dy = image[..., 1:, :] - image[..., :-1, :]
    return ((mu_law(dx) - mu_law(gx[..., :, :-1])).abs().mean()
            + (mu_law(dy) - mu_law(gy[..., :-1, :])).abs().mean())


def _pairs(t):
    """(t_i, t_j) for every ordered 4-neighbour pair: right, left, down, up, each as two
    equally shaped views."""
    return [(t[..., :, :-1], t[..., :, 1:]), (t[..., :, 1:], t[..., :, :-1]),
            (t[..., :-1, :], t[..., 1:, :]), (t[..., 1:, :], t[..., :-1, :])]


def first_order_loss(image, base, features, G):
    """Eq. 10 (eq. 11 when image is the base image), averaged over all ordered neighbour pairs."""
    ti, tb = mu_law(image), mu_law(base)
    total, count = 0.0, 0
    for (ii, ij), (bi, bj), (fi, fj), (gi, _) in zip(_pairs(ti), _pairs(tb), _pairs(features), _pairs(G)):
        w = torch.exp(-(bi - bj) ** 2 / (2.0 * SIGMA_B2))
        r = ij - ii - (gi * (fj - fi)).sum(dim=1, keepdim=True)
        total = total + (w * r.abs()).sum()
        count += r.numel()
    return total / count


def g_loss(base, features, G):
    """Eq. 11: the G-branch's loss."""
    return first_order_loss(base, base, features, G)


def total_loss(image, base, gx, gy, features, G, alpha=1.0, lam=0.0):
    """Eq. 7 (G is held fixed here: detach it, the G-branch trains on g_loss)."""
    out = grad_loss(image, gx, gy) + alpha * data_loss(image, base)
    if lam > 0.0:
        out = out + lam * first_order_loss(image, base, features, G)
    return out


def lambda_schedule(epoch, top=2.0):
    """Eq. 14: 0 for the first 5 epochs, then 0.1 x 1.1^(epoch - 5), at most `top` (the paper's 2;
    epochs count from 1)."""
    return 0.0 if epoch <= 5 else min(0.1 * 1.1 ** (epoch - 5), float(top))
