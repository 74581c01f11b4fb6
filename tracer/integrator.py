"""Wavefront unidirectional path tracing: NEE with MIS (power heuristic), Russian roulette.

Python drives the stages of one wave of paths; every stage is one Numba kernel over
structure-of-arrays path state (`prange` over paths), except the ray queries, which go
to the accel (Embree or the Numba BVH) in one batch per stage:

    camera rays -> [intersect] -> shade: emission (MIS), NEE sample, BSDF sample,
    Russian roulette -> [occluded] -> add NEE -> compact -> repeat

Depths follow Mitsuba 3: `max_depth` 1 shows emitters seen directly, 2 adds direct light,
-1 is unlimited (bounded at MAX_BOUNCES for safety); Russian roulette applies from the
bounce numbered `rr_depth` on, continuing with probability min(max(beta), 0.95).
"""
import math
import time

import numpy as np
from numba import prange

from . import bsdfs
from ._jit import jit, kernel
from .camera import camera_ray
from .film import N_AOV
from .lights import ENV_NONE, env_pdf, env_radiance, sample_light, triangle_emission, triangle_light_pdf
from .rng import DIM_PIXEL, DIR, LIGHT, LIGHT_POS, LOBE, RR, bounce_dim, path_key, uniform
from .sampling import dot, frame, power_heuristic, to_local, to_world

MAX_BOUNCES = 4096


@kernel
def init_paths(cam, width, height, crop, jitter, seed, sample0, g0, pix, key, ray_o, ray_d, beta, L, depth,
               prev_pdf, prev_delta, aov):
    """Camera rays for global path indices g0 .. g0+n-1 of a pass (sample-major order).

    crop = (x0, y0, w, h): the film covers that window of the width x height image; pix[i] is the
    film pixel, while the random stream is keyed by the image pixel, so a cropped render
    reproduces the same window of the full one exactly.
    jitter: True for the box filter (uniform over the pixel), False for the point filter
    (every sample through the pixel centre).
    """
    n = pix.shape[0]
    cw = crop[2]
    npix = crop[2] * crop[3]
    for i in prange(n):
        g = g0 + i
        s = sample0 + g // npix
        p = g % npix
        px = crop[0] + p % cw
        py = crop[1] + p // cw
        k = path_key(seed, py * width + px, s)
        pix[i] = p
        key[i] = k
        jx = uniform(k, DIM_PIXEL) if jitter else 0.5
        jy = uniform(k, DIM_PIXEL + 1) if jitter else 0.5
        o, d = camera_ray(cam, width, height, px, py, jx, jy)
        for c in range(3):
            ray_o[i, c] = o[c]
            ray_d[i, c] = d[c]
            beta[i, c] = 1.0
            L[i, c] = 0.0
        depth[i] = 0
        prev_pdf[i] = 0.0
        prev_delta[i] = False
        for c in range(N_AOV):
            aov[i, c] = 0.0


@jit
def _offset(x, ng, w, eps):
    """x pushed off the surface by eps along the normal, to the side direction w leaves on."""
    s = eps if dot(w, ng) >= 0.0 else -eps
    return (x[0] + s * ng[0], x[1] + s * ng[1], x[2] + s * ng[2])


@kernel
def shade(active, ray_o, ray_d, t, prim, b1, b2, tri, tri_normal, tri_material, mat_type, mat_param, lt,
          beta, L, depth, prev_pdf, prev_delta, key, aov, max_depth, rr_depth, eps,
          alive, next_o, next_d, sh_o, sh_d, sh_tmax, sh_L, has_shadow):
    """One bounce for every active path: emission, NEE sample, BSDF sample, roulette.

    Entry k of the hit arrays (t, prim, b1, b2) and of ray_o/ray_d belongs to path
    active[k]. Writes the continuation ray to next_o/next_d[k] with alive[k], and a shadow
    ray (origin, unit direction, tmax, unoccluded contribution) with has_shadow[k].
    """
    n = active.shape[0]
    for k in prange(n):
        i = active[k]
        alive[k] = False
        has_shadow[k] = False
        dk = depth[i]                                   # bounces so far (0 at the first hit)
        wray = (ray_d[k, 0], ray_d[k, 1], ray_d[k, 2])  # direction the path arrived along
        b = (beta[i, 0], beta[i, 1], beta[i, 2])        # throughput up to this vertex
        p = prim[k]
        if p < 0:
            # Escaped: environment light, MIS-weighted against NEE's choice of it
            if lt.env_type != ENV_NONE:
                le = env_radiance(lt, wray)
                w = 1.0
                if dk > 0 and not prev_delta[i]:
                    w = power_heuristic(prev_pdf[i], env_pdf(lt, wray))
                for c in range(3):
                    L[i, c] += b[c] * le[c] * w
            continue

        # Hit point (from barycentrics: on the triangle's plane) and geometric normal
        u1 = b1[k]
        u2 = b2[k]
        u0 = 1.0 - u1 - u2
        x = (u0 * tri[p, 0, 0] + u1 * tri[p, 1, 0] + u2 * tri[p, 2, 0],
             u0 * tri[p, 0, 1] + u1 * tri[p, 1, 1] + u2 * tri[p, 2, 1],
             u0 * tri[p, 0, 2] + u1 * tri[p, 1, 2] + u2 * tri[p, 2, 2])
        ng = (tri_normal[p, 0], tri_normal[p, 1], tri_normal[p, 2])  # unit, counter-clockwise side
        m = tri_material[p]
        cos_o = -dot(wray, ng)  # > 0 when the path arrived on the counter-clockwise side

        # Emission, MIS-weighted against NEE's choice of this triangle
        if lt.light_of_tri[p] >= 0:
            le = triangle_emission(lt, p, cos_o)
            w = 1.0
            if dk > 0 and not prev_delta[i]:
                w = power_heuristic(prev_pdf[i], triangle_light_pdf(lt, p, t[k] * t[k], cos_o))
            for c in range(3):
                L[i, c] += b[c] * le[c] * w

        # AOVs at the first hit: albedo, normal facing the camera, distance
        if dk == 0:
            al = bsdfs.bsdf_albedo(mat_type, mat_param, m)
            sgn = 1.0 if cos_o >= 0.0 else -1.0
            for c in range(3):
                aov[i, c] = al[c]
                aov[i, 3 + c] = sgn * ng[c]
            aov[i, 6] = t[k]

        # Continue past this vertex?
        if max_depth >= 0 and dk + 1 >= max_depth:
            continue
        s, tt = frame(ng)
        wo = to_local((-wray[0], -wray[1], -wray[2]), s, tt, ng)
        kk = key[i]

        # Next-event estimation (not at delta BSDFs)
        if not bsdfs.bsdf_is_delta(mat_type, mat_param, m):
            wl, dist, le, pl = sample_light(lt, tri, x, uniform(kk, bounce_dim(dk, LIGHT)),
                                            uniform(kk, bounce_dim(dk, LIGHT_POS)),
                                            uniform(kk, bounce_dim(dk, LIGHT_POS + 1)))
            if pl > 0.0 and (le[0] > 0.0 or le[1] > 0.0 or le[2] > 0.0):
                wil = to_local(wl, s, tt, ng)
                f = bsdfs.bsdf_eval(mat_type, mat_param, m, wo, wil, True)
                if f[0] > 0.0 or f[1] > 0.0 or f[2] > 0.0:
                    w = power_heuristic(pl, bsdfs.bsdf_pdf(mat_type, mat_param, m, wo, wil))
                    so = _offset(x, ng, wl, eps)
                    tmax = dist - 2.0 * eps if math.isfinite(dist) else np.inf
                    if tmax > 0.0:
                        for c in range(3):
                            sh_o[k, c] = so[c]
                            sh_d[k, c] = wl[c]
                            sh_L[k, c] = b[c] * f[c] * le[c] * w / pl
                        sh_tmax[k] = tmax
                        has_shadow[k] = True

        # Sample the BSDF for the continuation
        wi, wt, pdf, dlt = bsdfs.bsdf_sample(mat_type, mat_param, m, wo,
                                             uniform(kk, bounce_dim(dk, DIR)),
                                             uniform(kk, bounce_dim(dk, DIR + 1)),
                                             uniform(kk, bounce_dim(dk, LOBE)), True)
        nb = (b[0] * wt[0], b[1] * wt[1], b[2] * wt[2])
        bmax = max(nb[0], max(nb[1], nb[2]))
        if not (bmax > 0.0) or not math.isfinite(bmax):
            continue

        # Russian roulette
        if dk + 1 >= rr_depth:
            q = min(bmax, 0.95)
            if uniform(kk, bounce_dim(dk, RR)) >= q:
                continue
            nb = (nb[0] / q, nb[1] / q, nb[2] / q)
        if dk + 1 >= MAX_BOUNCES:
            continue

        wiw = to_world(wi, s, tt, ng)
        no = _offset(x, ng, wiw, eps)
        for c in range(3):
            beta[i, c] = nb[c]
            next_o[k, c] = no[c]
            next_d[k, c] = wiw[c]
        depth[i] = dk + 1
        prev_pdf[i] = pdf
        prev_delta[i] = dlt
        alive[k] = True


_CHUNKS = 64  # compaction splits a batch into this many chunks, counted then written in parallel


@kernel
def compact(active, alive, next_o, next_d, has_shadow, sh_o, sh_d, sh_tmax, sh_L,
            dst_active, dst_o, dst_d, sp_path, sp_o, sp_d, sp_tmax, sp_L):
    """Pack the continuing paths (alive) and the shadow rays (has_shadow) to the front of the
    dst_* and sp_* arrays, keeping their order. Returns (continuing, shadow rays).

    Two parallel passes over chunks: count per chunk, then write at the prefix-sum offsets.
    """
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
                sp_tmax[js] = sh_tmax[k]
                for q in range(3):
                    sp_o[js, q] = sh_o[k, q]
                    sp_d[js, q] = sh_d[k, q]
                    sp_L[js, q] = sh_L[k, q]
                js += 1
    return counts[_CHUNKS, 0], counts[_CHUNKS, 1]


@kernel
def add_unoccluded(path, occluded, contrib, L):
    """L[path[j]] += contrib[j] where the shadow ray was not blocked (one entry per path)."""
    for j in prange(path.shape[0]):
        if not occluded[j]:
            i = path[j]
            for c in range(3):
                L[i, c] += contrib[j, c]


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
    """Structure-of-arrays path state for waves of up to `size` paths, allocated once."""

    def __init__(self, size):
        self.size = size
        z3 = lambda: np.zeros((size, 3))  # noqa: E731
        self.pix = np.zeros(size, np.int64)
        self.key = np.zeros(size, np.uint64)
        self.beta, self.L = z3(), z3()
        self.depth = np.zeros(size, np.int32)
        self.prev_pdf = np.zeros(size)
        self.prev_delta = np.zeros(size, np.bool_)
        self.aov = np.zeros((size, N_AOV))
        self.active = np.zeros(size, np.int64)
        self.active2 = np.zeros(size, np.int64)
        self.ray_o, self.ray_d, self.next_o, self.next_d = z3(), z3(), z3(), z3()
        self.alive = np.zeros(size, np.bool_)
        self.sh_o, self.sh_d, self.sh_L = z3(), z3(), z3()
        self.sh_tmax = np.zeros(size)
        self.has_shadow = np.zeros(size, np.bool_)
        self.sp_path = np.zeros(size, np.int64)
        self.sp_o, self.sp_d, self.sp_L = z3(), z3(), z3()
        self.sp_tmax = np.zeros(size)


class Stats:
    """Wall time per stage and ray counts."""

    STAGES = ("camera", "intersect", "shade", "occluded", "compact", "film")

    def __init__(self):
        self.time = {s: 0.0 for s in self.STAGES}
        self.rays = 0
        self.shadow_rays = 0
        self.samples = 0
        self.nonfinite = 0

    def tick(self, stage, t0):
        t1 = time.perf_counter()
        self.time[stage] += t1 - t0
        return t1


def trace_wave(ctx, buf, film, sample0, g0, n, stats):
    """Trace paths g0 .. g0+n-1 of the pass that starts at sample index sample0; add to film."""
    scene, accel, lights = ctx.scene, ctx.accel, ctx.lights
    t0 = time.perf_counter()
    init_paths(ctx.cam, scene.width, scene.height, ctx.crop, ctx.jitter, ctx.seed, sample0, g0, buf.pix[:n], buf.key[:n],
               buf.ray_o[:n], buf.ray_d[:n], buf.beta[:n], buf.L[:n], buf.depth[:n],
               buf.prev_pdf[:n], buf.prev_delta[:n], buf.aov[:n])
    active, active2 = buf.active, buf.active2
    active[:n] = np.arange(n)
    n_active = n
    t0 = stats.tick("camera", t0)
    for _ in range(MAX_BOUNCES + 1):
        if n_active == 0:
            break
        ro, rd = buf.ray_o[:n_active], buf.ray_d[:n_active]
        t, prim, b1, b2 = accel.intersect(ro, rd)
        stats.rays += n_active
        t0 = stats.tick("intersect", t0)
        shade(active[:n_active], ro, rd, t, prim, b1, b2, scene.tri, ctx.tri_normal, scene.tri_material,
              scene.materials.type, scene.materials.param, lights, buf.beta, buf.L, buf.depth,
              buf.prev_pdf, buf.prev_delta, buf.key, buf.aov, ctx.max_depth, ctx.rr_depth, ctx.eps,
              buf.alive, buf.next_o, buf.next_d, buf.sh_o, buf.sh_d, buf.sh_tmax, buf.sh_L, buf.has_shadow)
        t0 = stats.tick("shade", t0)
        n_next, ns = compact(active[:n_active], buf.alive, buf.next_o, buf.next_d, buf.has_shadow, buf.sh_o,
                             buf.sh_d, buf.sh_tmax, buf.sh_L, active2, buf.ray_o, buf.ray_d, buf.sp_path,
                             buf.sp_o, buf.sp_d, buf.sp_tmax, buf.sp_L)
        active, active2 = active2, active
        t0 = stats.tick("compact", t0)
        if ns:
            occ = accel.occluded(buf.sp_o[:ns], buf.sp_d[:ns], buf.sp_tmax[:ns])
            add_unoccluded(buf.sp_path[:ns], occ, buf.sp_L[:ns], buf.L)
            stats.shadow_rays += ns
            t0 = stats.tick("occluded", t0)
        n_active = n_next
    stats.nonfinite += sanitize(buf.L[:n])
    film.add(buf.pix[:n], buf.L[:n], buf.aov[:n])
    stats.samples += n
    stats.tick("film", t0)
