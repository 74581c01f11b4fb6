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
import math
import time as _time

import numpy as np

from ..film import Film
from ..integrator import trace_wave
from ..sources import CameraSource

OFFSETS = ((1, 0), (-1, 0), (0, 1), (0, -1))


class _Discard:
    """A sink that keeps nothing: trace_gradient_wave reads the wave's samples from the buffer."""

    def add(self, pixel, radiance, aov, weight=None, spread=False):
        pass


class GradientFilms:
    """Per-pixel accumulators of a gradient-domain render (each a film.Film of the crop, only the
    base with AOVs): base (the path-traced image, direct light included), indirect (base less the direct light), direct, dx and
    dy (of the indirect part: dx at (x, y) estimates I(x + 1, y) - I(x, y), 2 samples per spp where
    both sides are inside the film)."""

    NAMES = ("base", "indirect", "direct", "dx", "dy")

    def __init__(self, width, height):
        for name in self.NAMES:  # the AOVs are read from the base film alone
            setattr(self, name, Film(width, height, aovs=name == "base"))

    @staticmethod
    def bytes_per_pixel():
        return Film.bytes_per_pixel() + 4 * Film.bytes_per_pixel(aovs=False)


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


def add_gradients(ctx, buf, films, n, G):
    """Add a wave's n base samples (buf: index, L, L_cam, aov) and gradient samples G (n, 4, 3),
    G[:, o] an estimate of I(p + e) - I(p) for offset e = OFFSETS[o], to `films`: dx at (x, y) gets
    the +x sample of (x, y) and minus the -x sample of (x + 1, y) (where x + 1 is inside the film),
    and dy likewise."""
    cw = int(ctx.crop[2])
    pix, aov = buf.index[:n], buf.aov[:n]
    full, cam = buf.L[:n], buf.L_cam[:n]
    films.base.add(pix, full, aov)
    films.direct.add(pix, cam, aov)
    films.indirect.add(pix, full - cam, aov)
    px, py = pix % cw, pix // cw
    for o, (ox, oy) in enumerate(OFFSETS):
        film = films.dx if ox else films.dy
        if ox + oy > 0:
            film.add(pix, G[:, o], aov)
        else:  # the gradient between p - e and p, stored at p - e where that is inside the film
            keep = (px if ox else py) >= 1
            film.add(pix[keep] - (1 if ox else cw), -G[keep, o], aov[keep])


_CAMERA = CameraSource()
_SINK = _Discard()
_SHIFTED = tuple(CameraSource(shift=o) for o in OFFSETS)


def gradient_passes(ctx, buf, stats, films, passes, spp=None, time=None, time_left=None, limit=None,
                    before_wave=None, after_wave=None, shift="replay", roughness=0.001, after_pass=None):
    """Render passes of 1, 2, 4, ... spp into `films` (GradientFilms) until `spp` in all, or, with
    a time budget (`time`), while time_left() (seconds) holds more: each pass at most what the time
    left holds at the speed so far (rounded up), its waves cut by limit(n, film, sweeps)
    (session.wave_limit, never before every pixel of the base film has a sample: the last sweep
    of the last pass partial); appends {spp, time, kind} (and partial, paths, sweeps)
    to `passes` after each. before_wave(n) and after_wave(n) are called around each wave of n base
    paths (before_wave may raise to stop: the films keep every finished wave). shift: "replay"
    (here) or "hybrid" (hybrid.py, reconnecting above `roughness`). after_pass(film) is called
    after each pass with the base film (it may raise to stop)."""
    if shift == "hybrid":
        from . import hybrid

        hb = hybrid.HybridBuffers(buf.size)

        def trace(sample0, g0, m):
            hybrid.trace_hybrid_wave(ctx, buf, hb, films, sample0, g0, m, stats, float(roughness))
    else:
        def trace(sample0, g0, m):
            trace_gradient_wave(ctx, buf, films, sample0, g0, m, stats)
    done = 0
    pass_spp = 1
    npix = ctx.n_pixels
    while True:
        if time is None:
            if done >= spp:
                break
            pass_spp = min(pass_spp, spp - done)
        else:
            left = time_left()
            if (left <= 0.0 and films.base.count.min() >= 1) or (passes and passes[-1].get("partial")):
                break  # (every pixel gets a sample whatever the budget)
            if passes:
                per_spp = sum(p["time"] for p in passes) / sum(p.get("paths", p["spp"] * npix) / npix for p in passes)
                pass_spp = max(1, min(pass_spp, math.ceil(left / per_spp)))
        tp = _time.perf_counter()
        total = pass_spp * npix
        g0 = 0
        while g0 < total:
            m = min(buf.size, total - g0)
            if limit is not None and time is not None:
                m = min(m, limit(m, films.base, 1))
                if m <= 0:
                    break
            if before_wave is not None:
                before_wave(m)
            trace(done, g0, m)
            if after_wave is not None:
                after_wave(m)
            g0 += m
        entry = {"spp": pass_spp, "time": _time.perf_counter() - tp, "kind": "gradient"}
        if g0 < total:
            entry.update(partial=True, paths=g0, sweeps=g0 // npix)
        passes.append(entry)
        if after_pass is not None:
            after_pass(films.base)
        done += pass_spp
        pass_spp *= 2
