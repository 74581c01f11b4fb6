"""Path vertices recorded for guides that learn, and the radiance that came back along them.

With recording on, the shading kernel writes one record per surface vertex where a direction was
sampled (tracer.integrator.shade); once the path has ended, `finalize_records` turns what the path
gathered after the vertex into the radiance along the vertex's direction. A guide receives the
records of each wave in `observe(records)`.
"""
import math
from typing import NamedTuple

import numpy as np
from numba import prange

from .._jit import kernel


class Records(NamedTuple):
    """Path vertices of a wave (R entries; strategy -1 = unused entry)."""

    x: np.ndarray  # (R, 3) float32 world position
    n: np.ndarray  # (R, 3) float32 geometric normal, on the side the path arrived from
    wi: np.ndarray  # (R, 3) float32 sampled world direction
    pdf: np.ndarray  # (R,) float32 solid-angle density it was sampled with (the MIS mixture)
    fcos: np.ndarray  # (R,) float32 luminance of f(wo, wi) |cos|
    strategy: np.ndarray  # (R,) int8 0 = BSDF, 1 = guide, -1 = no record
    node: np.ndarray  # (R,) int32 guide voxel (-1: none)
    path: np.ndarray  # (R,) int64 path slot in the wave
    pixel: np.ndarray  # (R,) int64 film pixel of the path
    L0: np.ndarray  # (R, 3) float64 path radiance when the direction was sampled
    beta: np.ndarray  # (R, 3) float64 throughput after the vertex (0 if the path ended)
    pb: np.ndarray  # (R,) float32 the BSDF's own density of wi (pdf is the mixture's)
    radiance: np.ndarray  # (R,) float32 luminance of the radiance that came back along wi
    prev: np.ndarray  # (R,) int64 record of the path's previous vertex (-1: first hit, or after a delta vertex)
    direct: np.ndarray  # (R,) float32 luminance of the emission wi hits directly, without MIS weight (0: none)
    plight: np.ndarray  # (R,) float32 next-event estimation's solid-angle density of that emission (0: none)

    @staticmethod
    def allocate(size):
        f3 = lambda: np.zeros((size, 3), np.float32)  # noqa: E731
        return Records(x=f3(), n=f3(), wi=f3(), pdf=np.zeros(size, np.float32), fcos=np.zeros(size, np.float32),
                       strategy=np.full(size, -1, np.int8), node=np.full(size, -1, np.int32),
                       path=np.zeros(size, np.int64), pixel=np.zeros(size, np.int64), L0=np.zeros((size, 3)),
                       beta=np.zeros((size, 3)), pb=np.zeros(size, np.float32), radiance=np.zeros(size, np.float32),
                       prev=np.full(size, -1, np.int64), direct=np.zeros(size, np.float32),
                       plight=np.zeros(size, np.float32))

    def grown(self, size, used):
        """A larger Records holding the first `used` entries of this one."""
        new = Records.allocate(size)
        for a, b in zip(self, new):
            b[:used] = a[:used]
        return new

    def head(self, n):
        """A view of the first n entries."""
        return Records(*(a[:n] for a in self))


@kernel
def finalize_records(strategy, path, beta, L0, radiance, L):
    """Radiance along each record's direction once its path has ended: luminance of
    (L_end - L0) / beta per channel (0 where beta is 0, negative or not finite)."""
    for r in prange(strategy.shape[0]):
        if strategy[r] < 0:
            continue
        i = path[r]
        v = 0.0
        for c in range(3):
            b = beta[r, c]
            if b > 0.0:
                v += (0.2126, 0.7152, 0.0722)[c] * (L[i, c] - L0[r, c]) / b
        radiance[r] = v if (v > 0.0 and math.isfinite(v)) else 0.0
