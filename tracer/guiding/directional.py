"""Directional sampling maps: full-sphere, world-space, cylindrical, piecewise constant.

A map has `n_theta` rows in z = cos(theta) (world z is the pole) and `n_phi` columns in
phi = atan2(y, x), both uniform, so every bin covers the same solid angle 4 pi / (n_theta n_phi)
(the cylindrical projection preserves area). Bin k = row * n_phi + col.

A map is sampled through an alias table (Walker, built by Vose's method) over its K bins: u0
picks a table entry and, with the entry's threshold q, the entry's bin or its alias; u1 and what
is left of u0 place the direction uniformly in solid angle inside the bin. Sampling is O(1). Each
entry is one 16-byte record (q, alias, P(bin), P(alias)) in float32, so that a sample, and a
density lookup, read a single cache line: with thousands of voxels the maps live in L3 at best,
and every line a vertex touches costs. P holds each bin's probability as the table realises it,
computed in float64 from the stored float32 thresholds and then rounded toward zero to float32:
the density `map_pdf` returns, P K / (4 pi), is the one `map_sample` returns for the same bin,
exactly, integrates to at most 1, and falls short of the frequency the table draws that bin with
by float32 rounding (at most 6e-8 relative).
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
def map_sample(table, slot, n_theta, n_phi, u0, u1):
    """Sample a direction from map `slot`: u0 picks the bin (and is reused inside it), u1 the
    position along phi. Returns (direction, pdf per unit solid angle); pdf 0 on failure."""
    K = n_theta * n_phi
    x = u0 * K
    k = min(int(x), K - 1)
    f = min(max(x - k, 0.0), 1.0)
    qk = float(table[slot, k, 0])
    if f < qk:
        b = k
        s = f / qk
        p = float(table[slot, k, 2])
    else:
        b = int(table[slot, k, 1])
        s = (f - qk) / (1.0 - qk) if qk < 1.0 else 0.5
        p = float(table[slot, k, 3])
    if not (p > 0.0):
        return (0.0, 0.0, 1.0), 0.0
    d = bin_direction(b, n_theta, n_phi, s, u1)
    return d, p * K / FOUR_PI


@jit(inline="always")
def map_pdf(table, slot, n_theta, n_phi, d):
    """Density per unit solid angle with which `map_sample` produces direction d."""
    return float(table[slot, direction_bin(d, n_theta, n_phi), 2]) * (n_theta * n_phi) / FOUR_PI


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
            qk = float(np.float32(q[s, k]))
            prob[s, k] += qk / K
            prob[s, alias[s, k]] += (1.0 - qk) / K


@kernel
def _pack(q, alias, prob, table):
    for s in prange(q.shape[0]):
        for k in range(q.shape[1]):
            table[s, k, 0] = q[s, k]
            table[s, k, 1] = alias[s, k]
            table[s, k, 2] = prob[s, k]
            table[s, k, 3] = prob[s, alias[s, k]]


def build_tables(maps):
    """Sampling tables of non-negative maps (S, n_theta, n_phi): (S, K, 4) float32 records
    (q, alias, P(bin), P(alias)) and usable (S,) bool, False where a map is zero everywhere (or
    not finite): no sampling there (all of its records are 0)."""
    s = maps.shape[0]
    m = np.ascontiguousarray(maps).reshape(s, -1)
    K = m.shape[1]
    if K >= 1 << 24:
        raise ValueError("maps of 2^24 bins or more cannot index their aliases in float32")
    q = np.zeros((s, K))
    alias = np.zeros((s, K), np.int64)
    prob = np.zeros((s, K))
    usable = np.zeros(s, np.bool_)
    table = np.zeros((s, K, 4), np.float32)
    if s:
        _build_alias(m, q, alias, prob, usable)
        # P rounded toward zero: a density that integrates to at most 1 (short by float32 rounding)
        p32 = prob.astype(np.float32)
        over = p32.astype(np.float64) > prob
        p32[over] = np.nextafter(p32[over], np.float32(0.0))
        _pack(q, alias, p32, table)
    return table, usable


@kernel
def map_sample_batch(table, slot, n_theta, n_phi, u):
    """Batch map_sample for tests: u (n, 2) -> directions (n, 3), pdf (n,)."""
    n = u.shape[0]
    d = np.empty((n, 3))
    p = np.empty(n)
    for i in prange(n):
        w, pdf = map_sample(table, slot, n_theta, n_phi, u[i, 0], u[i, 1])
        d[i, 0], d[i, 1], d[i, 2] = w
        p[i] = pdf
    return d, p


@kernel
def map_pdf_batch(table, slot, n_theta, n_phi, d):
    """Batch map_pdf for tests: d (n, 3) -> (n,)."""
    n = d.shape[0]
    p = np.empty(n)
    for i in prange(n):
        p[i] = map_pdf(table, slot, n_theta, n_phi, (d[i, 0], d[i, 1], d[i, 2]))
    return p


@kernel
def bin_of_batch(d, n_theta, n_phi):
    """Bin index of each direction d (n, 3)."""
    n = d.shape[0]
    out = np.empty(n, np.int64)
    for i in prange(n):
        out[i] = direction_bin((d[i, 0], d[i, 1], d[i, 2]), n_theta, n_phi)
    return out
