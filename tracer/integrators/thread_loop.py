"""The per-thread path loop: each thread carries a packet of 16 paths from the camera to their end.

The wavefront (tracer.integrators.path.trace_wave) runs one kernel per stage over every path of a
wave, so each bounce writes every path's state, hits and rays to memory and reads them back,
and packs the survivors in a compaction. For a pass that records nothing (plain path tracing,
and the final passes of every guide, splitting and the weight window included) this loop does
the same work inside one `prange` kernel: a chunk of the wave's paths goes to one thread, which
keeps 16 lanes, each holding one path, traces them with one `rtcIntersect16` per bounce, shades
every lane with the wavefront's own `shade_vertex`, traces the shadow rays with one
`rtcOccluded16` and, when a path ends, refills its lane with a waiting copy of a split path or
the chunk's next path, so the packets stay full.

The random numbers are the paths' own (counter-based, tracer.rng): which lane or bounce a path
shares with others changes nothing it draws, and each path adds its emission and its NEE in
the same order as in the wavefront, so the images are bit-identical to the wavefront's
(tests/test_thread_loop.py). With splitting they are too wherever neither runs out of room for
copies (the wavefront shares its room over the wave, this loop gives each chunk its share).
Embree only: the Numba BVH keeps the wavefront as the slow twin.
"""
import time

import numpy as np
from numba import prange

from .._jit import kernel
from ..bvh.embree import (_INTERSECT16, _LANES, _OCCLUDED16, _VALID, call4, clear_packet, cycles,
                          lane_occluded, load_lane, read_hit)
from ..bvh.numba_bvh import _NumbaThreads
from ..splitting import make_copy, split_count, throughput_plan
from ..wave import TRACE_PARTS
from ..engine.vertex import shade_vertex

_NO_SPLIT = throughput_plan(0.0)


COUNTS = 8  # counts' columns: rays, shadow rays, cycles of intersect, shade, occluded and all, copies, ended


@kernel
def trace_paths(rtc, packet, ray_o, ray_d, surf, lt, gs, ps, limits, state, split, plan, parent, capacity, counts):
    """Trace paths 0 .. n-1 (n = len(ray_o); their first rays ray_o, ray_d, their wave.PathState
    state set by the source) to their end. rtc: the addresses of rtcIntersect16 and rtcOccluded16;
    packet: the EmbreeAccel's packet_args (scene, plane, centre, refine and scratch, one packet row
    per chunk: the chunks are the parallel loop); surf, lt, gs, ps, the limits and the
    wave.PathState state as integrators.path.shade (nothing is recorded: a copy's prev_rec is -1).

    With `split`, a path that hits a surface after its first bounce goes on as the number of
    copies splitting.split_counts gives it (by the splitting.SplitPlan `plan`; 0 copies: the
    weight window ended it), as splitting.split_paths makes them: each its own path slot (chunk c owns slots n + c (capacity - n) / chunks up to the
    next chunk's, and makes fewer copies where they run out), beta and gain divided among them,
    parent[slot] the path it adds into, waiting on a stack for a free lane, with its hit. Each
    chunk adds its copies' radiance into their parents, the latest first, before it ends.

    counts[c] gets chunk c's closest-hit rays, shadow rays, the processor cycles its intersect,
    shade and occluded steps took and all its work took, the copies it made and the paths the
    window ended (COUNTS)."""
    fi = rtc[0]
    fo = rtc[1]
    scene = packet[0]
    plane = packet[1]
    centre = packet[2]
    refine = packet[3]
    scratch = packet[4]
    max_depth = limits[0]
    rr_depth = limits[1]
    nee = limits[2]
    beta = state.beta
    L = state.L
    L_cam = state.L_cam
    depth = state.depth
    prev_pdf = state.prev_pdf
    prev_delta = state.prev_delta
    gain = state.gain
    key = state.key
    pix = state.pix
    aov = state.aov
    aov_open = state.aov_open
    prev_rec = state.prev_rec
    outgoing = plan.outgoing
    pixel_est = plan.pixel_est
    split_hi = plan.hi
    split_low = plan.low
    threshold = plan.threshold
    n = ray_o.shape[0]
    nch = scratch.shape[0]
    LN = _LANES
    for c in prange(nch):
        buf = scratch[c]
        ib = buf.view(np.int32)
        addr = buf.ctypes.data
        nxt = c * n // nch
        hi = (c + 1) * n // nch
        room = capacity - n if split else 0
        slot0 = n + c * room // nch  # this chunk's copy slots: slot0 .. slot1 - 1
        slot1 = n + (c + 1) * room // nch
        used = slot0
        lane = np.full(LN, -1, np.int64)  # path slot of each lane (-1: empty)
        known = np.zeros(LN, np.bool_)  # the lane holds a copy whose hit is known (not traced again)
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
        nq = slot1 - slot0  # the copies waiting for a lane: slot, ray and hit
        q_slot = np.empty(nq, np.int64)
        q_o = np.empty((nq, 3))
        q_d = np.empty((nq, 3))
        q_t = np.empty(nq)
        q_prim = np.empty(nq, np.int32)
        q_b1 = np.empty(nq)
        q_b2 = np.empty(nq)
        waiting = 0
        rays = 0
        shadows = 0
        copies = 0
        ended = 0
        c_int = 0
        c_shade = 0
        c_occ = 0
        c0 = cycles()
        while True:
            live = 0
            for k in range(LN):
                if lane[k] < 0 and waiting > 0:
                    waiting -= 1
                    lane[k] = q_slot[waiting]
                    known[k] = True
                    t[k] = q_t[waiting]
                    prim[k] = q_prim[waiting]
                    b1[k] = q_b1[waiting]
                    b2[k] = q_b2[waiting]
                    for q in range(3):
                        o[k, q] = q_o[waiting, q]
                        d[k, q] = q_d[waiting, q]
                elif lane[k] < 0 and nxt < hi:
                    lane[k] = nxt
                    known[k] = False
                    for q in range(3):
                        o[k, q] = ray_o[nxt, q]
                        d[k, q] = ray_d[nxt, q]
                    nxt += 1
                if lane[k] >= 0:
                    live += 1
            if live == 0:
                break

            # closest hits of every live lane but the copies, whose hit is their parent's
            c1 = cycles()
            clear_packet(ib)
            any_valid = False
            for k in range(LN):
                if lane[k] >= 0 and not known[k]:
                    rays += 1
                    t[k] = np.inf
                    prim[k] = -1
                    b1[k] = 0.0
                    b2[k] = 0.0
                    if load_lane(buf, ib, k, o, d, k, centre, np.inf):
                        any_valid = True
            if any_valid:
                call4(fi, addr + 4 * _VALID * LN, scene, addr, 0)
                for k in range(LN):
                    if lane[k] >= 0 and not known[k]:
                        read_hit(buf, ib, k, refine, plane, o, d, t, prim, b1, b2, k)
            c2 = cycles()
            c_int += c2 - c1

            if split:
                for k in range(LN):
                    if lane[k] < 0 or known[k]:
                        continue
                    m = split_count(k, lane, d, (prim, b1, b2), (surf.tri, surf.normal), beta, gain, (depth, pix, key),
                                    gs, (outgoing, pixel_est, split_hi, split_low, threshold))
                    if m == 0:
                        ended += 1
                        lane[k] = -1
                        continue
                    m = min(m, slot1 - used + 1)
                    if m <= 1:
                        continue
                    i = lane[k]
                    for q in range(3):
                        beta[i, q] /= m
                    gain[i] /= m
                    for j in range(1, m):
                        sl = used
                        used += 1
                        copies += 1
                        make_copy(i, sl, j, beta, gain, L, depth, prev_pdf, prev_delta, key, pix, prev_rec, parent)
                        for q in range(3):
                            q_o[waiting, q] = o[k, q]
                            q_d[waiting, q] = d[k, q]
                        q_slot[waiting] = sl
                        q_t[waiting] = t[k]
                        q_prim[waiting] = prim[k]
                        q_b1[waiting] = b1[k]
                        q_b2[waiting] = b2[k]
                        waiting += 1

            c2 = cycles()
            for k in range(LN):
                known[k] = False
                if lane[k] >= 0:
                    v = shade_vertex((lane[k], d[k, 0], d[k, 1], d[k, 2], t[k], prim[k], b1[k], b2[k]), surf, lt,
                                     gs, ps, (max_depth, rr_depth, nee), beta, L, L_cam, depth, prev_pdf,
                                     prev_delta, gain, (key, pix), aov, aov_open)
                    alive[k] = v.alive
                    has_shadow[k] = v.shadow
                    for q in range(3):
                        next_o[k, q] = v.next_o[q]
                        next_d[k, q] = v.next_d[q]
                        sh_o[k, q] = v.sh_o[q]
                        sh_d[k, q] = v.sh_d[q]
                        sh_L[k, q] = v.sh_L[q]
                    sh_tmax[k] = v.sh_tmax
            c3 = cycles()
            c_shade += c3 - c2

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
            c_occ += cycles() - c3

            # the next ray of every path that goes on; an ended path frees its lane
            for k in range(LN):
                if lane[k] >= 0:
                    if alive[k]:
                        for q in range(3):
                            o[k, q] = next_o[k, q]
                            d[k, q] = next_d[k, q]
                    else:
                        lane[k] = -1
        for sl in range(used - 1, slot0 - 1, -1):  # copies into their parents, the latest first
            for q in range(3):
                L[parent[sl], q] += L[sl, q]
        counts[c, 0] = rays
        counts[c, 1] = shadows
        counts[c, 2] = c_int
        counts[c, 3] = c_shade
        counts[c, 4] = c_occ
        counts[c, 5] = cycles() - c0
        counts[c, 6] = copies
        counts[c, 7] = ended


def usable(ctx, record):
    """Whether a wave can take the per-thread loop: Embree, nothing recorded (it may split); with
    path_loop "lanes", the waves the lanes cannot take."""
    return ctx.path_loop in ("thread", "lanes") and ctx.accel.name == "embree" and not record


def run(ctx, buf, n, ps, stats, split=None):
    """Trace the n paths the source started in `buf` to their end (as trace_wave's bounce loop),
    splitting them by the splitting.SplitPlan `split` (None: never; buf made with split=True)."""
    accel = ctx.accel
    t0 = time.perf_counter()
    packet = accel.packet_args()
    counts = np.zeros((packet[-1].shape[0], COUNTS), np.int64)
    plan = split if split is not None else _NO_SPLIT
    with _NumbaThreads(accel.threads):
        trace_paths((_INTERSECT16, _OCCLUDED16), packet, buf.ray_o[:n], buf.ray_d[:n], ctx.surfaces, ctx.lights,
                    ctx.guide_state, ps, (ctx.max_depth, ctx.rr_depth, ctx.nee), buf.path_state(), split is not None,
                    plan, buf.parent, buf.capacity, counts)
    stats.rays += int(counts[:, 0].sum())
    stats.shadow_rays += int(counts[:, 1].sum())
    stats.split_copies += int(counts[:, 6].sum())
    stats.window_ended += int(counts[:, 7].sum())
    wall = stats.tick("trace", t0) - t0
    total = counts[:, 5].sum()
    if total > 0:  # the loop's wall time split by the cycles each step took, summed over chunks
        for k, name in enumerate(TRACE_PARTS[:3]):
            stats.trace_parts[name] += wall * counts[:, 2 + k].sum() / total
        stats.trace_parts["rest"] += wall * (total - counts[:, 2:5].sum()) / total
