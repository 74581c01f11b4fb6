"""The GradNet network (Guo et al. 2019, section 4.4), sized for the CPU, and its inference.

Input per colour channel (one channel an example, as the authors' code): the data branch sees the
mu-law compressed indirect light (1 channel) and the 7 features (albedo, (normal + 1) / 2,
depth in [0, 1]); the gradient branch the compressed dx and dy (2). Each branch is three 3x3
stride-2 convolutions (width w, 2w, 4w); their outputs meet in residual blocks at 1/8 resolution
(8w channels); the decoder is three 4x4 stride-2 transposed convolutions, each fed the previous
level and both branches' features of its resolution (eq. 12's dual skip links). LReLU everywhere
but the last layer. The G-branch (three 3x3 convolutions) gives the 7 derivatives of the image
with respect to the features that the first-order loss needs during training; inference does not
run it.

Inference (`reconstruct`): the three colour channels as a batch of 3 in one torch call under
`torch.inference_mode()`, the image padded by replication to a multiple of 8 and cropped back;
the output is clipped to +-1e6 (T_MAX in the mu-law) and expanded. `energy_correction` is eq. 13's post-process. torch is
imported by this module only.
"""
import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..nn import WEIGHTS_DIR, count_flops, load_weights, parameter_count  # noqa: F401

MU = 16.0
N_FEATURES = 7
NAME = "gradnet"
T_MAX = math.log1p(MU * 1e6) / math.log1p(MU)  # outputs are clipped to +-1e6 in linear radiance


def mu_law(x, mu=MU):
    """Signed mu-law compression (eq. 6)."""
    return torch.sign(x) * torch.log1p(mu * x.abs()) / math.log1p(mu)


def expand(t, mu=MU):
    """The inverse of mu_law."""
    return torch.sign(t) * torch.expm1(t.abs() * math.log1p(mu)) / mu


def _act(x):
    return F.leaky_relu(x, 0.01)


class _Residual(nn.Module):
    def __init__(self, c):
        super().__init__()
        self.a = nn.Conv2d(c, c, 3, padding=1)
        self.b = nn.Conv2d(c, c, 3, padding=1)

    def forward(self, x):
        return x + self.b(_act(self.a(x)))


class GradNet(nn.Module):
    """Two encoders (data: 1 + 7 channels; gradients: 2), `blocks` residual blocks, a decoder with
    dual skip links; `g_branch` the G-branch (see the module docstring). Width w: the first level's
    channels."""

    def __init__(self, width=8, blocks=2, full_res=True):
        super().__init__()
        w = int(width)
        self.width, self.blocks, self.full_res = w, int(blocks), bool(full_res)
        chans = (w, 2 * w, 4 * w)
        self.enc_d = nn.ModuleList([nn.Conv2d(c_in, c_out, 3, stride=2, padding=1)
                                    for c_in, c_out in zip((1 + N_FEATURES,) + chans[:2], chans)])
        self.enc_g = nn.ModuleList([nn.Conv2d(c_in, c_out, 3, stride=2, padding=1)
                                    for c_in, c_out in zip((2,) + chans[:2], chans)])
        self.res = nn.Sequential(*[_Residual(8 * w) for _ in range(self.blocks)])
        self.dec = nn.ModuleList([nn.ConvTranspose2d(16 * w, 2 * w, 4, stride=2, padding=1),
                                  nn.ConvTranspose2d(6 * w, w, 4, stride=2, padding=1),
                                  nn.ConvTranspose2d(3 * w, w if self.full_res else 1, 4, stride=2, padding=1)])
        if self.full_res:  # the last layer sees the full-resolution inputs and corrects the base
            self.out = nn.Conv2d(w + 1 + N_FEATURES + 2, 1, 3, padding=1)
            nn.init.zeros_(self.out.bias)
            with torch.no_grad():
                self.out.weight.mul_(0.1)
        self.g_branch = nn.Sequential(nn.Conv2d(3 + N_FEATURES, w, 3, padding=1), nn.LeakyReLU(0.01),
                                      nn.Conv2d(w, w, 3, padding=1), nn.LeakyReLU(0.01),
                                      nn.Conv2d(w, N_FEATURES, 3, padding=1))

    def forward(self, data, grads):
        """data (B, 8, H, W): compressed image and features; grads (B, 2, H, W): compressed dx, dy;
        H and W multiples of 8. Returns the compressed reconstruction (B, 1, H, W)."""
        ds, gs = [], []
        d, g = data, grads
        for cd, cg in zip(self.enc_d, self.enc_g):
            d, g = _act(cd(d)), _act(cg(g))
            ds.append(d)
            gs.append(g)
        h = self.res(torch.cat([d, g], 1))
        for k, deconv in enumerate(self.dec):
            h = deconv(torch.cat([h, ds[2 - k], gs[2 - k]], 1))
            if k < 2 or self.full_res:
                h = _act(h)
        if self.full_res:
            h = data[:, :1] + self.out(torch.cat([h, data, grads], 1))
        return h

    def derivatives(self, data, grads):
        """The G-branch: (B, 7, H, W) derivatives of the compressed image with respect to the features."""
        return self.g_branch(torch.cat([data, grads], 1))


def load(name=NAME, folder=None):
    """(model in eval mode, manifest dict) of the weights `name`.pt / `name`.json in folder
    (default: the shipped ones, WEIGHTS_DIR)."""
    return load_weights(GradNet, name, folder or WEIGHTS_DIR, "python -m learn.gradnet train")


CORRECTION_RADIUS, CORRECTION_SIGMA = 45, 15.0  # eq. 13's Gaussian


def energy_correction(image, base, radius=CORRECTION_RADIUS, sigma=CORRECTION_SIGMA):
    """Eq. 13: image x (base * k) / (image * k), k a Gaussian of standard deviation `sigma` cut at
    `radius` pixels, per colour channel (borders reflected); where image * k is not positive the
    image is kept. (H, W, C) arrays; returns float32."""
    from scipy.ndimage import gaussian_filter

    img = np.asarray(image, np.float64)
    kw = dict(sigma=(sigma, sigma, 0), truncate=radius / sigma, mode="reflect")
    num = gaussian_filter(np.asarray(base, np.float64), **kw)
    den = gaussian_filter(img, **kw)
    ok = den > 0
    scale = np.where(ok, num / np.where(ok, den, 1.0), 1.0)
    return (img * scale).astype(np.float32)


def inputs(indirect, dx, dy, albedo, normal, depth):
    """(data (3, 8, H, W), grads (3, 2, H, W)) float32 tensors, one example per colour channel, from
    (H, W, 3) buffers (depth (H, W, 1), in [0, 1]; normals in [-1, 1])."""
    feats = np.concatenate([albedo, (np.asarray(normal) + 1.0) * 0.5, depth], axis=2).transpose(2, 0, 1)
    feats = torch.from_numpy(np.ascontiguousarray(feats, np.float32))
    img = torch.from_numpy(np.ascontiguousarray(np.asarray(indirect, np.float32).transpose(2, 0, 1)))
    gx = torch.from_numpy(np.ascontiguousarray(np.asarray(dx, np.float32).transpose(2, 0, 1)))
    gy = torch.from_numpy(np.ascontiguousarray(np.asarray(dy, np.float32).transpose(2, 0, 1)))
    data = torch.cat([mu_law(img)[:, None], feats[None].expand(3, -1, -1, -1)], 1)
    grads = torch.stack([mu_law(gx), mu_law(gy)], 1)
    return data, grads


def reconstruct(model, indirect, dx, dy, albedo, normal, depth):
    """The network's reconstruction (H, W, 3) float32 of the indirect light from a gpt render's
    buffers (any H, W: padded by replication to multiples of 8, then cropped)."""
    data, grads = inputs(indirect, dx, dy, albedo, normal, depth)
    h, w = data.shape[2:]
    ph, pw = (-h) % 8, (-w) % 8
    with torch.inference_mode():
        if ph or pw:
            data = F.pad(data, (0, pw, 0, ph), mode="replicate")
            grads = F.pad(grads, (0, pw, 0, ph), mode="replicate")
        out = expand(model(data, grads).clamp(-T_MAX, T_MAX))[:, 0, :h, :w]
    return np.ascontiguousarray(out.numpy().transpose(1, 2, 0), np.float32)
