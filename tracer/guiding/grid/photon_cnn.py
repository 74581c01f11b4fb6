"""The photon guide's map-reconstruction network (Zhu et al. 2021, section 6): a compact U-Net with
partial convolutions that turns a sparse photon histogram into a dense sampling map.

Input per voxel (equation 11), five channels at the map's resolution (n_theta x n_phi):
    S_t, S_{t-1}   the normalised power maps of this and the previous update, times the number of
                   bins (mean 1), range-compressed by log1p
    P_t, P_{t-1}   photon counts per bin, log1p(count) / COUNT_SCALE (absolute: the network sees
                   how sparse the data is)
    B_t            1 where the bin holds a photon now
Output: the reconstructed map S_d, non-negative and normalised to mean 1 (a softmax over the bins).

Layers see the sphere as the guide does: phi wraps around (circular padding), z = cos(theta)
is padded by repeating the pole rows. The encoder's first two convolutions are partial convolutions (Liu et al.
2018): a bin outside the mask B_t enters no sum, and each output is rescaled by the share of its
window that holds data, so an empty bin's value never reaches the output. A fully empty input
gives the same value in every bin, hence a uniform map. Decoder levels each have an output head
(deep supervision during training; the finest one is the map).

torch is imported by this module only; `tracer` imports it when `reconstruct=cnn` is used.
"""
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ...nn import (WEIGHTS_DIR, Conv, PartialConv, act, count_flops, inner_levels, load_weights,  # noqa: F401
                  parameter_count)

COUNT_SCALE = 8.0  # log1p(count) / COUNT_SCALE: about 1 at 3000 photons in a bin
NAME = "photon_cnn"


def features(maps, counts, prev=None, prev_counts=None):
    """The network's input (S, 5, n_theta, n_phi) float32 from numpy arrays (S, n_theta, n_phi):
    `maps` normalised to sum 1 (or zero), `counts` photons per bin; the previous update's `prev`
    and `prev_counts` (zeros when absent)."""
    maps = np.asarray(maps, np.float32)
    k = maps.shape[1] * maps.shape[2]
    prev = np.zeros_like(maps) if prev is None else np.asarray(prev, np.float32)
    pc = np.zeros_like(maps) if prev_counts is None else np.asarray(prev_counts, np.float32)
    counts = np.asarray(counts, np.float32)
    x = np.empty((maps.shape[0], 5) + maps.shape[1:], np.float32)
    np.log1p(np.maximum(maps, 0.0) * k, out=x[:, 0])
    np.log1p(np.maximum(prev, 0.0) * k, out=x[:, 1])
    np.log1p(np.maximum(counts, 0.0), out=x[:, 2])
    np.log1p(np.maximum(pc, 0.0), out=x[:, 3])
    x[:, 2:4] /= COUNT_SCALE
    x[:, 4] = counts > 0.0
    return x


class PhotonUNet(nn.Module):
    """Three levels (full, 1/2, 1/4 resolution) of width (w, 2w, 2w). Encoder: a partial convolution
    at full resolution, a strided partial convolution and a residual block at 1/2, a strided
    convolution and a residual block at 1/4. Decoder: upsampling, skip links from the encoder, a
    residual block at 1/2, one convolution at full resolution; an output head per level. The full
    resolution has two convolutions only: most of the work runs at 1/2 and 1/4."""

    def __init__(self, width=8):
        super().__init__()
        w = int(width)
        self.width = w
        self.e0 = PartialConv(5, w)
        self.e1, self.e1r = PartialConv(w, 2 * w, stride=2), Conv(2 * w, 2 * w)
        self.e2, self.e2r = Conv(2 * w, 2 * w, stride=2), Conv(2 * w, 2 * w)
        self.d1, self.d1r = Conv(4 * w, 2 * w), Conv(2 * w, 2 * w)
        self.d0 = Conv(3 * w, w)
        self.h2, self.h1, self.h0 = nn.Conv2d(2 * w, 1, 1), nn.Conv2d(2 * w, 1, 1), nn.Conv2d(w, 1, 1)

    def forward(self, x, heads=False):
        """x (S, 5, H, W) from features(); H and W divisible by 4. Returns the maps (S, H, W), mean 1;
        with heads, the list of the three levels' maps, coarsest first."""
        e0, m0 = self.e0(x, x[:, 4:5])
        e0 = act(e0)
        e1, _ = self.e1(e0, m0)
        e1, e2, d1 = inner_levels(self, act(e1))
        d0 = act(self.d0(torch.cat([F.interpolate(d1, scale_factor=2, mode="nearest"), e0], 1)))
        outs = [self.h2(e2), self.h1(d1), self.h0(d0)] if heads else [self.h0(d0)]
        maps = []
        for o in outs:
            s, _, h, w = o.shape
            maps.append((torch.softmax(o.reshape(s, h * w), dim=1) * (h * w)).reshape(s, h, w))
        return maps if heads else maps[0]


def flops_per_map(model, n_theta, n_phi):
    """Floating-point operations of the convolutions for one map, all heads."""
    return count_flops(model, lambda: model(torch.zeros(1, 5, n_theta, n_phi), heads=True))


def load(name=NAME, folder=WEIGHTS_DIR):
    """(model in eval mode, manifest dict) of the shipped weights `name`.pt / `name`.json."""
    return load_weights(PhotonUNet, name, folder, "python -m learn.photon train")


def infer(model, x, batch=64):
    """Maps (S, H, W) float32 numpy from features x (S, 5, H, W), in batches under inference mode
    (64 maps a call: the fastest on a 2-core CPU, where larger batches spill the caches)."""
    out = np.empty((x.shape[0],) + x.shape[2:], np.float32)
    with torch.inference_mode():
        for i in range(0, x.shape[0], batch):
            out[i:i + batch] = model(torch.from_numpy(x[i:i + batch])).numpy()
    return out
