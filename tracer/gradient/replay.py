"""Gradient-domain path tracing with the random-replay shift: base image, dx, dy, direct buffer.

Every sample of pixel p = (x, y) is a base path and four offset paths, one per neighbour
(x +- 1, y +- 1): the offset path is traced from the neighbouring pixel with the base path's key
and its position inside the pixel (sources.CameraSource(shift=...)), so it draws the same random
numbers in every dimension (the counter-based stream makes the replay exact) and has the same
density in primary sample space: no Jacobian. Its difference from the base path estimates the
difference of the two pixels' values, I(p + e) - I(p), with little variance where the two paths
see the same light.

Each pixel pair gets two estimates per sample, one from each side (the +x offset of p and the -x
offset of p + e), weighted 1/2 each: with replay the offset and base densities are equal, so this
is the balance heuristic of the two directions. The light seen directly from the camera (what
the first hit emits, or the environment a camera ray escapes to: the integrator's L_cam) goes to
its own buffer and is left out of the base and the gradients the solver sees; it is added back
after the solve.
"""

import numpy as np

from ..integrators.path import trace_wave
from ..sources import CameraSource
from .films import OFFSETS, add_gradients


class _Discard:
    """A sink that keeps nothing: trace_gradient_wave reads the wave's samples from the buffer."""

    def add(self, pixel, radiance, aov, weight=None, spread=False):
        pass


def trace_gradient_wave(ctx, buf, films, sample0, g0, n, stats):
    """Trace paths g0 .. g0+n-1 of a pass (base and its four offsets) and add them to `films`
    (GradientFilms). Each trace leaves its samples in buf (index, L, L_cam, aov of slots 0..n-1),
    read before the next trace overwrites them."""
    G = np.empty((n, len(OFFSETS), 3))
    for o, src in enumerate(_SHIFTED):
        trace_wave(ctx, buf, src, _SINK, sample0, g0, n, stats)
        G[:, o] = buf.L[:n] - buf.L_cam[:n]  # the offset's value, less the light its camera ray sees
    trace_wave(ctx, buf, _CAMERA, _SINK, sample0, g0, n, stats)
    G -= (buf.L[:n] - buf.L_cam[:n])[:, None, :]  # offset minus base: I(p + e) - I(p)
    add_gradients(ctx, buf, films, n, G)


_CAMERA = CameraSource()
_SINK = _Discard()
_SHIFTED = tuple(CameraSource(shift=o) for o in OFFSETS)
