"""bench.lane_vertex, the lane micro-benchmark of issue 58, on a tiny render of the built-in Cornell
box (every material diffuse)."""
import math

import numpy as np

from bench import lane_vertex as lv


def test_lane_vertex_does_the_work_of_shade():
    """The float32 lane vertex estimates what the path kernel's shade estimates, on the same hits:
    the mean light-sample value per vertex (different random numbers: a z-test, |z| < 4) and the
    emission found (the same hits and MIS inputs: equal to float32 precision). A light sample
    missing its cosine, its pdf's distance term or its MIS weight moves the mean by far more than
    4 standard errors at these 4k vertices (the cosine alone by about 30%); an emission without
    its MIS weight breaks the equality. The vectorised and blocked variants write the same
    outputs as the plain one (only the polynomial sincos differs, by about 1e-6)."""
    calls = lv.capture("scenes/cornell/cornell.obj", 1, 32, 32)
    scene = lv.lane_scene(calls[0][7], calls[0][8])
    lim = lv.limits(calls)
    outs = {}
    for name in ("flat", "flat-fast-poly"):
        kernel = lv.make_kernel(*lv.VARIANTS[name])
        batches = [lv.Batch(c) for c in calls]
        for b in batches:
            b.reset()
            kernel(*b.args(scene, lim))
        outs[name] = np.concatenate([b.out[:, : b.n] for b in batches], axis=1)
    n = sum(b.n for b in batches)
    assert n > 2000
    assert np.all(np.isfinite(outs["flat"]))
    a, b = outs["flat"], outs["flat-fast-poly"]
    assert np.all(np.abs(b - a) <= 1e-4 * (1.0 + np.abs(a)))
    z = lv.same_work(calls, batches)
    assert abs(z["light_sample"]["z"]) < 4.0, z
    assert z["light_sample"]["shade"] > 0.0
    em = z["emission"]
    assert em["shade"] > 0.0
    assert math.isclose(em["lanes"], em["shade"], rel_tol=1e-4), em
