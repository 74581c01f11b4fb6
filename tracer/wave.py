"""The structure-of-arrays state of a wave of paths, and the bookkeeping kernels between stages.

`WaveBuffers` holds every per-path and per-entry array of a wave, allocated once per render;
`compact` packs the continuing paths and the shadow rays after shading; `add_unoccluded` adds
the shadow rays that got through; `sanitize` zeroes (and counts) non-finite samples before a
sink sees them; `Stats` keeps wall time per stage and ray counts.

Paths live in slots (path index i: beta, L, depth, key, pix, ...); the entries of a bounce
(index k) are the active paths in order, `active[k]` being entry k's slot. Hit arrays and the
rays of a bounce are per entry.
"""
import math
import time
from typing import NamedTuple

import numpy as np
from numba import prange

from ._jit import kernel
from .film import N_AOV
from .guiding.records import Records

TRACE_PARTS = ("intersect", "shade", "occluded", "rest")  # Stats.trace_parts: the per-thread loop's steps
_CHUNKS = 64  # compaction splits a batch into this many chunks, counted then written in parallel


# The bundles of a wave's arrays, each declared once: WaveBuffers.path_state(), .continuation(),
# .shadow_rays(), .shadow_queue(). A call site splats them (`*buf.path_state()`) into a kernel
# whose parameters list the fields in the same order: Numba 0.68 loses writes inside a parallel
# loop into arrays that arrive in a tuple, even when the tuple is unpacked before the loop
# (docs/findings.md), so kernels take the arrays one by one. tests/test_seams.py checks each
# kernel's parameter names against the bundles it takes.
class PathState(NamedTuple):
    """Per path slot i: what a path carries from bounce to bounce."""

    beta: np.ndarray  # (n, 3) float64 throughput
    L: np.ndarray  # (n, 3) float64 radiance so far
    L_cam: np.ndarray  # (n, 3) float64 the light the camera ray sees directly (the first hit's emission)
    depth: np.ndarray  # (n,) int32 bounces so far
    prev_pdf: np.ndarray  # (n,) float64 solid-angle density of the last sampled direction
    prev_delta: np.ndarray  # (n,) bool the last direction came from a delta lobe (or the camera)
    gain: np.ndarray  # (n,) float64 product of p_bsdf / p_mixture along the path
    key: np.ndarray  # (n,) uint64 the path's random stream
    pix: np.ndarray  # (n,) int64 film pixel (-1: none)
    aov: np.ndarray  # (n, N_AOV) float64
    aov_open: np.ndarray  # (n,) bool the albedo AOV waits for a non-delta vertex
    prev_rec: np.ndarray  # (n,) int64 record of the path's last vertex (-1: none)


class Continuation(NamedTuple):
    """Per entry k of a bounce: the path goes on (alive) along the ray next_o, next_d."""

    alive: np.ndarray  # (m,) bool
    next_o: np.ndarray  # (m, 3) float64
    next_d: np.ndarray  # (m, 3) float64


class ShadowRays(NamedTuple):
    """Per entry k of a bounce: a shadow ray (has) from o along unit d up to tmax, adding L if unblocked."""

    o: np.ndarray  # (m, 3) float64
    d: np.ndarray  # (m, 3) float64
    tmax: np.ndarray  # (m,) float64
    L: np.ndarray  # (m, 3) float64
    has: np.ndarray  # (m,) bool


class ShadowQueue(NamedTuple):
    """The shadow rays of a bounce packed to the front: path slot, entry, ray and value."""

    path: np.ndarray  # (m,) int64
    entry: np.ndarray  # (m,) int64
    o: np.ndarray  # (m, 3) float64
    d: np.ndarray  # (m, 3) float64
    tmax: np.ndarray  # (m,) float64
    L: np.ndarray  # (m, 3) float64


@kernel
def compact(active, cont, shr, dst, queue):
    """Pack the continuing paths (cont.alive: a Continuation) to the front of dst = (active, ray
    origins, ray directions) and the shadow rays (shr.has: ShadowRays) to the front of the
    ShadowQueue `queue`, keeping their order (queue.entry: the entry k a shadow ray came from).
    Returns (continuing, shadow rays).

    Two parallel passes over chunks: count per chunk, then write at the prefix-sum offsets.
    """
    alive = cont.alive
    next_o = cont.next_o
    next_d = cont.next_d
    sh_o = shr.o
    sh_d = shr.d
    sh_tmax = shr.tmax
    sh_L = shr.L
    has_shadow = shr.has
    dst_active = dst[0]
    dst_o = dst[1]
    dst_d = dst[2]
    sp_path = queue.path
    sp_entry = queue.entry
    sp_o = queue.o
    sp_d = queue.d
    sp_tmax = queue.tmax
    sp_L = queue.L
    n = active.shape[0]
    counts = np.zeros((_CHUNKS + 1, 2), np.int64)
    for c in prange(_CHUNKS):
        lo = c * n // _CHUNKS
        hi = (c + 1) * n // _CHUNKS
        a = 0
        b = 0
        for k in range(lo, hi):
            a += alive[k]
            b += has_shadow[k]
        counts[c + 1, 0] = a
        counts[c + 1, 1] = b
    for c in range(_CHUNKS):
        counts[c + 1, 0] += counts[c, 0]
        counts[c + 1, 1] += counts[c, 1]
    for c in prange(_CHUNKS):
        lo = c * n // _CHUNKS
        hi = (c + 1) * n // _CHUNKS
        j = counts[c, 0]
        js = counts[c, 1]
        for k in range(lo, hi):
            if alive[k]:
                dst_active[j] = active[k]
                for q in range(3):
                    dst_o[j, q] = next_o[k, q]
                    dst_d[j, q] = next_d[k, q]
                j += 1
            if has_shadow[k]:
                sp_path[js] = active[k]
                sp_entry[js] = k
                sp_tmax[js] = sh_tmax[k]
                for q in range(3):
                    sp_o[js, q] = sh_o[k, q]
                    sp_d[js, q] = sh_d[k, q]
                    sp_L[js, q] = sh_L[k, q]
                js += 1
    return counts[_CHUNKS, 0], counts[_CHUNKS, 1]


@kernel
def add_unoccluded(path, occluded, contrib, L, entry, rec_L0, rec_base, record):
    """L[path[j]] += contrib[j] where the shadow ray was not blocked (one entry per path).
    With `record`, the same goes into the L0 of the vertex's record, so that the radiance
    recorded along the vertex's sampled direction leaves out the vertex's own NEE."""
    for j in prange(path.shape[0]):
        if not occluded[j]:
            i = path[j]
            for c in range(3):
                L[i, c] += contrib[j, c]
            if record:
                r = rec_base + entry[j]
                for c in range(3):
                    rec_L0[r, c] += contrib[j, c]


@kernel
def sanitize(L):
    """Zero non-finite samples (never written to the film); returns how many there were."""
    bad = 0
    for i in prange(L.shape[0]):
        if not (math.isfinite(L[i, 0]) and math.isfinite(L[i, 1]) and math.isfinite(L[i, 2])):
            L[i, 0] = 0.0
            L[i, 1] = 0.0
            L[i, 2] = 0.0
            bad += 1
    return bad


class WaveBuffers:
    """Structure-of-arrays path state for waves of up to `size` paths, allocated once; with `split`,
    room for as many copies again (trace_wave's `split`)."""

    def __init__(self, size, split=False):
        self.size = size
        size = 2 * size if split else size
        self.capacity = size
        self.parent = np.zeros(size if split else 1, np.int64)  # path a copy adds into
        self.ks = np.zeros(size if split else 1, np.int64)  # copies per entry, in a bounce that splits
        z3 = lambda: np.zeros((size, 3))  # noqa: E731
        self.pix = np.zeros(size, np.int64)  # film pixel of the path (-1: none, e.g. a probe ray)
        self.index = np.zeros(size, np.int64)  # where the sink puts the path's sample (film pixel, or a probe's row)
        self.key = np.zeros(size, np.uint64)
        self.beta, self.L = z3(), z3()
        self.L_cam = z3()  # the light the camera ray sees directly (integrator.shade)
        self.depth = np.zeros(size, np.int32)
        self.prev_pdf = np.zeros(size)
        self.prev_delta = np.zeros(size, np.bool_)
        self.gain = np.ones(size)
        self.prev_rec = np.zeros(size, np.int64)
        self.aov = np.zeros((size, N_AOV))
        self.aov_open = np.zeros(size, np.bool_)  # the albedo AOV waits for a vertex that is not a delta BSDF
        self.active = np.zeros(size, np.int64)
        self.active2 = np.zeros(size, np.int64)
        self.ray_o, self.ray_d, self.next_o, self.next_d = z3(), z3(), z3(), z3()
        self.alive = np.zeros(size, np.bool_)
        self.sh_o, self.sh_d, self.sh_L = z3(), z3(), z3()
        self.sh_tmax = np.zeros(size)
        self.has_shadow = np.zeros(size, np.bool_)
        self.sp_path = np.zeros(size, np.int64)
        self.sp_entry = np.zeros(size, np.int64)
        self.weight = np.ones(size)  # the source's per-path weight (the sink multiplies it in)
        self.records = Records.allocate(1)  # grown on demand when a guide records
        self.sp_o, self.sp_d, self.sp_L = z3(), z3(), z3()
        self.sp_tmax = np.zeros(size)
        self._hits = ()  # hit arrays of a bounce with copies (copy_hits)

    @staticmethod
    def bytes_for(size, split=False):
        """Bytes that WaveBuffers(size, split) allocates (measured on buffers of 1 and 2 paths)."""
        b1, b2 = (sum(a.nbytes for a in vars(WaveBuffers(k, split)).values() if isinstance(a, np.ndarray))
                  for k in (1, 2))
        return b1 + (b2 - b1) * (size - 1)

    def path_state(self, n=None):
        """The PathState of every slot, or of slots 0 .. n-1 (views)."""
        return PathState(*(a[:n] for a in (self.beta, self.L, self.L_cam, self.depth, self.prev_pdf, self.prev_delta,
                                           self.gain, self.key, self.pix, self.aov, self.aov_open, self.prev_rec)))

    def continuation(self):
        return Continuation(self.alive, self.next_o, self.next_d)

    def shadow_rays(self):
        return ShadowRays(self.sh_o, self.sh_d, self.sh_tmax, self.sh_L, self.has_shadow)

    def shadow_queue(self):
        return ShadowQueue(self.sp_path, self.sp_entry, self.sp_o, self.sp_d, self.sp_tmax, self.sp_L)

    def copy_hits(self, *hits):
        """Arrays with room for `capacity` entries, of the dtypes of `hits` (t, prim, b1, b2): where
        split_paths writes a bounce's hits with its copies. Allocated once."""
        if tuple(a.dtype for a in self._hits) != tuple(a.dtype for a in hits):
            self._hits = tuple(np.empty(self.capacity, a.dtype) for a in hits)
        return self._hits


class Stats:
    """Wall time per stage and ray counts."""

    STAGES = ("camera", "trace", "intersect", "split", "shift", "shade", "occluded", "compact", "film", "record")

    def __init__(self):
        self.time = {s: 0.0 for s in self.STAGES}
        # the per-thread loop's "trace" seconds split by step, in proportion to the processor
        # cycles each took (integrators.thread_loop)
        self.trace_parts = {s: 0.0 for s in TRACE_PARTS}
        self.rays = 0
        self.shadow_rays = 0
        self.samples = 0
        self.nonfinite = 0
        self.split_copies = 0
        self.lane_samples = 0  # samples traced on the lanes of tracer.engine
        self.lane_general = 0  # ... the vertices of theirs that its general kernel shaded
        self.lane_listed = 0  # ... and its listed kernel (engine.listed)
        self.window_ended = 0

    def tick(self, stage, t0):
        t1 = time.perf_counter()
        self.time[stage] += t1 - t0
        return t1
