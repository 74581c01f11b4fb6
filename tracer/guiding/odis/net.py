"""The ODIS reconstruction network (Bako et al. 2019, sections 4.1-4.4), sized for CPU inference.

Input per map: the gather of tracer.guiding.odis.features (9 channels on the n_theta x n_phi sphere
grid, the `sampled` and `valid` masks), turned into 10 channels by `features`:

    0        radiance over the mean of the map's data bins, range-compressed (mu-law, MU)
    1, 5     first- and second-hit depth over the mean first-hit depth of the data bins
    2-4, 6-8 the two hits' shading normals
    9        the data mask: sampled and valid

Every channel is zero outside the data mask (a bin never sampled, or below the pixel's surface).
Output: the compressed radiance of every bin, zero outside `valid`; `radiance_maps` expands it
(the inverse mu-law), which is proportional to the incident radiance the maps are sampled from.

Layers (OdisUNet) see the sphere as the guides do (photon_cnn's padding: phi wraps, the pole rows
repeat). The first convolution is a partial convolution on the data mask, and `features` zeroes
every channel outside it, so that what a bin outside the mask holds never reaches the output.
Encoder-decoder over three scales with residual blocks and skip links, LReLU; most of the work
runs at 1/2 and 1/4 of the map's resolution (the CPU budget: docs/odis.md).

torch is imported by this module only; `tracer` imports it when `--guide odis` is used.
"""
import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ...nn import (WEIGHTS_DIR, Conv, PartialConv, act, count_flops, inner_levels, load_weights,  # noqa: F401
                  parameter_count)

MU = 5000.0  # the mu-law's compression (section 4.2)
N_IN = 10
NAME = "odis"
DEPTH_CLIP = 8.0  # relative depths above this are clipped


def compress(y):
    """The mu-law range compressor log(1 + MU y) / log(1 + MU) (numpy or torch, y >= 0)."""
    if isinstance(y, torch.Tensor):
        return torch.log1p(MU * y) / math.log1p(MU)
    return np.log1p(MU * y) / math.log1p(MU)


# compressed values are clipped here before expanding: (1 + MU)^10 / MU = 2e33, so that a map of
# 1024 such bins still sums to a finite float32. The KL loss sees only the normalised map, so the
# trained networks' outputs drift far above the mean of 1 (the shipped ones reach t = 5, 1e17):
# a lower clip makes their bright bins equal, and a clip at 3 once turned the shipped maps uniform
T_MAX = 10.0


def expand(t):
    """The inverse of `compress` (t clipped to [0, T_MAX])."""
    if isinstance(t, torch.Tensor):
        return torch.expm1(t.clamp(0.0, T_MAX) * math.log1p(MU)) / MU
    return np.expm1(np.clip(t, 0.0, T_MAX) * math.log1p(MU)) / MU


def features(feats, sampled, valid):
    """The network's input (m, 10, n_theta, n_phi) float32 from odis_input.gather's output."""
    feats = np.asarray(feats, np.float32)
    m = (np.asarray(sampled) > 0) & (np.asarray(valid) > 0)
    mf = m.astype(np.float32)
    n = np.maximum(mf.sum(axis=(1, 2)), 1.0)
    rad = np.maximum(feats[:, 0], 0.0) * mf
    scale = rad.sum(axis=(1, 2)) / n
    rad = rad / np.where(scale > 0, scale, 1.0)[:, None, None]
    depth = feats[:, 1] * mf
    dscale = depth.sum(axis=(1, 2)) / n
    dscale = np.where(dscale > 0, dscale, 1.0)[:, None, None]
    x = np.empty((feats.shape[0], N_IN) + feats.shape[2:], np.float32)
    x[:, 0] = compress(rad)
    x[:, 1] = np.minimum(depth / dscale, DEPTH_CLIP)
    x[:, 5] = np.minimum(feats[:, 5] * mf / dscale, DEPTH_CLIP)
    x[:, 2:5] = feats[:, 2:5] * mf[:, None]
    x[:, 6:9] = feats[:, 6:9] * mf[:, None]
    x[:, 9] = mf
    return x


def target(radiance, valid):
    """The training target: reference radiance maps (m, n_theta, n_phi) over their mean on the valid
    bins, compressed; zero outside `valid` (and where a map has no light)."""
    v = (np.asarray(valid) > 0).astype(np.float32)
    r = np.maximum(np.asarray(radiance, np.float32), 0.0) * v
    mean = r.sum(axis=(1, 2)) / np.maximum(v.sum(axis=(1, 2)), 1.0)
    return compress(r / np.where(mean > 0, mean, 1.0)[:, None, None]).astype(np.float32)


class OdisUNet(nn.Module):
    """Two levels below the map's resolution, 1/2 (width w) and 1/4 (2w). Encoder: a strided partial
    convolution from the full-resolution input to 1/2, a residual block there, a strided
    convolution and a residual block at 1/4. Decoder: upsampling with a skip link from the
    encoder to a convolution and a residual block at 1/2, then one convolution at full resolution
    that sees the upsampled features and the input's radiance and data mask (so a single bright
    sample still lands in its own bin). The output is softplus'd and multiplied by the valid mask.
    Nothing else runs at full resolution: there a convolution costs 4 times what it does at 1/2,
    and this layout was the fastest of those compared at equal width (docs/odis.md)."""

    def __init__(self, width=8):
        super().__init__()
        w = int(width)
        self.width = w
        self.e1, self.e1r = PartialConv(N_IN, w, stride=2), Conv(w, w)
        self.e2, self.e2r = Conv(w, 2 * w, stride=2), Conv(2 * w, 2 * w)
        self.d1, self.d1r = Conv(3 * w, w), Conv(w, w)
        self.out = Conv(w + 2, 1)

    def forward(self, x, valid):
        """x (S, 10, H, W) from features(), valid (S, H, W) {0, 1}; H and W divisible by 4. Returns
        the compressed radiance (S, H, W), zero outside valid."""
        e1, _ = self.e1(x, x[:, 9:10])
        _, _, d1 = inner_levels(self, act(e1))
        up = F.interpolate(d1, scale_factor=2, mode="nearest")
        return F.softplus(self.out(torch.cat([up, x[:, 0:1], x[:, 9:10]], 1)))[:, 0] * valid


def flops_per_map(model, n_theta=32, n_phi=32):
    """Floating-point operations (2 per multiply-add) of the convolutions for one map."""
    return count_flops(model, lambda: model(torch.zeros(1, N_IN, n_theta, n_phi), torch.ones(1, n_theta, n_phi)))


def load(name=NAME, folder=WEIGHTS_DIR):
    """(model in eval mode, manifest dict) of the shipped weights `name`.pt / `name`.json."""
    return load_weights(OdisUNet, name, folder, "python -m learn.odis train")


def radiance_maps(model, x, valid, batch=128):
    """Reconstructed radiance maps (S, H, W) float32 numpy (relative: mean about 1 on the valid bins)
    from features x (S, 10, H, W) and valid (S, H, W), in batches under inference mode."""
    out = np.empty((x.shape[0],) + x.shape[2:], np.float32)
    v = np.ascontiguousarray(valid, np.float32)
    with torch.inference_mode():
        for i in range(0, x.shape[0], batch):
            out[i:i + batch] = expand(model(torch.from_numpy(x[i:i + batch]), torch.from_numpy(v[i:i + batch]))).numpy()
    return out
