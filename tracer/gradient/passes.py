"""The passes of a gradient-domain render: 1, 2, 4, ... spp of base and offset paths into the
GradientFilms, by the replay shift (replay.py) or the hybrid shift (hybrid.py), until an spp count
or a time budget is spent."""
import math
import time as _time

from . import hybrid
from .replay import trace_gradient_wave


def gradient_passes(ctx, buf, stats, films, passes, spp=None, time=None, time_left=None, limit=None,
                    before_wave=None, after_wave=None, shift="replay", roughness=0.001, after_pass=None):
    """Render passes of 1, 2, 4, ... spp into `films` (GradientFilms) until `spp` in all, or, with
    a time budget (`time`), while time_left() (seconds) holds more: each pass at most what the time
    left holds at the speed so far (rounded up), its waves cut by limit(n, film, sweeps)
    (session.wave_limit, never before every pixel of the base film has a sample: the last sweep
    of the last pass partial); appends {spp, time, kind} (and partial, paths, sweeps)
    to `passes` after each. before_wave(n) and after_wave(n) are called around each wave of n base
    paths (before_wave may raise to stop: the films keep every finished wave). shift: "replay"
    (replay.py) or "hybrid" (hybrid.py, reconnecting above `roughness`). after_pass(film) is called
    after each pass with the base film (it may raise to stop)."""
    if shift == "hybrid":
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
