"""Gradient-domain path tracing with the hybrid shift (Kettunen et al. 2015; the details as in their
public implementation, gradient-domain Mitsuba 0.5).

Every sample of pixel p is a base path, the path tracer's own (the same random numbers, NEE and
MIS: its value is the path tracer's sample), and four offset paths, one per neighbour p + e
(e = +-x, +-y), that step with it:

- At the camera the offset ray goes through p + e at the same position inside the pixel.
- At each bounce from base vertex x_i to x_{i+1}, an offset at y_i
  - *fails* where x_i and y_i lie on either side of `roughness` (a diffuse bounce has no partner in a
    near-delta lobe), or, at the first vertex, of `direct_roughness`;
  - *reconnects* to x_{i+1} when x_i, x_{i+1} and y_i are all rough (bsdfs.bsdf_roughness above
    `roughness`; the environment counts as rough): the segment y_i -> x_{i+1} must be unblocked
    (else the shift fails), Jacobian |cos_y| d(x_i, x_{i+1})^2 / (|cos_x| d(y_i, x_{i+1})^2), both
    cosines at x_{i+1}'s normal. One bounce later it evaluates the BSDF at x_{i+1} with its own
    incoming direction, and from then on it is the base path (status RECENT, then CONNECTED).
  - else *copies the half-vector* of the base's bounce into y_i's local frame, reflection or
    refraction as the base did (Jacobian from dh/dwi = eta_t^2 |wi.h| / |H|^2 on both sides; a
    delta lobe copies its lobe, Jacobian 1). It fails on total internal reflection, on density 0,
    on a delta lobe where the offset has none, and when the reverse shift would have reconnected
    (x_i, y_i and the offset's new vertex y_{i+1} all rough): the mapping is its own inverse.
- NEE: the offset connects to the base's light sample (the same point; for the environment the
  same direction), Jacobian |cos_l'| d_b^2 / (|cos_l| d_o^2); it tests its own visibility (a
  blocked offset is a valid path that contributes 0).

With a guide (grid, photon: maps by position, none per pixel) the base samples the path
tracer's mixture a p_bsdf + (1 - a) p_guide, and every density of an offset (P_o in R, its NEE
weights) is the mixture's at the offset's own vertex (shift.path_density): the density its own
pixel's path tracer would sample it with, so the two sides' weights of a pair still sum to one.

Weights. Each pair (p, p + e) is estimated from both sides; each estimate is weighted by the power
heuristic over four techniques: the base's light and BSDF sampling and the neighbour's (the offset
path's densities times the Jacobian). Path state keeps beta = F / P_b (F the product of f |cos|,
P_b the base's density) for the base and beta_o = F_o J_o / P_b for the offset, and the ratio
R = J_o P_o / P_b, so no product of densities is ever formed (it would overflow in long glossy
paths). With light density pL and BSDF density pB of the last vertex, an NEE sample adds

    w (beta_o J_L f_o Le_o - beta f Le) / pL,   w = pL^2 / (pL^2 + pB^2 + (R J_L)^2 (pL_o^2 + pB_o^2)),

and an emitter found by a BSDF sample (R, beta after the bounce)

    (beta_o Le_o - beta Le) / (1 + (pL / pB)^2 + R^2 (1 + (pL_o / pB_o)^2)).

A pair whose bounce is a half-vector copy has no NEE partner (NEE reconnects): each side keeps its
own NEE with the path tracer's weight, and an emitter found by the copied BSDF samples adds
(w_o beta_o Le_o - w beta Le) / (1 + R^2), w and w_o the two paths' own BSDF weights against NEE.
A failed offset leaves the base its ordinary two-technique weight, and a gradient of minus the
base's weighted value. Russian roulette is the base's; a survivor divides beta and beta_o by q.
The direct buffer (L_cam), added back after the solve and left out of the gradients, holds the
light seen directly from the camera and the light a near-specular first vertex (GGX alpha below
`direct_roughness`) reflects: sharp, bright highlights whose gradients are as noisy as the pixels
and which a Poisson solve would spread over their neighbourhood.
"""

import time as _time

import numpy as np

from ..bvh.embree import _INTERSECT16, _OCCLUDED16, intersect_listed, occluded_listed
from ..bvh.numba_bvh import _NumbaThreads
from ..integrators.path import MAX_BOUNCES
from ..rng import no_primary_samples
from ..sources import CameraSource
from ..wave import compact, sanitize
from .films import add_gradients
from .offsets import BLOCKED, HybridBuffers, shift_offsets, start_offsets
from .offset_shading import ShiftLimits, add_next_event, shade_hybrid


_CAMERA = CameraSource()


def warm_up(ctx, buf, roughness, direct_roughness):
    """Compile (or load) the hybrid kernels: a wave of no paths still calls each one."""
    hb = HybridBuffers(1)
    idx = np.zeros(0, np.int64)
    t, prim, b1, b2 = ctx.accel.intersect(buf.ray_o[:0], buf.ray_d[:0])
    surf = ctx.surfaces
    start_offsets(ctx.cam, ctx.scene.width, ctx.scene.height, ctx.crop, ctx.jitter, no_primary_samples(),
                  buf.key[:0], buf.pix[:0], hb.offsets())
    shift_offsets(idx, (t, prim, b1, b2), buf.ray_d[:0], surf, ctx.guide_state, float(roughness), hb.base(),
                  hb.offsets())
    _shade(ctx, buf, hb, idx, buf.ray_d[:0], (t, prim, b1, b2), no_primary_samples(), roughness, direct_roughness)
    _add_next_event(buf, hb, idx)
    queries = _queries(ctx.accel, buf, hb)
    queries.offset_rays(idx)
    queries.shadows(idx, 0)


def _shade(ctx, buf, hb, active, rd, hits, ps, roughness, direct_roughness):
    limits = ShiftLimits(int(ctx.max_depth), int(ctx.rr_depth), float(roughness), float(direct_roughness))
    shade_hybrid(active, rd, hits, ctx.surfaces, ctx.lights, ctx.guide_state, ps, limits, buf.path_state(),
                 buf.continuation(), buf.shadow_rays(), hb.base(), hb.offsets(), hb.nee_terms())


def _add_next_event(buf, hb, active):
    add_next_event(active, buf.shadow_rays(), buf.L, buf.L_cam, hb.G, hb.nee_terms())


class BatchQueries:
    """The ray queries of a bounce beyond the base's closest hits, through the accel's batch calls
    (any accel): the flagged rays gathered, answered, scattered back."""

    def __init__(self, accel, buf, hb):
        self.accel, self.buf, self.hb = accel, buf, hb

    def offset_rays(self, active):
        """The offsets' own rays (their hits into hb.hit_*) and their reconnections' visibility
        (a blocked one's status BLOCKED): (rays, shadow rays) traced."""
        accel, hb = self.accel, self.hb
        pi, po = np.nonzero(hb.trace[active])
        if pi.size:
            sl = active[pi]
            ht, hp, h1, h2 = accel.intersect(hb.ray_o[sl, po], hb.ray_d[sl, po])
            hb.hit_t[sl, po], hb.hit_prim[sl, po], hb.hit_b1[sl, po], hb.hit_b2[sl, po] = ht, hp, h1, h2
        ri, ro_ = np.nonzero(hb.reconn[active])
        if ri.size:
            sl = active[ri]
            occ = accel.occluded(hb.ray_o[sl, ro_], hb.ray_d[sl, ro_], hb.tmax[sl, ro_])
            hb.status[sl[occ], ro_[occ]] = BLOCKED
        return pi.size, ri.size

    def shadows(self, active, na):
        """The shadow rays of the base (entries 0 .. na-1 of the wave) and of the offsets: their
        visibility into hb.vis_b and hb.vis; how many were traced."""
        buf, hb = self.buf, self.hb
        kb = np.flatnonzero(buf.has_shadow[:na])
        si, so = np.nonzero(hb.sh[active])
        ss = active[si]
        if kb.size + si.size:
            org = np.concatenate([buf.sh_o[kb], hb.sh_o[ss, so]])
            dirs = np.concatenate([buf.sh_d[kb], hb.sh_d[ss, so]])
            tmax = np.concatenate([buf.sh_tmax[kb], hb.sh_tmax[ss, so]])
            vis = ~self.accel.occluded(org, dirs, tmax)
            hb.vis_b[kb] = vis[:kb.size]
            hb.vis[ss, so] = vis[kb.size:]
        return kb.size + si.size


class PacketQueries(BatchQueries):
    """The same queries answered where the rays lie (Embree): each kernel walks the wave's paths
    and hands their flagged rays to rtcIntersect16 / rtcOccluded16 16 at a time, no gather or
    scatter in numpy."""

    def __init__(self, accel, buf, hb):
        super().__init__(accel, buf, hb)
        self.scene, self.plane, self.centre, self.refine, self.scratch = accel.packet_args()
        flat = lambda a: a.reshape((-1,) + a.shape[2:])  # noqa: E731  (path i's offset o at row 4 i + o)
        self.own = (flat(hb.trace), flat(hb.ray_o), flat(hb.ray_d))
        self.hits = (flat(hb.hit_t), flat(hb.hit_prim), flat(hb.hit_b1), flat(hb.hit_b2))
        self.reconn = (flat(hb.reconn), flat(hb.ray_o), flat(hb.ray_d), flat(hb.tmax))
        self.status = flat(hb.status)
        self.off_sh = (flat(hb.sh), flat(hb.sh_o), flat(hb.sh_d), flat(hb.sh_tmax))
        self.vis = flat(hb.vis)
        self.base_sh = (buf.has_shadow, buf.sh_o, buf.sh_d, buf.sh_tmax)
        self.positions = np.arange(buf.size)
        self.threads = accel.threads

    def offset_rays(self, active):
        with _NumbaThreads(self.threads):
            rays = intersect_listed(_INTERSECT16, self.scene, self.plane, self.centre, self.refine, self.scratch,
                                    active, 4, self.own, self.hits)
            shadow = occluded_listed(_OCCLUDED16, self.scene, self.centre, self.scratch, active, 4, self.reconn,
                                     self.status, np.int8(BLOCKED), np.int8(0), True)
        return rays, shadow

    def shadows(self, active, na):
        with _NumbaThreads(self.threads):
            traced = occluded_listed(_OCCLUDED16, self.scene, self.centre, self.scratch, self.positions[:na], 1,
                                     self.base_sh, self.hb.vis_b, False, True, False)
            traced += occluded_listed(_OCCLUDED16, self.scene, self.centre, self.scratch, active, 4, self.off_sh,
                                      self.vis, False, True, False)
        return traced


def _queries(accel, buf, hb):
    return (PacketQueries if hasattr(accel, "packet_args") else BatchQueries)(accel, buf, hb)


def trace_hybrid_wave(ctx, buf, hb, films, sample0, g0, n, stats, roughness, direct_roughness):
    """Trace paths g0 .. g0+n-1 of a pass (base and four offsets, hybrid shift) and add them to
    `films` (films.GradientFilms). buf: a WaveBuffers, hb: HybridBuffers, both of at least n;
    roughness: the shift's threshold; direct_roughness: first vertices smoother than it put the
    light they reflect into the direct buffer (shade_hybrid)."""
    accel = ctx.accel
    t0 = _time.perf_counter()
    ps = _CAMERA.start(ctx, buf, sample0, g0, n)
    start_offsets(ctx.cam, ctx.scene.width, ctx.scene.height, ctx.crop, ctx.jitter, ps, buf.key[:n], buf.pix[:n],
                  hb.offsets())
    cur, spare = buf.active, buf.active2  # the paths still going (their slots), and the next bounce's
    cur[:n] = np.arange(n)
    na = n
    surf = ctx.surfaces
    cont, shr, queue = buf.continuation(), buf.shadow_rays(), buf.shadow_queue()
    queries = _queries(accel, buf, hb)
    t0 = stats.tick("camera", t0)
    for bounce in range(MAX_BOUNCES + 1):
        if na == 0:
            break
        active = cur[:na]
        ro, rd = buf.ray_o[:na], buf.ray_d[:na]
        t, prim, b1, b2 = accel.intersect(ro, rd)
        stats.rays += na
        t0 = stats.tick("intersect", t0)
        if bounce > 0:
            shift_offsets(active, (t, prim, b1, b2), rd, surf, ctx.guide_state, float(roughness), hb.base(), hb.offsets())
            t0 = stats.tick("shift", t0)
        # The offsets' own rays, and the visibility of their reconnections
        rays, shadow_rays = queries.offset_rays(active)
        stats.rays += rays
        stats.shadow_rays += shadow_rays
        t0 = stats.tick("intersect", t0)
        _shade(ctx, buf, hb, active, rd, (t, prim, b1, b2), ps, roughness, direct_roughness)
        t0 = stats.tick("shade", t0)
        # Shadow rays: the base's and the offsets' own; then the NEE terms with their weights
        shadow_rays = queries.shadows(active, na)
        if shadow_rays:
            stats.shadow_rays += shadow_rays
            t0 = stats.tick("occluded", t0)
            _add_next_event(buf, hb, active)
            t0 = stats.tick("shade", t0)
        na = int(compact(active, cont, shr, (spare, buf.ray_o, buf.ray_d), queue)[0])
        cur, spare = spare, cur
        t0 = stats.tick("compact", t0)
    stats.nonfinite += sanitize(buf.L[:n]) + sanitize(hb.G[:n].reshape(-1, 3))
    add_gradients(ctx, buf, films, n, hb.G[:n], 2.0)
    stats.samples += n
    stats.tick("film", t0)
