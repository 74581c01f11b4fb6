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

Two options beyond the paper, both off in the layout the paper describes (`GradNet(...)`'s
defaults) and both on in `GradNet.v2`: `residual="l1"` (v2's) or `"l2"` gives the network a
screened Poisson solution of the same buffers (`solution`: the L1 one by a shortened IRLS, or the
exact L2 one by the DCT; alpha L2_ALPHA) as an input of both the data branch and the last layers,
and its output is a correction of that solution instead of the base image; `noise` gives it the standard error of each pixel's base and gradients (mu-law
compressed: the square roots of the render's variance buffers), the data branch that of the base,
the gradient branch those of dx and dy. `head` is the number of 3x3 convolutions at full
resolution (1 or 2) that see the decoder's output with the inputs.

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
from . import poisson

MU = 16.0
N_FEATURES = 7
RESIDUALS = ("base", "l2", "l1")
NAME = "gradnet"
T_MAX = math.log1p(MU * 1e6) / math.log1p(MU)  # outputs are clipped to +-1e6 in linear radiance
L2_ALPHA = 0.2  # the screened Poisson weight of the solution a residual network corrects (tracer's default alpha)
L1_FAST = {"reweights": 8, "cg_iterations": 5}  # residual="l1": a shortened IRLS (poisson.solve_l1)


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
    """Two encoders (data: 1 + 7 channels, + 1 for the solution corrected, + 1 for the base's noise;
    gradients: 2, + 2 for their noise), `blocks` residual blocks, a decoder with dual skip links,
    `head` full-resolution layers; `g_branch` the G-branch (see the module docstring). Width w:
    the first level's channels."""

    def __init__(self, width=8, blocks=2, full_res=True, residual="base", noise=False, head=1):
        super().__init__()
        w = int(width)
        self.width, self.blocks, self.full_res = w, int(blocks), bool(full_res)
        if residual not in RESIDUALS:
            raise ValueError(f"residual must be one of {', '.join(RESIDUALS)}, got {residual!r}")
        if int(head) not in (1, 2):
            raise ValueError(f"head must be 1 or 2, got {head!r}")
        self.residual, self.noise, self.head = residual, bool(noise), int(head)
        self.n_data = 1 + N_FEATURES + (residual != "base") + self.noise
        self.n_grad = 2 + 2 * self.noise
        chans = (w, 2 * w, 4 * w)
        self.enc_d = nn.ModuleList([nn.Conv2d(c_in, c_out, 3, stride=2, padding=1)
                                    for c_in, c_out in zip((self.n_data,) + chans[:2], chans)])
        self.enc_g = nn.ModuleList([nn.Conv2d(c_in, c_out, 3, stride=2, padding=1)
                                    for c_in, c_out in zip((self.n_grad,) + chans[:2], chans)])
        self.res = nn.Sequential(*[_Residual(8 * w) for _ in range(self.blocks)])
        self.dec = nn.ModuleList([nn.ConvTranspose2d(16 * w, 2 * w, 4, stride=2, padding=1),
                                  nn.ConvTranspose2d(6 * w, w, 4, stride=2, padding=1),
                                  nn.ConvTranspose2d(3 * w, w if self.full_res else 1, 4, stride=2, padding=1)])
        if self.full_res:  # the last layers see the full-resolution inputs and correct the base (or L2)
            c_in = w + self.n_data + self.n_grad
            if self.head == 2:
                self.mid = nn.Conv2d(c_in, w, 3, padding=1)
                c_in = w
            self.out = nn.Conv2d(c_in, 1, 3, padding=1)
            nn.init.zeros_(self.out.bias)
            with torch.no_grad():
                self.out.weight.mul_(0.1)
        elif self.residual != "base" or self.head != 1:
            raise ValueError("the paper's layout (full_res False) has no residual or head options")
        self.g_branch = nn.Sequential(nn.Conv2d(3 + N_FEATURES, w, 3, padding=1), nn.LeakyReLU(0.01),
                                      nn.Conv2d(w, w, 3, padding=1), nn.LeakyReLU(0.01),
                                      nn.Conv2d(w, N_FEATURES, 3, padding=1))

    @classmethod
    def v2(cls, width=8, blocks=2, residual="l1"):
        """The layout `learn.gradnet train` makes by default: a correction of the (shortened) L1
        solution, with the noise inputs and two full-resolution layers."""
        return cls(width, blocks, True, residual=residual, noise=True, head=2)

    def config(self):
        """The keyword arguments that rebuild this layout (a manifest's "model")."""
        return {"width": self.width, "blocks": self.blocks, "full_res": self.full_res, "residual": self.residual,
                "noise": self.noise, "head": self.head}

    def forward(self, data, grads):
        """data (B, n_data, H, W): compressed image, features, then (residual "l1" or "l2") the
        compressed solution and (noise) the base's compressed standard error; grads (B, n_grad, H, W):
        compressed dx, dy, then (noise) their compressed standard errors; H and W multiples of 8.
        Returns the compressed reconstruction (B, 1, H, W)."""
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
            h = torch.cat([h, data, grads], 1)
            if self.head == 2:
                h = _act(self.mid(h))
            start = data[:, 1 + N_FEATURES:2 + N_FEATURES] if self.residual != "base" else data[:, :1]
            h = start + self.out(h)
        return h

    def derivatives(self, data, grads):
        """The G-branch: (B, 7, H, W) derivatives of the compressed image with respect to the features."""
        return self.g_branch(torch.cat([data[:, :1 + N_FEATURES], grads[:, :2]], 1))


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


def solution(residual, indirect, dx, dy):
    """The screened Poisson solution (alpha L2_ALPHA) that a network of `residual` "l2" (exact, by
    the DCT) or "l1" (IRLS shortened to L1_FAST) corrects; (H, W, C) float64."""
    if residual == "l2":
        return poisson.solve_l2(indirect, dx, dy, L2_ALPHA)
    return poisson.solve_l1(indirect, dx, dy, L2_ALPHA, **L1_FAST)


def stderr(variance):
    """Compressed standard error: mu_law(sqrt(variance)) (negative variances read as 0)."""
    return mu_law(torch.sqrt(torch.clamp(torch.as_tensor(variance), min=0.0)))


def _chw(a):
    return torch.from_numpy(np.ascontiguousarray(np.asarray(a, np.float32).transpose(2, 0, 1)))


def inputs(indirect, dx, dy, albedo, normal, depth, variances=None, residual="base", noise=False):
    """(data (3, n_data, H, W), grads (3, n_grad, H, W)) float32 tensors, one example per colour
    channel, from (H, W, 3) buffers (depth (H, W, 1), in [0, 1]; normals in [-1, 1]); with
    residual "l1" or "l2" the solution of the buffers (`solution`) joins data, with noise the standard errors from
    `variances` (base, dx, dy variance buffers) join data and grads (GradNet.forward's order)."""
    feats = np.concatenate([albedo, (np.asarray(normal) + 1.0) * 0.5, depth], axis=2).transpose(2, 0, 1)
    feats = torch.from_numpy(np.ascontiguousarray(feats, np.float32))
    img, gx, gy = _chw(indirect), _chw(dx), _chw(dy)
    data = [mu_law(img)[:, None], feats[None].expand(3, -1, -1, -1)]
    grads = [mu_law(gx)[:, None], mu_law(gy)[:, None]]
    if residual != "base":
        data.append(mu_law(_chw(solution(residual, indirect, dx, dy)))[:, None])
    if noise:
        if variances is None:
            raise ValueError("this GradNet reads the variance buffers (base, dx, dy): none were given")
        vb, vx, vy = (_chw(v) for v in variances)
        data.append(stderr(vb)[:, None])
        grads += [stderr(vx)[:, None], stderr(vy)[:, None]]
    return torch.cat(data, 1), torch.cat(grads, 1)


def reconstruct(model, indirect, dx, dy, albedo, normal, depth, variances=None):
    """The network's reconstruction (H, W, 3) float32 of the indirect light from a gpt render's
    buffers (any H, W: padded by replication to multiples of 8, then cropped); `variances` the
    (base, dx, dy) variance buffers, which a network with noise inputs needs."""
    data, grads = inputs(indirect, dx, dy, albedo, normal, depth, variances, model.residual, model.noise)
    h, w = data.shape[2:]
    ph, pw = (-h) % 8, (-w) % 8
    with torch.inference_mode():
        if ph or pw:
            data = F.pad(data, (0, pw, 0, ph), mode="replicate")
            grads = F.pad(grads, (0, pw, 0, ph), mode="replicate")
        out = expand(model(data, grads).clamp(-T_MAX, T_MAX))[:, 0, :h, :w]
    return np.ascontiguousarray(out.numpy().transpose(1, 2, 0), np.float32)
