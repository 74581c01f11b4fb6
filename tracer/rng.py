"""Counter-based random numbers: u = hash(seed, pixel, sample index, dimension).

There is no generator state. Each path keeps one 64-bit key, `path_key(seed, pixel, sample)`,
and draws dimension d as `uniform(key, d)`. A render is therefore the same whatever the batch
size, wave size or thread count, and any path can be replayed (gradient-domain random replay,
PSS warps that replace the first dimensions of the stream).

The dimension layout is this table, and nothing else in the code hard-codes a dimension:

    dim                       what
    0, 1                      position inside the pixel (x, y)
    BOUNCE + B*k + 0, 1       bounce k: direction (BSDF or guide sample)
    BOUNCE + B*k + 2          bounce k: lobe choice inside the BSDF
    BOUNCE + B*k + 3          bounce k: strategy choice (BSDF or guide, one-sample MIS)
    BOUNCE + B*k + 4          bounce k: light choice for next-event estimation
    BOUNCE + B*k + 5, 6       bounce k: position on the chosen light
    BOUNCE + B*k + 7          bounce k: Russian roulette

with BOUNCE = 2 and B = 8; bounce k = 0 is the first surface the camera ray hits.

The sample seam: every random number of a camera path is `draw(ps, key, row, dim)`. It reads the
counter-based stream, except for the dimensions that a caller supplies in a `PrimarySamples`
(an external vector per path, e.g. a primary-sample-space warp's output): `pss_dims(m)` lists
the ones a warp replaces, the pixel position and the direction of the first m bounces.
A path split into copies at bounce k (tracer.splitting) keeps its key; copy j >= 1
takes `split_key(key, k, j)`, a fresh key that draws the same table from bounce k on. The weight
window's roulette at bounce k (splitting.split_counts) draws `uniform(split_key(key, k, 0), 0)`,
from a key no copy gets.

Photons (light paths traced to feed guides) have their own keys, `photon_key(seed, iteration,
index)`, which no camera path shares, and their own table:

    dim                       what
    0                         light choice (by power; the environment first)
    1, 2                      position on the light (triangle) / direction (environment)
    3, 4                      emitted direction (triangle) / position on the disk (environment)
    P_BOUNCE + PB*k + 0, 1    photon bounce k: direction (BSDF sample)
    P_BOUNCE + PB*k + 2       photon bounce k: lobe choice
    P_BOUNCE + PB*k + 3       photon bounce k: Russian roulette

with P_BOUNCE = 5 and PB = 4.
"""
from typing import NamedTuple

import numpy as np
from numba import prange, types
from numba.extending import overload

from ._jit import jit, kernel

DIM_PIXEL = 0
BOUNCE = 2
BLOCK = 8
DIR = 0
LOBE = 2
STRATEGY = 3
LIGHT = 4
LIGHT_POS = 5
RR = 7

P_LIGHT = 0
P_POS = 1
P_DIR = 3
P_BOUNCE = 5
P_BLOCK = 4
P_RR = 3
_PHOTON_SALT = 0x70686F746F6E  # "photon": keeps photon keys apart from camera-path keys

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0  # 2^-53


@jit
def mix64(x):
    """SplitMix64 finaliser: a bijective avalanche of a 64-bit integer."""
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


@jit
def path_key(seed, pixel, sample):
    """The key of one path: a hash of (seed, pixel index, sample index)."""
    k = mix64(np.uint64(seed) * _GOLDEN + np.uint64(1))
    k = mix64(k ^ (np.uint64(pixel) * _M2 + np.uint64(1)))
    return mix64(k ^ (np.uint64(sample) * _M1 + _GOLDEN))


@jit
def uniform(key, dim):
    """The path's random number in dimension `dim`, a float64 in [0, 1)."""
    h = mix64(key ^ ((np.uint64(dim) + np.uint64(1)) * _GOLDEN))
    # the top 53 bits; through int64, whose conversion to double is one instruction
    return float(np.int64(h >> _S11)) * _INV53


class PrimarySamples(NamedTuple):
    """External values for some dimensions of the paths of a wave (the sample seam).

    col: (C,) int64, col[d] = the column of u that dimension d < C comes from, -1 where the
    stream supplies it; u: (n, D) float64 in [0, 1), row i for the wave's path slot i (slots >= n,
    e.g. the copies of split paths, read the stream)."""

    col: np.ndarray
    u: np.ndarray


_NONE_SUPPLIED = None


def no_primary_samples():
    """What a source without external samples passes: a PrimarySamples that supplies no dimension
    (every one from the stream). It has the type of one that does, so every kernel that takes ps
    compiles once (a kernel's compile costs up to a minute), for the price of one comparison per
    random number."""
    global _NONE_SUPPLIED
    if _NONE_SUPPLIED is None:
        _NONE_SUPPLIED = PrimarySamples(np.zeros(0, np.int64), np.zeros((0, 0)))
    return _NONE_SUPPLIED


def primary_samples(u, dims):
    """PrimarySamples with u (n, len(dims)) supplying dimensions `dims` (e.g. pss_dims(m))."""
    dims = np.asarray(dims, dtype=np.int64)
    u = np.ascontiguousarray(u, dtype=np.float64)
    if u.ndim != 2 or u.shape[1] != dims.shape[0]:
        raise ValueError(f"u must be (n, {dims.shape[0]}) for dims {dims.tolist()}, got {u.shape}")
    if dims.size and (dims.min() < 0 or np.unique(dims).size != dims.size):
        raise ValueError(f"dims must be distinct and >= 0, got {dims.tolist()}")
    col = np.full(int(dims.max()) + 1 if dims.size else 0, -1, np.int64)
    col[dims] = np.arange(dims.size)
    return PrimarySamples(col, u)


def draw(ps, key, row, dim):
    """Dimension `dim` of the path in wave slot `row` with key `key`: from ps (a PrimarySamples)
    where it supplies that dimension for that row, else (and always when ps is None)
    uniform(key, dim). Jitted code gets the implementation for ps's type (see _draw)."""
    if ps is not None and dim < ps.col.shape[0] and row < ps.u.shape[0]:
        c = ps.col[dim]
        if c >= 0:
            return float(ps.u[row, c])
    return uniform(key, dim)


@overload(draw, inline="always")
def _draw(ps, key, row, dim):
    if isinstance(ps, types.NoneType):
        def stream(ps, key, row, dim):
            return uniform(key, dim)
        return stream

    def supplied(ps, key, row, dim):
        if dim < ps.col.shape[0] and row < ps.u.shape[0]:
            c = ps.col[dim]
            if c >= 0:
                return ps.u[row, c]
        return uniform(key, dim)
    return supplied


@jit
def bounce_dim(depth, slot):
    """Dimension of `slot` (DIR, LOBE, ...) at bounce `depth` (0 = first hit)."""
    return BOUNCE + BLOCK * depth + slot


@jit
def split_key(key, bounce, copy):
    """The key of copy `copy` (>= 1) of a path split at bounce `bounce`."""
    return mix64(key ^ ((np.uint64(bounce) + np.uint64(1)) * _M2 + np.uint64(copy) * _GOLDEN))


def pss_dims(m):
    """(2 + 2m,) int64: the dimensions a primary-sample-space warp of the first m bounces replaces,
    in order: the pixel position (x, y), then the direction (2 dims) of bounces 0 .. m-1."""
    m = int(m)
    if m < 0:
        raise ValueError(f"m must be >= 0, got {m}")
    dims = [DIM_PIXEL, DIM_PIXEL + 1]
    for k in range(m):
        dims += [BOUNCE + BLOCK * k + DIR, BOUNCE + BLOCK * k + DIR + 1]
    return np.array(dims, np.int64)


@jit
def photon_key(seed, iteration, index):
    """The key of photon `index` of guide iteration `iteration`."""
    return path_key(np.uint64(seed) ^ np.uint64(_PHOTON_SALT), index, iteration)


@jit
def photon_dim(bounce, slot):
    return P_BOUNCE + P_BLOCK * bounce + slot


@kernel
def uniform_batch(seed, pixel, sample, dims):
    """u (n, len(dims)) float64 for paths (pixel[i], sample[i]); for tests and experiments."""
    n = pixel.shape[0]
    out = np.empty((n, dims.shape[0]))
    for i in prange(n):
        key = path_key(seed, pixel[i], sample[i])
        for j in range(dims.shape[0]):
            out[i, j] = uniform(key, dims[j])
    return out
