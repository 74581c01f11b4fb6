"""Directional sampling maps: full-sphere, world-space, cylindrical, piecewise constant.

A map has `n_theta` rows in z = cos(theta) (world z is the pole) and `n_phi` columns in
phi = atan2(y, x), both uniform, so every bin covers the same solid angle 4 pi / (n_theta n_phi)
(the cylindrical projection preserves area). Bin k = row * n_phi + col.

A map is stored quantised: integer weights w (uint16, the largest bin 65535) with their total W,
so that bin k has probability exactly w_k / W and density w_k K / (4 pi W). Sampling goes through
an alias table (Walker, built by Vose's method in integer arithmetic, so that it realises those
probabilities exactly): u0 picks an entry k and, with the entry's integer threshold q_k in [0, W],
the entry's bin or its alias; u1 and what is left of u0 place the direction uniformly in solid
angle inside the bin. Sampling is O(1).

The layout is for the cost of a density lookup, which every guided vertex pays twice (NEE's MIS
weight and the BSDF-sampled direction's mixture pdf): the weights of a 64 x 32 map take 4 KiB, so
with hundreds of voxels the lookups stay in cache (16-byte float records per bin were 8 times
larger and made a guided pass 40% slower on Cornell). Bins below half a quantum of the largest one
get weight 0; keeping every direction with light reachable is the BSDF's part of the mixture.
"""
import math
from typing import NamedTuple

import numpy as np
from numba import prange

from .._jit import jit, kernel

FOUR_PI = 4.0 * math.pi


# atan(r) / r for r in [0, 1] as a polynomial in r^2 (fitted here, |error| < 1.7e-6 rad)
_ATAN = (0.99997724, -0.33262322, 0.19354295, -0.11643318, 0.05265485, -0.01172215)
_ATAN_ERR = 1e-5  # radians: a bound on the fit's error, with a margin of 6


@jit(inline="always")
def atan2_approx(y, x):
    """atan2(y, x) within _ATAN_ERR, several times faster than libm's (which the bins pay twice per
    guided vertex); 0 at the origin."""
    ax = abs(x)
    ay = abs(y)
    mx = max(ax, ay)
    if mx == 0.0:
        return 0.0
    r = min(ax, ay) / mx
    q = r * r
    a = r * (_ATAN[0] + q * (_ATAN[1] + q * (_ATAN[2] + q * (_ATAN[3] + q * (_ATAN[4] + q * _ATAN[5])))))
    if ay > ax:
        a = 0.5 * math.pi - a
    if x < 0.0:
        a = math.pi - a
    return -a if y < 0.0 else a


@jit(inline="always")
def direction_bin(d, n_theta, n_phi):
    """Bin index of the unit world direction d: the column is floor((atan2(y, x) + pi) n_phi / 2 pi),
    from the fast atan2 unless that lands within its error bound of a column edge (then libm's
    atan2 decides), so the bin is exactly the one libm's atan2 gives."""
    row = int((d[2] + 1.0) * 0.5 * n_theta)
    row = min(max(row, 0), n_theta - 1)
    scale = (0.5 / math.pi) * n_phi
    t = (atan2_approx(d[1], d[0]) + math.pi) * scale
    col = int(t)
    f = t - col
    margin = _ATAN_ERR * scale
    if not (margin < f < 1.0 - margin):
        col = int((math.atan2(d[1], d[0]) + math.pi) * scale)
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
def map_sample(table, dens, wsum, slot, n_theta, n_phi, u0, u1):
    """Sample a direction from map `slot`: u0 picks the bin (and is reused inside it), u1 the
    position along phi. Returns (direction, pdf per unit solid angle); pdf 0 on failure."""
    K = n_theta * n_phi
    total = wsum[slot]
    x = u0 * K
    k = min(int(x), K - 1)
    y = min(max(x - k, 0.0), 1.0) * total
    qk = float(table[slot, k, 0])
    if y < qk:
        b = k
        s = y / qk
    else:
        b = int(table[slot, k, 1])
        s = (y - qk) / (total - qk) if qk < total else 0.5
    w = float(dens[slot, b])
    if not (w > 0.0):
        return (0.0, 0.0, 1.0), 0.0
    d = bin_direction(b, n_theta, n_phi, s, u1)
    return d, w * K / (FOUR_PI * total)


@jit(inline="always")
def map_pdf(dens, wsum, slot, n_theta, n_phi, d):
    """Density per unit solid angle with which `map_sample` produces direction d."""
    K = n_theta * n_phi
    w = float(dens[slot, direction_bin(d, n_theta, n_phi)])
    return w * K / (FOUR_PI * wsum[slot]) if w > 0.0 else 0.0


WMAX = 65535  # the largest bin's weight


@kernel
def _quantise(m, dens, wsum, usable):
    """Integer weights of the rows of m (S, K): round(65535 v / max), 0 where v is not finite and
    positive; wsum their total, usable False where it is 0."""
    S, K = m.shape
    for s in prange(S):
        mx = 0.0
        for k in range(K):
            v = m[s, k]
            if v > mx and math.isfinite(v):
                mx = v
        total = 0
        for k in range(K):
            v = m[s, k]
            w = 0
            if mx > 0.0 and v > 0.0 and math.isfinite(v):
                w = min(int(v / mx * WMAX + 0.5), WMAX)
            dens[s, k] = w
            total += w
        wsum[s] = total
        usable[s] = total > 0


@kernel
def _build_alias(dens, wsum, table):
    """Alias tables (Vose, exact in integers) of the weights dens (S, K) with totals wsum: entry k
    keeps its own bin when y < table[k, 0] (y uniform in [0, W)), else goes to table[k, 1]."""
    S, K = dens.shape
    for s in prange(S):
        W = np.int64(wsum[s])
        for k in range(K):
            table[s, k, 0] = 0
            table[s, k, 1] = k
        if W <= 0:
            continue
        scaled = np.empty(K, np.int64)  # w_k K, against the full entry W
        small = np.empty(K, np.int64)
        large = np.empty(K, np.int64)
        ns = 0
        nl = 0
        for k in range(K):
            scaled[k] = np.int64(dens[s, k]) * K
            if scaled[k] < W:
                small[ns] = k
                ns += 1
            else:
                large[nl] = k
                nl += 1
        while ns > 0 and nl > 0:
            ns -= 1
            lo = small[ns]
            g = large[nl - 1]
            table[s, lo, 0] = scaled[lo]
            table[s, lo, 1] = g
            scaled[g] -= W - scaled[lo]
            if scaled[g] < W:
                nl -= 1
                small[ns] = g
                ns += 1
        # integer arithmetic leaves every remaining entry exactly full
        for j in range(nl):
            table[s, large[j], 0] = W
        for j in range(ns):
            table[s, small[j], 0] = W


class MapTables(NamedTuple):
    """Sampling tables of S maps of K bins."""

    table: np.ndarray  # (S, K, 2) uint32: (threshold q in [0, W], alias bin)
    dens: np.ndarray  # (S, K) uint16 integer weights w
    wsum: np.ndarray  # (S,) float64 their total W (an integer)
    usable: np.ndarray  # (S,) bool: W > 0


def probabilities(tables):
    """(S, K) float64 probability of each bin of MapTables, w / W (0 for unusable maps)."""
    return tables.dens / np.where(tables.wsum > 0, tables.wsum, 1.0)[:, None]


def build_tables(maps):
    """Sampling tables (MapTables) of non-negative maps (S, n_theta, n_phi); a map that is zero
    everywhere (or not finite) is not usable: no sampling there."""
    s = maps.shape[0]
    m = np.ascontiguousarray(maps).reshape(s, -1)
    K = m.shape[1]
    if K > 1 << 16:
        raise ValueError("maps of more than 2^16 bins cannot keep their weights' total in uint32")
    out = MapTables(np.zeros((s, K, 2), np.uint32), np.zeros((s, K), np.uint16), np.zeros(s), np.zeros(s, np.bool_))
    if s:
        _quantise(m, out.dens, out.wsum, out.usable)
        _build_alias(out.dens, out.wsum, out.table)
    return out


@kernel
def map_sample_batch(tables, slot, n_theta, n_phi, u):
    """Batch map_sample for tests: u (n, 2) -> directions (n, 3), pdf (n,)."""
    n = u.shape[0]
    d = np.empty((n, 3))
    p = np.empty(n)
    for i in prange(n):
        w, pdf = map_sample(tables.table, tables.dens, tables.wsum, slot, n_theta, n_phi, u[i, 0], u[i, 1])
        d[i, 0], d[i, 1], d[i, 2] = w
        p[i] = pdf
    return d, p


@kernel
def map_pdf_batch(tables, slot, n_theta, n_phi, d):
    """Batch map_pdf for tests: d (n, 3) -> (n,)."""
    n = d.shape[0]
    p = np.empty(n)
    for i in prange(n):
        p[i] = map_pdf(tables.dens, tables.wsum, slot, n_theta, n_phi, (d[i, 0], d[i, 1], d[i, 2]))
    return p


@kernel
def bin_of_batch(d, n_theta, n_phi):
    """Bin index of each direction d (n, 3)."""
    n = d.shape[0]
    out = np.empty(n, np.int64)
    for i in prange(n):
        out[i] = direction_bin((d[i, 0], d[i, 1], d[i, 2]), n_theta, n_phi)
    return out
