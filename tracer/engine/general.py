"""The lanes' general kernel: the vertices the fast class does not cover (every material, texture,
light and guide), each shaded by engine.vertex.shade_vertex in float64 on the wave's PathState.
A module of its own because it inlines all of shade_vertex (minutes of compile): Numba caches by
file, so an edit to the lanes' other kernels leaves it compiled."""
import numpy as np
from numba import prange

from .._jit import kernel
from ..guiding.records import RECORD_NONE, record_vertex
from .rows import ALIVE, BR, DELTA, DEPTH, DX, DY, DZ, LR, OX, PDF, SDX, SHADOW, SLOT, SOX, SR, TMAX
from .vertex import shade_vertex

@kernel
def shade_general(lf, li, hit, prim, sh, flags, general, centre, surf, lt, gs, ps, limits, state, rec):
    """Shade the vertex of each lane general[0 .. ] (classify's list) with engine.vertex.shade_vertex
    in float64, on the wave's PathState `state` (its path slot's row, loaded from the lane first:
    throughput, depth, the last direction's density and delta flag), and write back into the lane
    what the fast kernel writes: the next ray, the throughput, depth, density and delta flag after
    it, flags[ALIVE], the shadow ray (flags[SHADOW], its value with the throughput in). The
    emission it finds goes into the slot's radiance directly. limits: (max_depth, rr_depth, nee,
    record, rec_base). With `record` (guiding.records' RECORD_ALL or RECORD_INDIRECT), lane k's vertex
    is record rec_base + k of the guiding.records.Records `rec` (record_emission, record_sampled,
    record_vectors); the lane's radiance so far moves into the slot's first, so that the record's
    L0 holds all of it."""
    max_depth = limits[0]
    rr_depth = limits[1]
    nee = limits[2]
    record = limits[3]
    rec_base = limits[4]
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
    r_strategy = rec.strategy
    for j in prange(general.shape[0]):
        k = general[j]
        i = li[SLOT, k]
        if record != RECORD_NONE:
            r_strategy[rec_base + k] = -1
            for q in range(3):
                L[i, q] += lf[LR + q, k]
                lf[LR + q, k] = 0.0
        for q in range(3):
            beta[i, q] = lf[BR + q, k]
        depth[i] = li[DEPTH, k]
        prev_pdf[i] = lf[PDF, k]
        prev_delta[i] = li[DELTA, k] != 0
        v = shade_vertex((i, np.float64(lf[DX, k]), np.float64(lf[DY, k]), np.float64(lf[DZ, k]), np.float64(hit[0, k]),
                          prim[k], np.float64(hit[1, k]), np.float64(hit[2, k])),
                         surf, lt, gs, ps, (max_depth, rr_depth, nee), beta, L, L_cam, depth, prev_pdf, prev_delta,
                         gain, (key, pix), aov, aov_open)
        flags[ALIVE, k] = np.int32(1) if v.alive else np.int32(0)
        if v.alive:
            for q in range(3):
                lf[OX + q, k] = v.next_o[q] - centre[q]
                lf[DX + q, k] = v.next_d[q]
                lf[BR + q, k] = beta[i, q]
            lf[PDF, k] = prev_pdf[i]
            li[DEPTH, k] = np.int32(depth[i])
            li[DELTA, k] = np.int32(1) if prev_delta[i] else np.int32(0)
        flags[SHADOW, k] = np.int32(1) if v.shadow else np.int32(0)
        if v.shadow:
            for q in range(3):
                sh[SOX + q, k] = v.sh_o[q] - centre[q]
                sh[SDX + q, k] = v.sh_d[q]
                sh[SR + q, k] = v.sh_L[q]
            sh[TMAX, k] = v.sh_tmax
        if record != RECORD_NONE:
            record_vertex(v, L, i, rec_base + k, record, prev_rec, pix, rec)


