"""The lanes' float32 arithmetic: constants, the 32-bit random numbers and the helpers that LLVM
packs 8 or 16 lanes to an instruction (scalar arguments only, 32-bit integers: docs/throughput.md,
"The lane engine"). The fast class's kernels and the glossy class's draw their random numbers here.
"""
import math

import numpy as np

from .._jit import jit

F = np.float32
U32 = np.uint32
ZERO, ONE = F(0.0), F(1.0)
INV_PI = F(1.0 / math.pi)
HALF_PI = F(0.5 * math.pi)
INV24 = F(2.0 ** -24)
SHORT = F(1.0 - 1e-3)  # a shadow ray ends this fraction of the way to its light point
TINY = F(1e-20)
HALF = F(0.5)
TWO23 = F(2.0 ** 23)
BIG = F(1e30)  # a texel coordinate past this is not finite (material.texture_eval: black)
RR_MAX = 0.95  # the roulette's survival cap (GuideState.rr_max's default), the fast class's
# Taylor coefficients of sin and cos on [0, pi/2] (errors below 4e-6 and 5e-7 there)
S3, S5, S7, S9, S11 = (F(-1.0 / 6.0), F(1.0 / 120.0), F(-1.0 / 5040.0), F(1.0 / 362880.0), F(-1.0 / 39916800.0))
C2, C4, C6, C8, C10 = (F(-0.5), F(1.0 / 24.0), F(-1.0 / 720.0), F(1.0 / 40320.0), F(-1.0 / 3628800.0))
_GOLDEN32, _FM1, _FM2 = U32(0x9E3779B9), U32(0x85EBCA6B), U32(0xC2B2AE35)
_S16, _S13, _S8 = U32(16), U32(13), U32(8)
# tracer.rng's dimensions of bounce k: BOUNCE + BLOCK k + slot (direction 0, 1; lobe 2; the light's alias coin 3;
# the light's column 4; its point 5, 6; roulette 7)
BOUNCE, BLOCK = 2, 8
D_DIR, D_LOBE, D_COIN, D_LIGHT, D_POS, D_RR = 0, 2, 3, 4, 5, 7
TWO32 = 2.0 ** 32
_STRATEGY = 1 << 24  # past every bounce's dimensions (BOUNCE + BLOCK x 4096)


@jit(inline="always")
def strategy_dim(depth):
    """The dimension of the coin between a guide's map and the BSDF at bounce `depth` (0: the first hit):
    one of its own past the bounces' blocks, whose eight slots the lanes use all (slot 3, tracer.rng's
    STRATEGY, holds their alias coin)."""
    return _STRATEGY + depth


@jit(inline="always")
def hash32(key, dim):
    """uint32: MurmurHash3's finaliser of key + (dim + 1) x golden (SplitMix's sequence in 32 bits),
    every integer kept 32-bit so that LLVM packs 8 or 16 lanes."""
    x = U32(U32(key) + U32(U32(dim + 1) * _GOLDEN32))
    x = U32(U32(x ^ (x >> _S16)) * _FM1)
    x = U32(U32(x ^ (x >> _S13)) * _FM2)
    return U32(x ^ (x >> _S16))


@jit(inline="always")
def rand32(key, dim):
    """float32 in [0, 1): the top 24 bits of hash32(key, dim)."""
    return F(np.int32(hash32(key, dim) >> _S8)) * INV24


@jit(inline="always")
def alias_column(key, dim, n):
    """A column 0 .. n-1 of an alias table: the high half of hash32(key, dim) x n, each column's
    probability 1/n to within 1/2^32 (a float32 uniform times n would leave the coin a resolution
    of n/2^24)."""
    return np.int32((np.uint64(hash32(key, dim)) * np.uint64(n)) >> np.uint64(32))


def alias_thresholds(prob):
    """An alias table's keep probabilities as uint32 thresholds for hash32: keep column j when
    hash32 < t[j], exact to 1/2^32."""
    return np.minimum(np.round(np.asarray(prob, np.float64) * TWO32), TWO32 - 1.0).astype(np.uint32)


@jit(inline="always")
def floor32(x):
    """floor of a float32, in float32 (2^23 and past are integers already), kept to ops LLVM packs."""
    t = F(np.int32(x)) if abs(x) < TWO23 else x
    return t - ONE if t > x else t


@jit(inline="always")
def sincos2pi(u):
    """(cos, sin) of 2 pi u for u in [0, 1): the quadrant from 4u, then Taylor polynomials on [0, pi/2)."""
    v = u * F(4.0)
    q = min(np.int32(v), np.int32(3))
    a = (v - F(q)) * HALF_PI
    a2 = a * a
    s = a * (ONE + a2 * (S3 + a2 * (S5 + a2 * (S7 + a2 * (S9 + a2 * S11)))))
    c = ONE + a2 * (C2 + a2 * (C4 + a2 * (C6 + a2 * (C8 + a2 * C10))))
    cq = c if q == 0 else (-s if q == 1 else (-c if q == 2 else s))
    sq = s if q == 0 else (c if q == 1 else (-s if q == 2 else -c))
    return cq, sq
