"""Directional sampling maps: full-sphere, world-space, cylindrical, piecewise constant.

A map has `n_theta` rows in z = cos(theta) (world z is the pole) and `n_phi` columns in
phi = atan2(y, x), both uniform, so every bin covers the same solid angle 4 pi / (n_theta n_phi)
(the cylindrical projection preserves area). Bin k = row * n_phi + col.

A map is stored quantised: integer weights w (uint16, the largest bin 65535) with their total W,
so that bin k has probability exactly w_k / W and density w_k K / (4 pi W). Besides the weights a
map keeps only the cumulative sums of its rows (n_theta + 1 uint32). Sampling draws an integer j
uniform in [0, W) from u0, finds its row by binary search in the row sums and its bin by a scan
of that row's weights (bin k owns the integers [C_k, C_k + w_k), C_k the sum of the weights
before it): exactly w_k / W. What is left of u0 and u1 place the direction uniformly in solid
angle inside the bin.

The layout is for the memory a guided vertex touches. A sample reads the row sums and one row
(128 bytes of a 64 x 32 map), a density lookup one weight, which every guided vertex pays twice
(NEE's MIS weight and the BSDF-sampled direction's mixture pdf); a map is 4.1 KiB in all, so
hundreds of them stay in the cache. (An alias table, O(1) but 16 KiB a map beside the weights,
missed the cache so often that shading with a frozen photon guide on Cornell took 1.07 s per
32 spp against 0.76 s with this layout.) Bins below half a quantum of the
largest one get weight 0; keeping every direction with light reachable is the BSDF's part of the
mixture.
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
    # k // n_phi without an integer division (k + 0.5 is far from a multiple of n_phi for k < 2^16)
    row = int((k + 0.5) * (1.0 / n_phi))
    col = k - row * n_phi
    # kept 1e-9 of a bin away from its edges, so that rounding never moves the direction
    # into the neighbouring bin (direction_bin(bin_direction(k, ...)) == k always)
    s = min(max(s, 1e-9), 1.0 - 1e-9)
    t = min(max(t, 1e-9), 1.0 - 1e-9)
    z = -1.0 + (row + s) * (2.0 / n_theta)
    z = min(max(z, -1.0), 1.0)
    phi = -math.pi + (col + t) * (2.0 * math.pi / n_phi)
    r = math.sqrt(max(0.0, 1.0 - z * z))
    return (r * math.cos(phi), r * math.sin(phi), z)


@jit(inline="always")
def map_sample(rowcum, dens, wsum, pscale, slot, n_theta, n_phi, u0, u1):
    """Sample a direction from map `slot`: u0 picks the bin (and is reused inside it), u1 the
    position along phi. Returns (direction, pdf per unit solid angle); pdf 0 on failure."""
    total = wsum[slot]
    if not (total > 0.0):
        return (0.0, 0.0, 1.0), 0.0
    y = u0 * total
    j = min(np.int64(y), np.int64(total) - 1)  # uniform integer in [0, W)
    frac = min(max(y - j, 0.0), 1.0)
    # the row: rowcum[r] <= j < rowcum[r + 1] (binary search; rowcum[0] = 0, rowcum[n_theta] = W)
    lo = 0
    hi = n_theta
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if np.int64(rowcum[slot, mid]) <= j:
            lo = mid
        else:
            hi = mid
    r0 = np.int64(rowcum[slot, lo])
    r1 = np.int64(rowcum[slot, lo + 1])
    # the bin inside the row: the one whose integers [acc, acc + w) hold j, scanned from the
    # nearer end of the row
    base = lo * n_phi
    if 2 * (j - r0) < r1 - r0:
        c = 0
        w = np.int64(dens[slot, base])
        acc = r0
        while c < n_phi - 1 and j >= acc + w:
            acc += w
            c += 1
            w = np.int64(dens[slot, base + c])
    else:
        c = n_phi - 1
        w = np.int64(dens[slot, base + c])
        acc = r1 - w
        while c > 0 and j < acc:
            c -= 1
            w = np.int64(dens[slot, base + c])
            acc -= w
    if not (w > 0 and acc <= j < acc + w):
        return (0.0, 0.0, 1.0), 0.0
    s = (float(j - acc) + frac) / float(w)
    d = bin_direction(base + c, n_theta, n_phi, s, u1)
    return d, float(w) * pscale[slot]


@jit(inline="always")
def map_pdf(dens, pscale, slot, n_theta, n_phi, d):
    """Density per unit solid angle with which `map_sample` produces direction d: the bin's weight
    times pscale = K / (4 pi W) (a multiplication rather than a division: this lookup is on the
    critical path of every guided vertex)."""
    return float(dens[slot, direction_bin(d, n_theta, n_phi)]) * pscale[slot]


WMAX = 65535  # the largest bin's weight


@jit(inline="always")
def quantised_weight(v, mx):
    """A bin's integer weight: round(65535 v / mx) for finite positive v (mx the map's largest
    finite value), else 0."""
    if mx > 0.0 and v > 0.0 and math.isfinite(v):
        return min(int(v / mx * WMAX + 0.5), WMAX)
    return 0


@kernel
def _quantise(m, dens, wsum, pscale, usable):
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
            w = quantised_weight(m[s, k], mx)
            dens[s, k] = w
            total += w
        wsum[s] = total
        pscale[s] = K / (FOUR_PI * total) if total > 0 else 0.0
        usable[s] = total > 0


@kernel
def _row_sums(dens, n_theta, rowcum):
    """Cumulative row sums of the weights dens (S, n_theta * n_phi): rowcum (S, n_theta + 1)."""
    S, K = dens.shape
    n_phi = K // n_theta
    for s in prange(S):
        acc = 0
        rowcum[s, 0] = 0
        for r in range(n_theta):
            for c in range(n_phi):
                acc += dens[s, r * n_phi + c]
            rowcum[s, r + 1] = acc


class MapTables(NamedTuple):
    """Sampling tables of S maps of K = n_theta x n_phi bins."""

    rowcum: np.ndarray  # (S, n_theta + 1) uint32: cumulative sums of the rows' weights (0 ... W)
    dens: np.ndarray  # (S, K) uint16 integer weights w
    wsum: np.ndarray  # (S,) float64 their total W (an integer)
    pscale: np.ndarray  # (S,) float64 K / (4 pi W): a bin's density per unit of weight (0 if W = 0)
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
    n_theta = maps.shape[1]
    out = MapTables(np.zeros((s, n_theta + 1), np.uint32), np.zeros((s, K), np.uint16), np.zeros(s), np.zeros(s),
                    np.zeros(s, np.bool_))
    if s:
        _quantise(m, out.dens, out.wsum, out.pscale, out.usable)
        _row_sums(out.dens, n_theta, out.rowcum)
    return out


@kernel
def map_sample_batch(tables, slot, n_theta, n_phi, u):
    """Batch map_sample for tests: u (n, 2) -> directions (n, 3), pdf (n,)."""
    n = u.shape[0]
    d = np.empty((n, 3))
    p = np.empty(n)
    for i in prange(n):
        w, pdf = map_sample(tables.rowcum, tables.dens, tables.wsum, tables.pscale, slot, n_theta, n_phi, u[i, 0], u[i, 1])
        d[i, 0], d[i, 1], d[i, 2] = w
        p[i] = pdf
    return d, p


@kernel
def map_pdf_batch(tables, slot, n_theta, n_phi, d):
    """Batch map_pdf for tests: d (n, 3) -> (n,)."""
    n = d.shape[0]
    p = np.empty(n)
    for i in prange(n):
        p[i] = map_pdf(tables.dens, tables.pscale, slot, n_theta, n_phi, (d[i, 0], d[i, 1], d[i, 2]))
    return p


@kernel
def bin_of_batch(d, n_theta, n_phi):
    """Bin index of each direction d (n, 3)."""
    n = d.shape[0]
    out = np.empty(n, np.int64)
    for i in prange(n):
        out[i] = direction_bin((d[i, 0], d[i, 1], d[i, 2]), n_theta, n_phi)
    return out
