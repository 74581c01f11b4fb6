"""Wavefront unidirectional path tracing: NEE with MIS (power heuristic), Russian roulette.

Python drives the stages of one wave of paths; every stage is one Numba kernel over
structure-of-arrays path state (tracer.wave, `prange` over paths), except the ray queries,
which go to the accel (Embree or the Numba BVH) in one batch per stage:

    source (camera, probe rays, ...) -> [intersect] -> split (final passes of a guide)
    -> shade: emission (MIS), NEE sample, direction from the mixture, record, roulette
    -> compact -> [occluded] -> add NEE -> repeat -> sink (film, or the caller's samples)

With path_loop="lanes" (the default) a wave goes to the lane engine (tracer.engine.lanes) where
it can (Embree, no external primary samples; its records from the lanes' general kernel). A wave
that records nothing takes the per-thread path loop with path_loop="thread" (tracer.integrators.
thread_loop, Embree only): the same stages per packet of 16 paths inside one kernel. Both shade
a vertex with `shade_vertex` (tracer.engine.vertex), so their images are the same bit for bit.

The steps of `shade_vertex` are the helpers of tracer.shading; its random numbers go through the sample
seam `rng.draw` (the stream, or a source's external primary samples). With a guide, a non-delta
vertex asks it where its map is (`guiding.contract.locate`: a voxel's map, or a per-pixel map at
the first bounce) and draws its direction from the one-sample MIS mixture p = a p_bsdf + (1 - a)
p_guide (the strategy picked by the STRATEGY dimension); that mixture density is the one NEE's and
the emission's MIS weights use. A guide that learns gets, per vertex, a record (tracer.guiding.
records: position, normal, pixel, sampled direction, strategy, mixture pdf, |f cos| and, once the
path has ended, the radiance that came back along the direction: (L_end - L_at_vertex) /
throughput after it, with the vertex's own NEE excluded and the emission its direction hit
counted without MIS weight, so that the record is an unbiased estimate of the incident radiance
along that direction).

Depths follow Mitsuba 3: `max_depth` 1 shows emitters seen directly, 2 adds direct light,
-1 is unlimited (bounded at MAX_BOUNCES for safety); Russian roulette applies from the
bounce numbered `rr_depth` on, continuing with probability min(max(beta / gain), 0.95), where
beta / gain is the throughput BSDF sampling would have given (shading.russian_roulette), drawn
before the sampled ray is traced. A guide may set another (GuideState.rr_late, rr_min, rr_max:
Practical Path Guiding's reference draws it after the ray, once the emission it hits is counted,
so that a vertex's record always holds that emission) and records of X / q (rec_q).
"""
import time

import numpy as np
from numba import prange

from .._jit import kernel
from ..engine.vertex import MAX_BOUNCES, shade_vertex
from ..film import aovs_of, combine_films
from ..guiding.records import RECORD_ALL, RECORD_INDIRECT, RECORD_NONE, finalize_records, record_vertex
from ..shading import write_shadow
from ..splitting import merge_copies, split_wave
from ..result import RenderResult, report_dark
from ..wave import WaveBuffers, add_unoccluded, compact, sanitize
from .base import Integrator

__all__ = ["MAX_BOUNCES", "PathIntegrator", "shade", "trace_wave"]




@kernel
def shade(active, ray_o, ray_d, hits, surf, lt, gs, ps, limits, state, cont, shr, record, rec_base, rec):
    """One bounce for every active path: emission, NEE sample, direction sample, roulette.

    Entry k's ray is ray_o/ray_d[k], its hit in hits = (t, prim, b1, b2), its path slot active[k];
    surf the scene's material.Surfaces; lt the lights; gs the guide's GuideState (empty: BSDF
    sampling); ps the wave's PrimarySamples; limits = (max_depth, rr_depth, nee) (nee False: no
    light sampling; emission found by a path then counts in full, without MIS); state the
    wave.PathState of every slot (L_cam[i] gets the light the camera ray sees directly: the
    emission at the first hit, or the environment if it escapes); cont the wave.Continuation of
    entry k (its next ray) and shr its wave.ShadowRays (origin, unit direction, tmax, unoccluded
    value); the record mode and base, and rec the guiding.records.Records.

    Records (record RECORD_ALL or RECORD_INDIRECT): the vertex of entry k goes to record
    rec_base + k of the r_* arrays (strategy -1 where nothing was sampled).
    RECORD_ALL: records of the full incident radiance; RECORD_INDIRECT: of the radiance less the
    emission the direction hits directly (the part NEE samples). prev_rec[i] is the record of the
    path's last vertex: emission found by its sampled direction counts there in full
    (RECORD_ALL), not MIS-weighted, since the vertex's own NEE, which covers the rest, is not in
    its record; or not at all (RECORD_INDIRECT). A record's `prev` is the record of the path's
    vertex before it (-1 at the first hit and after a delta vertex).
    """
    t = hits[0]
    prim = hits[1]
    b1 = hits[2]
    b2 = hits[3]
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
    alive = cont.alive
    next_o = cont.next_o
    next_d = cont.next_d
    sh_o = shr.o
    sh_d = shr.d
    sh_tmax = shr.tmax
    sh_L = shr.L
    has_shadow = shr.has
    r_strategy = rec.strategy
    for k in prange(active.shape[0]):
        i = active[k]
        if record != RECORD_NONE:
            r_strategy[rec_base + k] = -1
        v = shade_vertex((i, ray_d[k, 0], ray_d[k, 1], ray_d[k, 2], t[k], prim[k], b1[k], b2[k]), surf, lt, gs, ps,
                         (max_depth, rr_depth, nee), beta, L, L_cam, depth, prev_pdf, prev_delta, gain, (key, pix),
                         aov, aov_open)
        alive[k] = v.alive
        has_shadow[k] = False
        if v.shadow:
            write_shadow(k, v.sh_o, v.sh_d, v.sh_tmax, v.sh_L, sh_o, sh_d, sh_tmax, sh_L, has_shadow)
        if v.alive:
            for c in range(3):
                next_o[k, c] = v.next_o[c]
                next_d[k, c] = v.next_d[c]
        if record != RECORD_NONE:
            record_vertex(v, L, i, rec_base + k, record, prev_rec, pix, rec)


def warm_up_shadows(ctx):
    """Dispatch the wavefront's shadow-ray step (ctx.accel.occluded, add_unoccluded) with trace_wave's
    argument types: the throwaway paths of a render's warm-up may trace no shadow ray, and then
    these compiled inside a guide's first recording pass (3.5 s of a 5 s budget on a new install)."""
    buf = WaveBuffers(1)
    buf.sp_d[0, 2] = 1.0  # a ray of length 0 from the origin: its answer is not used
    occ = ctx.accel.occluded(buf.sp_o[:1], buf.sp_d[:1], buf.sp_tmax[:1])
    add_unoccluded(buf.sp_path[:0], occ[:0], buf.sp_L[:0], buf.L, buf.sp_entry[:0], buf.records.L0, 0, False)


def trace_wave(ctx, buf, source, sink, sample0, g0, n, stats, observe=None, direct=True, split=None):
    """Trace paths g0 .. g0+n-1 of `source` (tracer.sources) for the pass that starts at sample
    index sample0, and give the finished samples to `sink` (a Film, or a film.SampleSink):
    sink.add(index, radiance, aov, weight[, spread=True]) (see sources: the index is the film pixel,
    or a probe ray's row).

    ctx (render.RenderContext) holds the scene, accel, lights, depths and the guide's state, which
    steers the sampling. observe(records), if given, gets the wave's vertices (guiding.records),
    whose radiance includes the emission their direction hits directly only if `direct`.
    split: a splitting.SplitPlan (final passes of a guide; a buffer made with split=True; not
    while recording), or None.
    """
    accel = ctx.accel
    t0 = time.perf_counter()
    ps = source.start(ctx, buf, sample0, g0, n)
    active, active2 = buf.active, buf.active2
    active[:n] = np.arange(n)
    n_active = n
    record = RECORD_NONE if observe is None else (RECORD_ALL if direct else RECORD_INDIRECT)
    rec = buf.records
    n_rec = 0
    n_slots = n
    splitting = split is not None and record == RECORD_NONE and buf.capacity > buf.size
    limits = (ctx.max_depth, ctx.rr_depth, ctx.nee)
    state, out, shadow, queue = buf.path_state(), buf.continuation(), buf.shadow_rays(), buf.shadow_queue()
    t0 = stats.tick("camera", t0)
    if engine is not None and engine.usable(ctx, record, ps):
        n_rec = engine.run(ctx, buf, n, ps, stats, split if splitting else None, record)
        rec = buf.records
        n_active = 0
        t0 = time.perf_counter()
    elif thread_loop is not None and thread_loop.usable(ctx, record):
        thread_loop.run(ctx, buf, n, ps, stats, split if splitting else None)
        n_active = 0
        t0 = time.perf_counter()
    for _ in range(MAX_BOUNCES + 1):
        if n_active == 0:
            break
        ro, rd = buf.ray_o[:n_active], buf.ray_d[:n_active]
        hits = accel.intersect(ro, rd)
        stats.rays += n_active
        t0 = stats.tick("intersect", t0)
        if splitting:
            n_active, n_slots, hits = split_wave(buf, active, n_active, n_slots, hits, rd, ctx, split, stats)
            ro, rd = buf.ray_o[:n_active], buf.ray_d[:n_active]
            t0 = stats.tick("split", t0)
        if record > 0 and n_rec + n_active > rec.strategy.shape[0]:
            rec = buf.records = rec.grown(max(2 * rec.strategy.shape[0], n_rec + n_active, 4 * n), n_rec)
        shade(active[:n_active], ro, rd, hits, ctx.surfaces, ctx.lights, ctx.guide_state, ps, limits, state, out,
              shadow, record, n_rec, rec)
        t0 = stats.tick("shade", t0)
        n_next, ns = compact(active[:n_active], out, shadow, (active2, buf.ray_o, buf.ray_d), queue)
        active, active2 = active2, active
        t0 = stats.tick("compact", t0)
        if ns:
            occ = accel.occluded(buf.sp_o[:ns], buf.sp_d[:ns], buf.sp_tmax[:ns])
            add_unoccluded(buf.sp_path[:ns], occ, buf.sp_L[:ns], buf.L, buf.sp_entry[:ns], rec.L0, n_rec, record > 0)
            stats.shadow_rays += ns
            t0 = stats.tick("occluded", t0)
        if record != RECORD_NONE:
            n_rec += n_active
        n_active = n_next
    if n_slots > n:
        merge_copies(buf.L, buf.parent, n, n_slots)
    stats.nonfinite += sanitize(buf.L[:n])
    if record > 0 and n_rec:
        head = rec.head(n_rec)
        finalize_records(head.strategy, head.path, head.beta, head.L0, head.radiance, buf.L)
        observe(head)
        t0 = stats.tick("record", t0)
    if source.spread:
        sink.add(buf.index[:n], buf.L[:n], buf.aov[:n], buf.weight[:n] if source.weighted else None, spread=True)
    else:
        sink.add(buf.index[:n], buf.L[:n], buf.aov[:n], buf.weight[:n] if source.weighted else None)
    stats.samples += n
    stats.tick("film", t0)


class PathIntegrator(Integrator):
    """`--integrator path`: unidirectional path tracing (this module's wavefront), NEE with MIS
    (`nee` 1, the default) or without NEE (`nee` 0: emission found by a path counts in full; the
    guiding papers' equal-time tables are rendered so). The image combines the films of the
    method's passes by inverse mean variance (film.combine_films; pilots left out)."""

    name = "path"
    DEFAULTS = {"nee": 1}

    def result(self, session, interrupted, snapshot):
        films = session.films or [(session.final, "final")]
        image, variance, weights = combine_films([f for f, _ in films], [k for _, k in films])
        image, variance = image.astype(np.float32), variance.astype(np.float32)
        aovs = aovs_of([f for f, _ in films])
        st = snapshot()
        st["interrupted"] = interrupted
        for p_entry in st["passes"]:
            p_entry["weight"] = weights[p_entry.pop("film")]
        report_dark(session.ctx.scene, image, st)
        return RenderResult(image, variance, aovs, st, session.final)


try:  # the per-thread loop and the lanes need Embree (embreex); without it every wave takes the wavefront
    from . import thread_loop
    from ..engine import lanes as engine
except ImportError as err:
    if not (err.name or "").startswith("embreex"):
        raise
    thread_loop = None
    engine = None
