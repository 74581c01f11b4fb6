"""A Real NVP warp of the unit cube: the primary-sample-space sampler of `--guide pss`.

The warp Psi maps z, uniform in [0, 1)^D, to y in (0, 1)^D (Zheng & Zwicker 2019, section 4.3):

    z' = EPS + (1 - 2 EPS) z      squeeze (so that the logit is finite)
    a  = logit(z')
    b  = F(a)                     affine coupling layers, alternating masks (eq. 10)
    y  = sigmoid(b)

so log q(y) = -log|dy/dz| = -D log(1 - 2 EPS) + sum log z'(1 - z') - logdet F(a) - sum log y(1 - y).
The inverse runs the same steps backwards (eq. 11); q is 0 where z' falls outside [EPS, 1 - EPS].
Each coupling layer's s and t come from one residual MLP (a linear layer, `blocks` residual blocks
of two linear layers with ReLU, a linear head) of the kept coordinates and an optional context
(the pixel, for the pixel-conditioned warp); s is soft-clamped to [-S_MAX, S_MAX]. The heads start
at zero, so a new flow is the identity (the paper pre-trains to the identity; zeros give it
exactly). The squeeze and the logit/sigmoid run in float64 and F in float32, so a density is
exact to float32 rounding inside F.
"""
import math
import os

import numpy as np
import torch
from torch import nn

EPS = 1e-6
S_MAX = 3.0
N_FREQ = 4  # pixel context: (x, y) and sin/cos of 2^k pi x, 2^k pi y for k < N_FREQ


def masks(dims, layers):
    """(layers, dims) bool: which coordinates each coupling layer keeps. Even/odd coordinates, then
    the first/second half (so that the pixel pair and a direction pair exchange information), in
    turn, each followed by its complement."""
    idx = np.arange(dims)
    patterns = [idx % 2 == 0]
    if dims >= 4:
        patterns.append(idx < dims // 2)
    out = []
    for i in range(layers):
        p = patterns[(i // 2) % len(patterns)]
        out.append(p if i % 2 == 0 else ~p)
    return np.array(out)


def context_features(xy):
    """(n, 2 + 4 N_FREQ) float32 features of pixel positions xy (n, 2) in [0, 1]."""
    xy = np.asarray(xy, dtype=np.float64)
    feats = [xy]
    for k in range(N_FREQ):
        w = math.pi * 2.0 ** k
        feats += [np.sin(w * xy), np.cos(w * xy)]
    return np.concatenate(feats, axis=1).astype(np.float32)


N_CONTEXT = 2 + 4 * N_FREQ


class _STNet(nn.Module):
    def __init__(self, n_in, n_out, width, blocks):
        super().__init__()
        self.inp = nn.Linear(n_in, width)
        self.blocks = nn.ModuleList(
            nn.Sequential(nn.ReLU(), nn.Linear(width, width), nn.ReLU(), nn.Linear(width, width))
            for _ in range(blocks))
        self.head = nn.Linear(width, n_out)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def forward(self, x):
        h = self.inp(x)
        for b in self.blocks:
            h = h + b(h)
        return self.head(torch.relu(h))


class _Coupling(nn.Module):
    def __init__(self, keep, n_context, width, blocks):
        super().__init__()
        keep = np.asarray(keep, dtype=bool)
        self.register_buffer("keep", torch.from_numpy(np.nonzero(keep)[0]))
        self.register_buffer("change", torch.from_numpy(np.nonzero(~keep)[0]))
        self.k = int((~keep).sum())
        self.net = _STNet(int(keep.sum()) + n_context, 2 * self.k, width, blocks)

    def _st(self, x, ctx):
        inp = x[:, self.keep]
        if ctx is not None:
            inp = torch.cat([inp, ctx], dim=1)
        st = self.net(inp)
        s = S_MAX * torch.tanh(st[:, :self.k] / S_MAX)
        return s, st[:, self.k:]

    def forward(self, x, ctx):
        s, t = self._st(x, ctx)
        y = x.clone()
        y[:, self.change] = x[:, self.change] * torch.exp(s) + t
        return y, s.sum(dim=1)

    def inverse(self, y, ctx):
        s, t = self._st(y, ctx)
        x = y.clone()
        x[:, self.change] = (y[:, self.change] - t) * torch.exp(-s)
        return x, -s.sum(dim=1)


class PSSFlow(nn.Module):
    """Real NVP on [0, 1)^dims: `layers` coupling layers, s/t networks `width` wide with `blocks`
    residual blocks; `context` True conditions every layer on a pixel position (context_features).
    """

    def __init__(self, dims, layers=4, width=32, blocks=1, context=False):
        super().__init__()
        if dims < 2 or layers < 1 or width < 1 or blocks < 0:
            raise ValueError(f"PSSFlow needs dims >= 2, layers >= 1, width >= 1, blocks >= 0; got "
                             f"{dims}, {layers}, {width}, {blocks}")
        self.config = {"dims": int(dims), "layers": int(layers), "width": int(width), "blocks": int(blocks),
                       "context": bool(context)}
        n_ctx = N_CONTEXT if context else 0
        self.couplings = nn.ModuleList(_Coupling(k, n_ctx, width, blocks) for k in masks(dims, layers))

    @property
    def dims(self):
        return self.config["dims"]

    # F and its inverse on float32 tensors (a: logit space), with log|det|
    def f_forward(self, a, ctx=None):
        logdet = torch.zeros(a.shape[0], dtype=a.dtype)
        for c in self.couplings:
            a, ld = c(a, ctx)
            logdet = logdet + ld
        return a, logdet

    def f_inverse(self, b, ctx=None):
        logdet = torch.zeros(b.shape[0], dtype=b.dtype)
        for c in reversed(self.couplings):
            b, ld = c.inverse(b, ctx)
            logdet = logdet + ld
        return b, logdet

    def nll_terms(self, b, ctx=None):
        """-log q(y) up to the data-only terms (see prepare_targets), differentiable: b = logit(y)
        float32 (n, D). Returns (n,) float32."""
        a, logdet_inv = self.f_inverse(b, ctx)
        # log z'(1 - z') with z' = sigmoid(a): -softplus(a) - softplus(-a)
        lz = -(nn.functional.softplus(a) + nn.functional.softplus(-a)).sum(dim=1)
        return -(lz + logdet_inv)


def prepare_targets(y):
    """For training on samples y (n, D) float64 in [0, 1): (b = logit(y) float32, const (n,) float64)
    with -log q(y) = nll_terms(b) + const. y is clipped into [EPS, 1 - EPS] (the flow's support)."""
    y = np.clip(np.asarray(y, dtype=np.float64), EPS, 1.0 - EPS)
    b = _logit(y)
    const = y.shape[1] * math.log1p(-2.0 * EPS) + np.sum(np.log(y) + np.log1p(-y), axis=1)
    return torch.from_numpy(b.astype(np.float32)), const


def _ctx_tensor(ctx):
    return None if ctx is None else torch.from_numpy(np.ascontiguousarray(ctx, dtype=np.float32))


def _logit(x):
    return np.log(x) - np.log1p(-x)


def _log_sigmoids(v):
    """(log s, log(1 - s)) of s = sigmoid(v), in float64 without cancellation."""
    return -np.logaddexp(0.0, -v), -np.logaddexp(0.0, v)


def _log_q(dims, log_zs, log_1mzs, logdet_f, log_y, log_1my):
    """log q(y) = -D log(1 - 2 EPS) + sum log z'(1 - z') - logdet F(a) - sum log y(1 - y)."""
    return (-dims * math.log1p(-2.0 * EPS) + np.sum(log_zs + log_1mzs, axis=1) - logdet_f
            - np.sum(log_y + log_1my, axis=1))


def _run(fn, x, ctx):
    """fn (f_forward or f_inverse) on float64 numpy x in float32 torch: (out float64, logdet float64)."""
    with torch.inference_mode():
        out, logdet = fn(torch.from_numpy(x.astype(np.float32)), _ctx_tensor(ctx))
    return out.numpy().astype(np.float64), logdet.numpy().astype(np.float64)


def warp(flow, z, ctx=None):
    """y = Psi(z) and log q(y): z (n, D) float64 in [0, 1), ctx (n, N_CONTEXT) features or None.
    Returns (y (n, D) float64 in [0, 1), log q (n,) float64)."""
    zs = EPS + (1.0 - 2.0 * EPS) * np.asarray(z, dtype=np.float64)
    b, logdet = _run(flow.f_forward, _logit(zs), ctx)
    log_y, log_1my = _log_sigmoids(b)
    y = np.minimum(np.exp(log_y), np.nextafter(1.0, 0.0))
    return y, _log_q(zs.shape[1], np.log(zs), np.log1p(-zs), logdet, log_y, log_1my)


def unwarp(flow, y, ctx=None):
    """z = Psi^-1(y) and log q(y): y (n, D) float64 in [0, 1). Returns (z (n, D) float64, log q (n,)
    float64, -inf where y is outside the flow's support)."""
    yc = np.clip(np.asarray(y, dtype=np.float64), 1e-300, np.nextafter(1.0, 0.0))
    a, logdet_inv = _run(flow.f_inverse, _logit(yc), ctx)
    log_zs, log_1mzs = _log_sigmoids(a)
    zs = np.exp(log_zs)
    logq = _log_q(yc.shape[1], log_zs, log_1mzs, -logdet_inv, np.log(yc), np.log1p(-yc))
    inside = np.all((zs >= EPS) & (zs <= 1.0 - EPS), axis=1)
    return (zs - EPS) / (1.0 - 2.0 * EPS), np.where(inside, logq, -np.inf)


def log_density(flow, y, ctx=None):
    """log q(y) (n,) float64 for y (n, D) in [0, 1) (-inf outside the flow's support)."""
    return unwarp(flow, y, ctx)[1]


def parameter_count(flow):
    return int(sum(p.numel() for p in flow.parameters()))


def flops_per_sample(flow):
    """Multiply-adds x 2 of one pass of F (forward or inverse) for one sample."""
    total = 0
    for c in flow.couplings:
        for m in c.net.modules():
            if isinstance(m, nn.Linear):
                total += 2 * m.in_features * m.out_features
    return total


def save(flow, path, extra=None):
    """Write the flow's config, weights and `extra` (a dict) to `path` (torch.save), atomically."""
    from ...imageio import replace_atomically

    blob = {"config": flow.config, "state": flow.state_dict(), "extra": extra or {}}
    replace_atomically(os.fspath(path), lambda tmp: torch.save(blob, tmp))


def load(path):
    """(flow, extra) from a file written by save()."""
    blob = torch.load(os.fspath(path), map_location="cpu", weights_only=True)
    flow = PSSFlow(**blob["config"])
    flow.load_state_dict(blob["state"])
    flow.eval()
    return flow, blob["extra"]
