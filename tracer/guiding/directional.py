"""Directional sampling maps: full-sphere, world-space, cylindrical, piecewise constant.

A map has `n_theta` rows in z = cos(theta) (world z is the pole) and `n_phi` columns in
phi = atan2(y, x), both uniform, so every bin covers the same solid angle 4 pi / (n_theta n_phi)
(the cylindrical projection preserves area). Bin k = row * n_phi + col.

A map is sampled through an alias table (Walker, built by Vose's method) over its K bins: u0
picks a table entry and, with the entry's threshold q (float32), the entry's bin or its alias; u1
and what is left of u0 place the direction uniformly in solid angle inside the bin. Sampling is
O(1) and touches two or three cache lines of the map: with thousands of voxels, the maps do not
fit in cache, and a binary search over a CDF cost one cache miss per step. Beside the table,
`prob` (float64) holds each bin's probability as the table actually realises it, computed from
the stored float32 thresholds: the density `map_pdf` returns, prob[k] K / (4 pi), is the one
`map_sample` samples from, to rounding in the last bit of a double.
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
    # kept 1e-9 of a bin away from its edges, so that rounding never moves the direction
    # into the neighbouring bin (direction_bin(bin_direction(k, ...)) == k always)
    s = min(max(s, 1e-9), 1.0 - 1e-9)
    t = min(max(t, 1e-9), 1.0 - 1e-9)
    z = -1.0 + 2.0 * (row + s) / n_theta
    z = min(max(z, -1.0), 1.0)
    phi = -math.pi + 2.0 * math.pi * (col + t) / n_phi
    r = math.sqrt(max(0.0, 1.0 - z * z))
    return (r * math.cos(phi), r * math.sin(phi), z)


@jit(inline="always")
def map_sample(q, alias, prob, slot, n_theta, n_phi, u0, u1):
    """Sample a direction from map `slot`: u0 picks the bin (and is reused inside it), u1 the
    position along phi. Returns (direction, pdf per unit solid angle); pdf 0 on failure."""
    K = n_theta * n_phi
    x = u0 * K
    k = min(int(x), K - 1)
    f = min(max(x - k, 0.0), 1.0)
    qk = float(q[slot, k])
    if f < qk:
        b = k
        s = f / qk
    else:
        b = alias[slot, k]
        s = (f - qk) / (1.0 - qk) if qk < 1.0 else 0.5
    p = prob[slot, b]
    if not (p > 0.0):
        return (0.0, 0.0, 1.0), 0.0
    d = bin_direction(b, n_theta, n_phi, s, u1)
    return d, p * K / FOUR_PI


@jit(inline="always")
def map_pdf(prob, slot, n_theta, n_phi, d):
    """Density per unit solid angle with which `map_sample` produces direction d."""
    return prob[slot, direction_bin(d, n_theta, n_phi)] * (n_theta * n_phi) / FOUR_PI


@kernel
def _build_alias(m, q, alias, prob, usable):
    """Alias tables (Vose) of the rows of m (S, K), in parallel over rows; entries that are not
    finite and positive count as 0."""
    S, K = m.shape
    for s in prange(S):
        total = 0.0
        for k in range(K):
            v = m[s, k]
            if v > 0.0 and math.isfinite(v):
                total += v
        for k in range(K):
            q[s, k] = 1.0
            alias[s, k] = k
            prob[s, k] = 0.0
        if not (total > 0.0) or not math.isfinite(total):
            usable[s] = False
            for k in range(K):
                q[s, k] = 0.0
            continue
        usable[s] = True
        scaled = np.empty(K)
        small = np.empty(K, np.int64)
        large = np.empty(K, np.int64)
        ns = 0
        nl = 0
        for k in range(K):
            v = m[s, k]
            scaled[k] = v * K / total if (v > 0.0 and math.isfinite(v)) else 0.0
            if scaled[k] < 1.0:
                small[ns] = k
                ns += 1
            else:
                large[nl] = k
                nl += 1
        while ns > 0 and nl > 0:
            ns -= 1
            lo = small[ns]
            g = large[nl - 1]
            q[s, lo] = scaled[lo]
            alias[s, lo] = g
            scaled[g] = (scaled[g] + scaled[lo]) - 1.0
            if scaled[g] < 1.0:
                nl -= 1
                small[ns] = g
                ns += 1
        # what is left (rounding) keeps its own bin: q = 1
        # the probabilities the stored float32 thresholds realise
        for k in range(K):
            qk = float(q[s, k])
            prob[s, k] += qk / K
            prob[s, alias[s, k]] += (1.0 - qk) / K


def build_tables(maps):
    """Sampling tables of non-negative maps (S, n_theta, n_phi): thresholds q (S, K) float32,
    alias (S, K) int16, prob (S, K) float64, and usable (S,) bool, False where a map is zero
    everywhere (or not finite): no sampling there."""
    s = maps.shape[0]
    m = np.ascontiguousarray(maps).reshape(s, -1)
    K = m.shape[1]
    q = np.zeros((s, K), np.float32)
    alias = np.zeros((s, K), np.int16 if K <= 32767 else np.int32)
    prob = np.zeros((s, K))
    usable = np.zeros(s, np.bool_)
    if s:
        _build_alias(m, q, alias, prob, usable)
    return q, alias, prob, usable


@kernel
def map_sample_batch(q, alias, prob, slot, n_theta, n_phi, u):
    """Batch map_sample for tests: u (n, 2) -> directions (n, 3), pdf (n,)."""
    n = u.shape[0]
    d = np.empty((n, 3))
    p = np.empty(n)
    for i in prange(n):
        w, pdf = map_sample(q, alias, prob, slot, n_theta, n_phi, u[i, 0], u[i, 1])
        d[i, 0], d[i, 1], d[i, 2] = w
        p[i] = pdf
    return d, p


@kernel
def map_pdf_batch(prob, slot, n_theta, n_phi, d):
    """Batch map_pdf for tests: d (n, 3) -> (n,)."""
    n = d.shape[0]
    p = np.empty(n)
    for i in prange(n):
        p[i] = map_pdf(prob, slot, n_theta, n_phi, (d[i, 0], d[i, 1], d[i, 2]))
    return p


@kernel
def bin_of_batch(d, n_theta, n_phi):
    """Bin index of each direction d (n, 3)."""
    n = d.shape[0]
    out = np.empty(n, np.int64)
    for i in prange(n):
        out[i] = direction_bin((d[i, 0], d[i, 1], d[i, 2]), n_theta, n_phi)
    return out
