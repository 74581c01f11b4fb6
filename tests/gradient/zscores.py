"""Per-pixel z-scores of a gradient-domain render's dx and dy against an independent path render."""
import os

import numpy as np

import tracer
from tests import scenes
from tracer.testing.stats import assert_clean

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def gradient_z(name, size, spp, ref_spp, **kw):
    """[(key, z)] for dx and dy of a size x size render of built-in scene `name` (tests.scenes.builtin:
    `NAME-textured` too): scene_gradient_z's."""
    return scene_gradient_z(scenes.builtin(ROOT, name, size, size), spp, ref_spp, **kw)


def scene_gradient_z(scene, spp, ref_spp, **kw):
    """[(key, z)] for dx and dy of a gpt render of `scene` (spp, seed 11, max_depth 5, render
    kwargs kw): per-pixel z-scores, where no emitter is seen directly from either pixel, of the
    gradient against the difference of the two pixels of a path render (ref_spp, seed 12), with
    the variances of both."""
    g = tracer.render(scene, spp=spp, integrator="gpt", recon="none", seed=11, max_depth=5, **kw)
    p = tracer.render(scene, spp=ref_spp, seed=12, max_depth=5)
    assert_clean(g)
    img = p.image.astype(np.float64).mean(axis=2)
    var = p.variance.astype(np.float64).mean(axis=2)
    lit = g.buffers["direct"].astype(np.float64).max(axis=2) > 0.0
    out = []
    for key, axis in (("dx", 1), ("dy", 0)):
        d = g.buffers[key].astype(np.float64).mean(axis=2)
        dv = g.buffers[key + "_variance"].astype(np.float64).mean(axis=2)
        if axis == 1:
            diff, dvar = img[:, 1:] - img[:, :-1], var[:, 1:] + var[:, :-1]
            d, dv, ok = d[:, :-1], dv[:, :-1], ~(lit[:, 1:] | lit[:, :-1])
        else:
            diff, dvar = img[1:] - img[:-1], var[1:] + var[:-1]
            d, dv, ok = d[:-1], dv[:-1], ~(lit[1:] | lit[:-1])
        tot = dv + dvar
        ok &= tot > 0
        out.append((key, (d - diff)[ok] / np.sqrt(tot[ok])))
    return out
