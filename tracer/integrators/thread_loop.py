"""The per-thread path loop: each thread carries a packet of 16 paths from the camera to their end.

The wavefront (tracer.integrators.path.trace_wave) runs one kernel per stage over every path of a
wave, so each bounce writes every path's state, hits and rays to memory and reads them back,
and packs the survivors in a compaction. For a pass that records nothing and splits nothing
(plain path tracing, and the final passes of a guide that does not split) this loop does the
same work inside one `prange` kernel: a chunk of the wave's paths goes to one thread, which keeps
16 lanes, each holding one path, traces them with one `rtcIntersect16` per bounce, shades every
lane with the wavefront's own `shade_vertex`, traces the shadow rays with one `rtcOccluded16`
and, when a path ends, refills its lane with the chunk's next path, so the packets stay full.

The random numbers are the paths' own (counter-based, tracer.rng): which lane or bounce a path
shares with others changes nothing it draws, and each path adds its emission and its NEE in
the same order as in the wavefront, so the images are bit-identical to the wavefront's
(tests/test_thread_loop.py). Embree only: the Numba BVH keeps the wavefront as the slow twin.
"""
import time

import numpy as np
from numba import prange

from .._jit import kernel
from ..bvh.embree import (_INTERSECT16, _LANES, _OCCLUDED16, _VALID, call4, clear_packet, lane_occluded,
                          load_lane, read_hit)
from ..bvh.numba_bvh import _NumbaThreads
from .path import shade_vertex


@kernel
def trace_paths(fi, fo, scene, plane, centre, refine, scratch, ray_o, ray_d, surf, lt, gs, ps,
                max_depth, rr_depth, nee,
                beta, L, L_cam, depth, prev_pdf, prev_delta, gain, key, pix, aov, aov_open, prev_rec, counts):
    """Trace paths 0 .. n-1 (n = len(ray_o); their first rays ray_o, ray_d, their wave.PathState
    set by the source) to their end. fi, fo: the addresses of rtcIntersect16 and rtcOccluded16;
    scene, plane, centre, refine: the EmbreeAccel's; scratch: one packet row per chunk (the
    chunks are the parallel loop); surf, lt, gs, ps, the limits and the wave.PathState as
    integrators.path.shade (prev_rec unused: nothing is recorded). counts[c] gets chunk c's
    (closest-hit rays, shadow rays)."""
    n = ray_o.shape[0]
    nch = scratch.shape[0]
    LN = _LANES
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        addr = buf.ctypes.data
        nxt = c * n // nch
        hi = (c + 1) * n // nch
        lane = np.full(LN, -1, np.int64)  # path slot of each lane (-1: empty)
        o = np.empty((LN, 3))
        d = np.empty((LN, 3))
        t = np.empty(LN)
        prim = np.empty(LN, np.int32)
        b1 = np.empty(LN)
        b2 = np.empty(LN)
        alive = np.zeros(LN, np.bool_)
        next_o = np.empty((LN, 3))
        next_d = np.empty((LN, 3))
        sh_o = np.empty((LN, 3))
        sh_d = np.empty((LN, 3))
        sh_tmax = np.empty(LN)
        sh_L = np.empty((LN, 3))
        has_shadow = np.zeros(LN, np.bool_)
        rays = 0
        shadows = 0
        while True:
            live = 0
            for k in range(LN):
                if lane[k] < 0 and nxt < hi:
                    lane[k] = nxt
                    for q in range(3):
                        o[k, q] = ray_o[nxt, q]
                        d[k, q] = ray_d[nxt, q]
                    nxt += 1
                if lane[k] >= 0:
                    live += 1
            if live == 0:
                break
            rays += live

            # closest hits of every live lane
            clear_packet(ib)
            any_valid = False
            for k in range(LN):
                t[k] = np.inf
                prim[k] = -1
                b1[k] = 0.0
                b2[k] = 0.0
                if lane[k] >= 0 and load_lane(buf, ib, k, o, d, k, centre, np.inf):
                    any_valid = True
            if any_valid:
                call4(fi, addr + 4 * _VALID * LN, scene, addr, 0)
                for k in range(LN):
                    if lane[k] >= 0:
                        read_hit(buf, ib, k, refine, plane, o, d, t, prim, b1, b2, k)

            for k in range(LN):
                if lane[k] >= 0:
                    v = shade_vertex(lane[k], (d[k, 0], d[k, 1], d[k, 2]), t[k], prim[k], b1[k], b2[k], surf, lt, gs,
                                     ps, max_depth, rr_depth, nee, beta, L, L_cam, depth, prev_pdf, prev_delta,
                                     gain, key, pix, aov, aov_open)
                    alive[k] = v.alive
                    has_shadow[k] = v.shadow
                    for q in range(3):
                        next_o[k, q] = v.next_o[q]
                        next_d[k, q] = v.next_d[q]
                        sh_o[k, q] = v.sh_o[q]
                        sh_d[k, q] = v.sh_d[q]
                        sh_L[k, q] = v.sh_L[q]
                    sh_tmax[k] = v.sh_tmax

            # shadow rays; what gets through adds to the path's radiance
            clear_packet(ib)
            any_valid = False
            for k in range(LN):
                if lane[k] >= 0 and has_shadow[k]:
                    shadows += 1
                    if load_lane(buf, ib, k, sh_o, sh_d, k, centre, sh_tmax[k]):
                        any_valid = True
            if any_valid:
                call4(fo, addr + 4 * _VALID * LN, scene, addr, 0)
            for k in range(LN):
                if lane[k] >= 0 and has_shadow[k] and not lane_occluded(buf, ib, k):
                    i = lane[k]
                    for q in range(3):
                        L[i, q] += sh_L[k, q]

            # the next ray of every path that goes on; an ended path frees its lane
            for k in range(LN):
                if lane[k] >= 0:
                    if alive[k]:
                        for q in range(3):
                            o[k, q] = next_o[k, q]
                            d[k, q] = next_d[k, q]
                    else:
                        lane[k] = -1
        counts[c, 0] = rays
        counts[c, 1] = shadows


def usable(ctx, record, splitting):
    """Whether a wave can take the per-thread loop: Embree, nothing recorded, nothing split."""
    return ctx.path_loop == "thread" and ctx.accel.name == "embree" and not record and not splitting


def run(ctx, buf, n, ps, stats):
    """Trace the n paths the source started in `buf` to their end (as trace_wave's bounce loop)."""
    accel = ctx.accel
    t0 = time.perf_counter()
    counts = np.zeros((accel._rows.shape[0], 2), np.int64)
    with _NumbaThreads(accel.threads):
        trace_paths(_INTERSECT16, _OCCLUDED16, accel._scene, accel._plane, accel.centre, accel.refine, accel._rows,
                    buf.ray_o[:n], buf.ray_d[:n], ctx.surfaces, ctx.lights, ctx.guide_state, ps,
                    ctx.max_depth, ctx.rr_depth, ctx.nee, *buf.path_state(), counts)
    stats.rays += int(counts[:, 0].sum())
    stats.shadow_rays += int(counts[:, 1].sum())
    stats.tick("trace", t0)
