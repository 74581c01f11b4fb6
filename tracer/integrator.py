"""Wavefront unidirectional path tracing: NEE with MIS (power heuristic), Russian roulette.

Python drives the stages of one wave of paths; every stage is one Numba kernel over
structure-of-arrays path state (`prange` over paths), except the ray queries, which go
to the accel (Embree or the Numba BVH) in one batch per stage:

    camera rays -> [intersect] -> shade: emission (MIS), NEE sample, direction sample
    (BSDF or guide), record the vertex, Russian roulette -> [occluded] -> add NEE -> compact
    -> repeat

With a guide, a non-delta vertex in a voxel that has a sampling map draws its direction from
the one-sample MIS mixture p = a p_bsdf + (1 - a) p_guide (a: the voxel's mixing weight, the
strategy picked by the STRATEGY dimension); that mixture density is the one NEE's and the
emission's MIS weights use. A guide that learns gets, per vertex, a record (position, normal,
sampled direction, strategy, mixture pdf, |f cos| and, once the path has ended, the radiance
that came back along the direction: (L_end - L_at_vertex) / throughput after it, with the
vertex's own NEE excluded and the emission its direction hit counted without MIS weight, so
that the record is an unbiased estimate of the incident radiance along that direction).

Depths follow Mitsuba 3: `max_depth` 1 shows emitters seen directly, 2 adds direct light,
-1 is unlimited (bounded at MAX_BOUNCES for safety); Russian roulette applies from the
bounce numbered `rr_depth` on, continuing with probability min(max(beta), 0.95), where beta is
the throughput BSDF sampling would have given (the same thing without a guide; see shade).
"""
import math
import time
from typing import NamedTuple

import numpy as np
from numba import prange

from . import bsdfs
from ._jit import jit, kernel
from .camera import camera_ray
from .film import N_AOV
from .lights import ENV_NONE, env_pdf, env_radiance, sample_light, triangle_emission, triangle_light_pdf
from .guiding.spatial import find_voxel, voxel_pdf, voxel_sample
from .rng import DIM_PIXEL, DIR, LIGHT, LIGHT_POS, LOBE, RR, STRATEGY, bounce_dim, path_key, split_key, uniform
from .sampling import dot, frame, power_heuristic, to_local, to_world, triangle_point

MAX_BOUNCES = 4096


@kernel
def init_paths(cam, width, height, crop, jitter, seed, sample0, g0, pix, key, ray_o, ray_d, beta, L, depth,
               prev_pdf, prev_delta, aov, prev_rec):
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
        prev_rec[i] = -1
        for c in range(N_AOV):
            aov[i, c] = 0.0


@jit
def _offset(x, ng, w, eps):
    """x pushed off the surface by eps along the normal, to the side direction w leaves on (eps:
    the triangle's entry of tracer.bvh.ray_offsets)."""
    s = eps if dot(w, ng) >= 0.0 else -eps
    return (x[0] + s * ng[0], x[1] + s * ng[1], x[2] + s * ng[2])


@jit(inline="always")
def shadow_ray(x, ng, eps, wl, dist, lt, lt_tri, tri_eps):
    """(origin, unit direction, tmax) of the shadow ray from x (normal ng, offset eps) toward the
    light sample at distance dist along wl, on triangle lt_tri (-1: the environment, tmax inf).
    Both ends are offset by their own triangle's ray_offsets, the light's end along its normal
    toward x (pbrt-v4's SpawnRayTo), so the ray stops short of the light's plane as Embree sees it.
    tmax <= 0 means there is no room for a ray (x on the light)."""
    o = _offset(x, ng, wl, eps)
    if lt_tri < 0:
        return o, wl, np.inf
    li = lt.light_of_tri[lt_tri]
    el = tri_eps[lt_tri]
    y = (x[0] + dist * wl[0] + el * lt.normal[li, 0], x[1] + dist * wl[1] + el * lt.normal[li, 1],
         x[2] + dist * wl[2] + el * lt.normal[li, 2])
    d = (y[0] - o[0], y[1] - o[1], y[2] - o[2])
    tmax = math.sqrt(dot(d, d))
    if not tmax > 0.0:
        return o, wl, 0.0
    inv = 1.0 / tmax
    return o, (d[0] * inv, d[1] * inv, d[2] * inv), tmax


@kernel
def shade(active, ray_o, ray_d, t, prim, b1, b2, tri, tri_normal, tri_material, mat_type, mat_param, lt,
          beta, L, depth, prev_pdf, prev_delta, gain, key, aov, max_depth, rr_depth, tri_eps,
          alive, next_o, next_d, sh_o, sh_d, sh_tmax, sh_L, has_shadow, gs,
          r_x, r_n, r_wi, r_pdf, r_fcos, r_strategy, r_node, r_path, r_L0, r_beta, r_pb, rec_base, record,
          prev_rec, r_prev):
    """One bounce for every active path: emission, NEE sample, BSDF sample, roulette.

    Entry k of the hit arrays (t, prim, b1, b2) and of ray_o/ray_d belongs to path
    active[k]. Writes the continuation ray to next_o/next_d[k] with alive[k], and a shadow
    ray (origin, unit direction, tmax, unoccluded contribution) with has_shadow[k].
    gs is the guide's state (an empty one for plain BSDF sampling); with `record`, the vertex
    of entry k goes to record rec_base + k (strategy -1 where nothing was sampled) in the
    r_* arrays (the fields of `Records`, passed one by one: Numba 0.68's parallel loops can drop
    writes into arrays that arrive inside a NamedTuple). record: 0 none, 1 records of the full
    incident radiance, 2 of the radiance less the emission the direction hits directly (the part
    NEE samples). prev_rec[i] is the record of the path's last vertex: emission found by its
    sampled direction counts there in full (mode 1), not MIS-weighted, since the vertex's own NEE,
    which covers the rest, is not in its record; or not at all (mode 2). r_prev of a record is
    the record of the path's vertex before it (-1 at the first hit and after a delta vertex).
    """
    n = active.shape[0]
    for k in prange(n):
        i = active[k]
        alive[k] = False
        has_shadow[k] = False
        if record > 0:
            r_strategy[rec_base + k] = -1
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
                if record > 0 and prev_rec[i] >= 0:
                    x_le = -(1.0 - w) if record == 1 else w
                    for c in range(3):
                        r_L0[prev_rec[i], c] += b[c] * le[c] * x_le
            continue

        # Hit point (from barycentrics: on the triangle's plane) and geometric normal
        x = triangle_point(tri, p, b1[k], b2[k])
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
            if record > 0 and prev_rec[i] >= 0:
                x_le = -(1.0 - w) if record == 1 else w
                for c in range(3):
                    r_L0[prev_rec[i], c] += b[c] * le[c] * x_le

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
        delta = bsdfs.bsdf_is_delta(mat_type, mat_param, m)

        # The guide's voxel and the mixing weight a (probability of BSDF sampling; 1 = no guide)
        node = -1
        a = 1.0
        nf = ng if cos_o >= 0.0 else (-ng[0], -ng[1], -ng[2])  # normal on the side the path arrived
        if gs.res[0] > 0 and not delta:
            node = find_voxel(gs, x, nf)
            if node >= 0 and gs.slot[node] >= 0:
                a = gs.alpha[node]

        # Next-event estimation (not at delta BSDFs)
        if not delta:
            wl, dist, le, pl, lt_tri = sample_light(lt, tri, x, uniform(kk, bounce_dim(dk, LIGHT)),
                                                    uniform(kk, bounce_dim(dk, LIGHT_POS)),
                                                    uniform(kk, bounce_dim(dk, LIGHT_POS + 1)))
            if pl > 0.0 and (le[0] > 0.0 or le[1] > 0.0 or le[2] > 0.0):
                wil = to_local(wl, s, tt, ng)
                f = bsdfs.bsdf_eval(mat_type, mat_param, m, wo, wil, True)
                if f[0] > 0.0 or f[1] > 0.0 or f[2] > 0.0:
                    pb = bsdfs.bsdf_pdf(mat_type, mat_param, m, wo, wil)
                    if a < 1.0:
                        pb = a * pb + (1.0 - a) * voxel_pdf(gs, node, wl)
                    w = power_heuristic(pl, pb)
                    so, sd, tmax = shadow_ray(x, ng, tri_eps[p], wl, dist, lt, lt_tri, tri_eps)
                    if tmax > 0.0:
                        for c in range(3):
                            sh_o[k, c] = so[c]
                            sh_d[k, c] = sd[c]
                            sh_L[k, c] = b[c] * f[c] * le[c] * w / pl
                        sh_tmax[k] = tmax
                        has_shadow[k] = True

        # Sample the continuation: the BSDF, or the guide with probability 1 - a
        u0 = uniform(kk, bounce_dim(dk, DIR))
        u1 = uniform(kk, bounce_dim(dk, DIR + 1))
        strategy = 0
        gn = gain[i]  # product of p_bsdf / p_mixture along the path (1 without a guide)
        if a < 1.0 and uniform(kk, bounce_dim(dk, STRATEGY)) >= a:
            strategy = 1
            wiw, pg = voxel_sample(gs, node, u0, u1)
            wi = to_local(wiw, s, tt, ng)
            f = bsdfs.bsdf_eval(mat_type, mat_param, m, wo, wi, True)
            pbs = bsdfs.bsdf_pdf(mat_type, mat_param, m, wo, wi)
            pdf = a * pbs + (1.0 - a) * pg
            wt = (0.0, 0.0, 0.0)
            if pdf > 0.0:
                inv = 1.0 / pdf
                wt = (f[0] * inv, f[1] * inv, f[2] * inv)
                gn *= pbs * inv
            dlt = False
        else:
            wi, wt, pdf, dlt = bsdfs.bsdf_sample(mat_type, mat_param, m, wo, u0, u1,
                                                 uniform(kk, bounce_dim(dk, LOBE)), True)
            wiw = to_world(wi, s, tt, ng)
            pbs = pdf
            if a < 1.0 and pdf > 0.0 and not dlt:
                pm = a * pdf + (1.0 - a) * voxel_pdf(gs, node, wiw)
                rb = pdf / pm  # p_bsdf / p_mixture
                wt = (wt[0] * rb, wt[1] * rb, wt[2] * rb)
                gn *= rb
                pdf = pm
        nb = (b[0] * wt[0], b[1] * wt[1], b[2] * wt[2])
        bmax = max(nb[0], max(nb[1], nb[2]))
        ok = bmax > 0.0 and math.isfinite(bmax)

        # Russian roulette, on the throughput BSDF sampling would have had (beta / gain): on beta
        # itself it would undo the guide, since a guided direction's small weight f cos / p would
        # be raised back to ~1 by a matching chance of death (a path's survival density ~ f cos)
        if ok and dk + 1 >= rr_depth:
            q = min(bmax / gn, 0.95)
            if uniform(kk, bounce_dim(dk, RR)) >= q:
                ok = False
            else:
                nb = (nb[0] / q, nb[1] / q, nb[2] / q)
        if dk + 1 >= MAX_BOUNCES:
            ok = False

        # Record the vertex for a guide that learns (also when the path ends here: its radiance is 0)
        last = -1
        if record > 0:
            last = prev_rec[i]
            prev_rec[i] = -1
        if record > 0 and not delta and pdf > 0.0:
            r = rec_base + k
            r_prev[r] = last
            prev_rec[i] = r
            r_strategy[r] = strategy
            r_node[r] = node
            r_path[r] = i
            r_pdf[r] = pdf
            r_pb[r] = pbs
            r_fcos[r] = (0.2126 * wt[0] + 0.7152 * wt[1] + 0.0722 * wt[2]) * pdf
            for c in range(3):
                r_x[r, c] = x[c]
                r_n[r, c] = nf[c]
                r_wi[r, c] = wiw[c]
                r_L0[r, c] = L[i, c]
                r_beta[r, c] = nb[c] if ok else 0.0
        if not ok:
            continue

        no = _offset(x, ng, wiw, tri_eps[p])
        for c in range(3):
            beta[i, c] = nb[c]
            next_o[k, c] = no[c]
            next_d[k, c] = wiw[c]
        depth[i] = dk + 1
        prev_pdf[i] = pdf
        prev_delta[i] = dlt
        gain[i] = gn
        alive[k] = True


_CHUNKS = 64  # compaction splits a batch into this many chunks, counted then written in parallel


@kernel
def compact(active, alive, next_o, next_d, has_shadow, sh_o, sh_d, sh_tmax, sh_L,
            dst_active, dst_o, dst_d, sp_path, sp_entry, sp_o, sp_d, sp_tmax, sp_L):
    """Pack the continuing paths (alive) and the shadow rays (has_shadow) to the front of the
    dst_* and sp_* arrays, keeping their order (sp_entry: the entry k a shadow ray came from).
    Returns (continuing, shadow rays).

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


class Records(NamedTuple):
    """Path vertices of a wave, for guides that learn (R entries; strategy -1 = unused entry)."""

    x: np.ndarray  # (R, 3) float32 position
    n: np.ndarray  # (R, 3) float32 geometric normal, on the side the path arrived from
    wi: np.ndarray  # (R, 3) float32 sampled world direction
    pdf: np.ndarray  # (R,) float32 density it was sampled with (the MIS mixture)
    fcos: np.ndarray  # (R,) float32 luminance of f(wo, wi) |cos|
    strategy: np.ndarray  # (R,) int8 0 = BSDF, 1 = guide, -1 = no record
    node: np.ndarray  # (R,) int32 guide voxel (-1: none)
    path: np.ndarray  # (R,) int64 path slot in the wave
    L0: np.ndarray  # (R, 3) float64 path radiance when the direction was sampled
    beta: np.ndarray  # (R, 3) float64 throughput after the vertex (0 if the path ended)
    pb: np.ndarray  # (R,) float32 the BSDF's own density of wi (pdf is the mixture's)
    radiance: np.ndarray  # (R,) float32 luminance of the radiance that came back along wi
    prev: np.ndarray  # (R,) int64 record of the path's previous vertex (-1: first hit, or after a delta vertex)

    @staticmethod
    def allocate(size):
        f3 = lambda: np.zeros((size, 3), np.float32)  # noqa: E731
        return Records(f3(), f3(), f3(), np.zeros(size, np.float32), np.zeros(size, np.float32),
                       np.full(size, -1, np.int8), np.full(size, -1, np.int32), np.zeros(size, np.int64),
                       np.zeros((size, 3)), np.zeros((size, 3)), np.zeros(size, np.float32),
                       np.zeros(size, np.float32), np.full(size, -1, np.int64))

    def grown(self, size, used):
        new = Records.allocate(size)
        for a, b in zip(self, new):
            b[:used] = a[:used]
        return new

    def head(self, n):
        return Records(*(a[:n] for a in self))


@kernel
def finalize_records(strategy, path, beta, L0, radiance, L):
    """Radiance along each record's direction once its path has ended: luminance of
    (L_end - L0) / beta per channel (0 where beta is 0, negative or not finite)."""
    for r in prange(strategy.shape[0]):
        if strategy[r] < 0:
            continue
        i = path[r]
        v = 0.0
        for c in range(3):
            b = beta[r, c]
            if b > 0.0:
                v += (0.2126, 0.7152, 0.0722)[c] * (L[i, c] - L0[r, c]) / b
        radiance[r] = v if (v > 0.0 and math.isfinite(v)) else 0.0


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


SPLIT_MAX = 8  # copies a path is split into at most
WINDOW_MIN_SURVIVAL = 0.05  # the weight window's roulette keeps a path with at least this probability


@jit(inline="always")
def _split_count(k, active, ray_d, prim, b1, b2, tri, tri_normal, beta, gain, depth, pix, key, gs, outgoing, pixel_est,
                 hi, low, threshold):
    """split_counts for entry k; after the window's roulette it divides its path's beta and gain."""
    i = active[k]
    p = prim[k]
    if p < 0 or depth[i] < 1:
        return 1
    if hi > 0.0:
        x = triangle_point(tri, p, b1[k], b2[k])
        ng = (tri_normal[p, 0], tri_normal[p, 1], tri_normal[p, 2])
        arriving = -(ray_d[k, 0] * ng[0] + ray_d[k, 1] * ng[1] + ray_d[k, 2] * ng[2]) >= 0.0
        nf = ng if arriving else (-ng[0], -ng[1], -ng[2])
        node = find_voxel(gs, x, nf)
        if node >= 0 and outgoing[node] > 0.0:
            q = (0.2126 * beta[i, 0] + 0.7152 * beta[i, 1] + 0.0722 * beta[i, 2]) * outgoing[node] / pixel_est[pix[i]]
            if q > hi:
                return min(int(math.ceil(q / hi)), SPLIT_MAX)
            if q < low:
                ps = max(q / low, WINDOW_MIN_SURVIVAL)
                if uniform(split_key(key[i], depth[i], 0), 0) >= ps:
                    return 0
                for c in range(3):
                    beta[i, c] /= ps
                gain[i] /= ps
            return 1
    if threshold > 0.0:
        bm = max(beta[i, 0], max(beta[i, 1], beta[i, 2]))
        if bm > threshold:
            return min(int(math.ceil(bm)), SPLIT_MAX)
    return 1


@kernel
def split_counts(active, ray_d, prim, b1, b2, tri, tri_normal, beta, gain, depth, pix, key, gs, outgoing, pixel_est,
                 hi, low, threshold, ks):
    """ks[k]: how many copies entry k's path goes on as (0: it ends here), for a path that hit a
    surface after its first bounce; 1 elsewhere.

    Weight window (hi > 0), where the guide's voxel has an outgoing radiance estimate Lo: the path's
    expected share of its pixel is q = lum(beta) Lo / I (I = pixel_est of its pixel). Above hi it
    splits into min(ceil(q / hi), SPLIT_MAX) copies; below low it survives a roulette with probability
    max(q / low, WINDOW_MIN_SURVIVAL), its beta and gain divided by that (here, in place). Elsewhere
    (no window, or no estimate): throughput splitting, min(ceil(max beta), SPLIT_MAX) copies where
    max beta > threshold > 0. Returns (sum of ks, entries with ks 0)."""
    wanted = 0
    ended = 0
    for k in prange(active.shape[0]):
        m = _split_count(k, active, ray_d, prim, b1, b2, tri, tri_normal, beta, gain, depth, pix, key, gs, outgoing,
                         pixel_est, hi, low, threshold)
        ks[k] = m
        wanted += m
        if m == 0:
            ended += 1
    return wanted, ended


@jit(inline="always")
def _copy_entry(k, e, t, prim, b1, b2, t2, prim2, b12, b22, ray_o, ray_d):
    """Wave entry k's hit (t, prim, b1, b2) to entry e of (t2, prim2, b12, b22), and its ray."""
    t2[e] = t[k]
    prim2[e] = prim[k]
    b12[e] = b1[k]
    b22[e] = b2[k]
    for c in range(3):
        ray_o[e, c] = ray_o[k, c]
        ray_d[e, c] = ray_d[k, c]


@jit
def split_paths(active, ks, t, prim, b1, b2, t2, prim2, b12, b22, ray_o, ray_d, beta, gain, L, depth, prev_pdf,
                prev_delta, key, pix, prev_rec, parent, n_slots, capacity):
    """Apply split_counts: entries with ks 0 leave the wave (their paths end; what they gathered
    stays in L); entry k's path becomes ks[k] copies with beta / ks[k] and gain / ks[k] each (so
    Russian roulette, which looks at beta / gain, treats them as it would the path), fewer where
    fewer than ks[k] - 1 path slots or wave entries are left below `capacity`. The kept entries'
    rays and hits (t, prim, b1, b2 into t2, prim2, b12, b22, which have room for the copies) move
    to the front; copies take path slots from n_slots on and the entries after the kept ones, with
    the entry's ray and hit, L = 0, a key of their own, and parent = the path whose sample they add
    to. Returns (entries, path slots) in use. Sequential: slots are handed out in order, so a render
    does not depend on the thread count."""
    n_active = ks.shape[0]
    e = 0
    for k in range(n_active):
        if ks[k] == 0:
            continue
        active[e] = active[k]
        ks[e] = ks[k]
        _copy_entry(k, e, t, prim, b1, b2, t2, prim2, b12, b22, ray_o, ray_d)
        e += 1
    kept = e
    s = n_slots
    for k in range(kept):
        m = min(ks[k], capacity - s + 1, capacity - e + 1)
        if m <= 1:
            continue
        i = active[k]
        for c in range(3):
            beta[i, c] /= m
        gain[i] /= m
        for j in range(1, m):
            active[e] = s
            _copy_entry(k, e, t2, prim2, b12, b22, t2, prim2, b12, b22, ray_o, ray_d)
            for c in range(3):
                beta[s, c] = beta[i, c]
                L[s, c] = 0.0
            gain[s] = gain[i]
            depth[s] = depth[i]
            prev_pdf[s] = prev_pdf[i]
            prev_delta[s] = prev_delta[i]
            key[s] = split_key(key[i], depth[i], j)
            pix[s] = pix[i]
            prev_rec[s] = -1
            parent[s] = i
            e += 1
            s += 1
    return e, s


@jit
def merge_copies(L, parent, n, n_slots):
    """Add the radiance of copies (slots n .. n_slots - 1) into the paths they were split from, the
    latest first (a copy may be the parent of a later one)."""
    for j in range(n_slots - 1, n - 1, -1):
        p = parent[j]
        for c in range(3):
            L[p, c] += L[j, c]


def warm_up_splitting(ctx):
    """Compile (or load from the cache) the splitting kernels on a tiny wave of ctx's scene."""
    buf = WaveBuffers(1, split=True)
    ks = buf.ks[:1]
    e = (np.zeros(1), np.full(1, -1, np.int32), np.zeros(1), np.zeros(1))
    split_counts(buf.active[:1], buf.ray_d[:1], e[1], e[2], e[3], ctx.scene.tri, ctx.tri_normal, buf.beta, buf.gain,
                 buf.depth, buf.pix, buf.key, ctx.guide_state, np.zeros(1), np.ones(1), 1.0, 0.1, 1.0, ks)
    split_paths(buf.active, ks, *e, *e, buf.ray_o, buf.ray_d, buf.beta, buf.gain, buf.L, buf.depth, buf.prev_pdf,
                buf.prev_delta, buf.key, buf.pix, buf.prev_rec, buf.parent, 1, buf.capacity)
    merge_copies(buf.L, buf.parent, 1, 1)


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
        self.pix = np.zeros(size, np.int64)
        self.key = np.zeros(size, np.uint64)
        self.beta, self.L = z3(), z3()
        self.depth = np.zeros(size, np.int32)
        self.prev_pdf = np.zeros(size)
        self.prev_delta = np.zeros(size, np.bool_)
        self.gain = np.ones(size)
        self.prev_rec = np.zeros(size, np.int64)
        self.aov = np.zeros((size, N_AOV))
        self.active = np.zeros(size, np.int64)
        self.active2 = np.zeros(size, np.int64)
        self.ray_o, self.ray_d, self.next_o, self.next_d = z3(), z3(), z3(), z3()
        self.alive = np.zeros(size, np.bool_)
        self.sh_o, self.sh_d, self.sh_L = z3(), z3(), z3()
        self.sh_tmax = np.zeros(size)
        self.has_shadow = np.zeros(size, np.bool_)
        self.sp_path = np.zeros(size, np.int64)
        self.sp_entry = np.zeros(size, np.int64)
        self.records = Records.allocate(1)  # grown on demand when a guide records
        self.sp_o, self.sp_d, self.sp_L = z3(), z3(), z3()
        self.sp_tmax = np.zeros(size)
        self._hits = ()  # hit arrays of a bounce with copies (copy_hits)

    def copy_hits(self, *hits):
        """Arrays with room for `capacity` entries, of the dtypes of `hits` (t, prim, b1, b2): where
        split_paths writes a bounce's hits with its copies. Allocated once."""
        if tuple(a.dtype for a in self._hits) != tuple(a.dtype for a in hits):
            self._hits = tuple(np.empty(self.capacity, a.dtype) for a in hits)
        return self._hits


class Stats:
    """Wall time per stage and ray counts."""

    STAGES = ("camera", "intersect", "split", "shade", "occluded", "compact", "film", "record")

    def __init__(self):
        self.time = {s: 0.0 for s in self.STAGES}
        self.rays = 0
        self.shadow_rays = 0
        self.samples = 0
        self.nonfinite = 0
        self.split_copies = 0
        self.window_ended = 0

    def tick(self, stage, t0):
        t1 = time.perf_counter()
        self.time[stage] += t1 - t0
        return t1


def trace_wave(ctx, buf, film, sample0, g0, n, stats, observe=None, direct=True, split=0.0):
    """Trace paths g0 .. g0+n-1 of the pass that starts at sample index sample0; add to film.
    ctx.guide_state steers the sampling; `observe(records)`, if given, gets the wave's vertices,
    whose radiance includes the emission their direction hits directly only if `direct`.

    Splitting and the weight window (a buffer made with split=True; not while recording). A guide
    makes overweight paths: its mixture weighs a BSDF-sampled direction p_bsdf / p_mixture, up to
    1 / a, where the map is thin, and these factors multiply along the path (BSDF sampling alone
    keeps beta <= 1 / 0.95). At each surface hit after the first bounce (split_counts):
    - ctx.window = (outgoing, pixel_est, hi, low), or None: a weight window after adjoint-driven
      Russian roulette and splitting (Vorba and Krivanek 2016), where the guide's voxel has an
      estimate `outgoing` of the radiance a path arriving there goes on to collect. The path's
      expected share of its pixel's value pixel_est is q = lum(beta) outgoing / pixel_est: above hi
      it splits into ceil(q / hi) copies (SPLIT_MAX at most), below low it is rouletted.
    - split > 0, where there is no window estimate: a path whose throughput (max channel) exceeds
      `split` goes on as min(ceil(max beta), SPLIT_MAX) copies.
    A path split into k copies gives each throughput beta / k and its own key; each samples its own
    rest of the path, and their radiance adds up to the path's one sample. Copies are made only
    where the wave buffer has room. Whether a path splits or survives never depends on its own
    future, so the estimate stays unbiased."""
    scene, accel, lights = ctx.scene, ctx.accel, ctx.lights
    t0 = time.perf_counter()
    init_paths(ctx.cam, scene.width, scene.height, ctx.crop, ctx.jitter, ctx.seed, sample0, g0, buf.pix[:n], buf.key[:n],
               buf.ray_o[:n], buf.ray_d[:n], buf.beta[:n], buf.L[:n], buf.depth[:n],
               buf.prev_pdf[:n], buf.prev_delta[:n], buf.aov[:n], buf.prev_rec[:n])
    buf.gain[:n] = 1.0
    active, active2 = buf.active, buf.active2
    active[:n] = np.arange(n)
    n_active = n
    gs = ctx.guide_state
    record = 0 if observe is None else (1 if direct else 2)
    rec = buf.records
    n_rec = 0
    n_slots = n
    window = getattr(ctx, "window", None)
    splitting = (split > 0.0 or window is not None) and record == 0 and buf.capacity > buf.size
    outgoing, pixel_est, hi, low = window if window is not None else (np.zeros(1), np.ones(1), 0.0, 0.0)
    t0 = stats.tick("camera", t0)
    for _ in range(MAX_BOUNCES + 1):
        if n_active == 0:
            break
        ro, rd = buf.ray_o[:n_active], buf.ray_d[:n_active]
        t, prim, b1, b2 = accel.intersect(ro, rd)
        stats.rays += n_active
        t0 = stats.tick("intersect", t0)
        if splitting:
            ks = buf.ks[:n_active]
            wanted, ended = split_counts(active[:n_active], rd, prim, b1, b2, scene.tri, ctx.tri_normal, buf.beta,
                                         buf.gain, buf.depth, buf.pix, buf.key, gs, outgoing, pixel_est, hi, low,
                                         split, ks)
            if wanted > n_active or ended > 0:
                hit2 = buf.copy_hits(t, prim, b1, b2)
                n_e, n_s = split_paths(active, ks, t, prim, b1, b2, *hit2, buf.ray_o, buf.ray_d, buf.beta, buf.gain,
                                   buf.L, buf.depth, buf.prev_pdf, buf.prev_delta, buf.key, buf.pix, buf.prev_rec,
                                   buf.parent, n_slots, buf.capacity)
                stats.split_copies += n_s - n_slots
                stats.window_ended += ended
                n_slots, n_active = n_s, n_e
                t, prim, b1, b2 = (a[:n_e] for a in hit2)
                ro, rd = buf.ray_o[:n_active], buf.ray_d[:n_active]
            t0 = stats.tick("split", t0)
        if record > 0 and n_rec + n_active > rec.strategy.shape[0]:
            rec = buf.records = rec.grown(max(2 * rec.strategy.shape[0], n_rec + n_active, 4 * n), n_rec)
        shade(active[:n_active], ro, rd, t, prim, b1, b2, scene.tri, ctx.tri_normal, scene.tri_material,
              scene.materials.type, scene.materials.param, lights, buf.beta, buf.L, buf.depth,
              buf.prev_pdf, buf.prev_delta, buf.gain, buf.key, buf.aov, ctx.max_depth, ctx.rr_depth, ctx.tri_eps,
              buf.alive, buf.next_o, buf.next_d, buf.sh_o, buf.sh_d, buf.sh_tmax, buf.sh_L, buf.has_shadow,
              gs, *rec[:11], n_rec, record, buf.prev_rec, rec.prev)
        t0 = stats.tick("shade", t0)
        n_next, ns = compact(active[:n_active], buf.alive, buf.next_o, buf.next_d, buf.has_shadow, buf.sh_o,
                             buf.sh_d, buf.sh_tmax, buf.sh_L, active2, buf.ray_o, buf.ray_d, buf.sp_path,
                             buf.sp_entry, buf.sp_o, buf.sp_d, buf.sp_tmax, buf.sp_L)
        active, active2 = active2, active
        t0 = stats.tick("compact", t0)
        if ns:
            occ = accel.occluded(buf.sp_o[:ns], buf.sp_d[:ns], buf.sp_tmax[:ns])
            add_unoccluded(buf.sp_path[:ns], occ, buf.sp_L[:ns], buf.L, buf.sp_entry[:ns], rec.L0, n_rec, record > 0)
            stats.shadow_rays += ns
            t0 = stats.tick("occluded", t0)
        if record > 0:
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
    film.add(buf.pix[:n], buf.L[:n], buf.aov[:n])
    stats.samples += n
    stats.tick("film", t0)
