"""Directional sampling maps: full-sphere, world-space, cylindrical, piecewise constant.

A map has `n_theta` rows in z = cos(theta) (world z is the pole) and `n_phi` columns in
phi = atan2(y, x), both uniform, so every bin covers the same solid angle 4 pi / (n_theta n_phi)
(the cylindrical projection preserves area). Bin k = row * n_phi + col.

A map is sampled through one flat CDF over its K = n_theta * n_phi bins, stored as float32
(K + 1 entries, cdf[0] = 0, cdf[K] = 1): the probability of bin k is cdf[k+1] - cdf[k], which
is computed exactly in float64 from the stored floats, so the density `map_pdf` returns is the
one `map_sample` samples from, to the last bit. Inside a bin the direction is uniform in solid
angle; the density is therefore P(bin) * K / (4 pi).
"""
import math

import numpy as np
from numba import prange

from .._jit import jit, kernel

FOUR_PI = 4.0 * math.pi


@jit(inline="always")
def direction_bin(d, n_theta, n_phi):
    """Bin index of the unit world direction d."""
    row = int((d[2] + 1.0) * 0.5 * n_theta)
    row = min(max(row, 0), n_theta - 1)
    col = int((math.atan2(d[1], d[0]) + math.pi) * (0.5 / math.pi) * n_phi)
    col = min(max(col, 0), n_phi - 1)
    return row * n_phi + col


@jit(inline="always")
def bin_direction(k, n_theta, n_phi, s, t):
    """Direction at fractional position (s, t) in [0,1)^2 inside bin k (s along z, t along phi)."""
    row = k // n_phi
    col = k - row * n_phi
    z = -1.0 + 2.0 * (row + s) / n_theta
    z = min(max(z, -1.0), 1.0)
    phi = -math.pi + 2.0 * math.pi * (col + t) / n_phi
    r = math.sqrt(max(0.0, 1.0 - z * z))
    return (r * math.cos(phi), r * math.sin(phi), z)


@jit(inline="always")
def _cdf_find(cdf, slot, u):
    """Largest k with cdf[slot, k] <= u, in [0, K - 1]."""
    lo = 0
    hi = cdf.shape[1] - 1
    while lo + 1 < hi:
        mid = (lo + hi) >> 1
        if cdf[slot, mid] <= u:
            lo = mid
        else:
            hi = mid
    return lo


@jit(inline="always")
def map_sample(cdf, slot, n_theta, n_phi, u0, u1):
    """Sample a direction from map `slot`: u0 picks the bin (and is reused inside it), u1 the
    position along phi. Returns (direction, pdf per unit solid angle); pdf 0 on failure."""
    k = _cdf_find(cdf, slot, u0)
    lo = float(cdf[slot, k])
    width = float(cdf[slot, k + 1]) - lo
    if not (width > 0.0):
        return (0.0, 0.0, 1.0), 0.0
    s = min(max((u0 - lo) / width, 0.0), 1.0 - 1e-12)
    d = bin_direction(k, n_theta, n_phi, s, u1)
    return d, width * (n_theta * n_phi) / FOUR_PI


@jit(inline="always")
def map_pdf(cdf, slot, n_theta, n_phi, d):
    """Density per unit solid angle with which `map_sample` produces direction d."""
    k = direction_bin(d, n_theta, n_phi)
    width = float(cdf[slot, k + 1]) - float(cdf[slot, k])
    return width * (n_theta * n_phi) / FOUR_PI


def build_cdfs(maps):
    """Flat float32 CDFs (S, K + 1) of non-negative maps (S, n_theta, n_phi); also a (S,) bool
    `usable` that is False where a map is zero everywhere (or not finite): no sampling there."""
    s = maps.shape[0]
    flat = np.asarray(maps, dtype=np.float64).reshape(s, -1)
    flat = np.where(np.isfinite(flat) & (flat > 0.0), flat, 0.0)
    cdf = np.zeros((s, flat.shape[1] + 1), dtype=np.float64)
    np.cumsum(flat, axis=1, out=cdf[:, 1:])
    total = cdf[:, -1].copy()
    usable = total > 0.0
    cdf[usable] /= total[usable, None]
    out = cdf.astype(np.float32)
    out[:, -1] = 1.0  # exact: u < 1 always finds a bin of positive width
    out[~usable] = 0.0
    return out, usable


@kernel
def map_sample_batch(cdf, slot, n_theta, n_phi, u):
    """Batch map_sample for tests: u (n, 2) -> directions (n, 3), pdf (n,)."""
    n = u.shape[0]
    d = np.empty((n, 3))
    p = np.empty(n)
    for i in prange(n):
        w, pdf = map_sample(cdf, slot, n_theta, n_phi, u[i, 0], u[i, 1])
        d[i, 0], d[i, 1], d[i, 2] = w
        p[i] = pdf
    return d, p


@kernel
def map_pdf_batch(cdf, slot, n_theta, n_phi, d):
    """Batch map_pdf for tests: d (n, 3) -> (n,)."""
    n = d.shape[0]
    p = np.empty(n)
    for i in prange(n):
        p[i] = map_pdf(cdf, slot, n_theta, n_phi, (d[i, 0], d[i, 1], d[i, 2]))
    return p


@kernel
def bin_of_batch(d, n_theta, n_phi):
    """Bin index of each direction d (n, 3)."""
    n = d.shape[0]
    out = np.empty(n, np.int64)
    for i in prange(n):
        out[i] = direction_bin((d[i, 0], d[i, 1], d[i, 2]), n_theta, n_phi)
    return out
