"""The lanes' listed kernel: one lane after another in float64, for the vertices that the
vectorised diffuse kernel does not take and that need not go through shade_vertex.

`shade_listed` shades the lanes classify listed for it:
- always the glossy class: Mitsuba's plastic and roughplastic (bsdfs.COATED) and its conductor
  and roughconductor (bsdfs.METAL), opaque, not emitting, whose colour (the coat's diffuse
  reflectance, the metal's specular one) may be a texture (the reflectance kernel's kd rows);
- under a guide (its maps, its roulette, or its splitting, which reads the wave's PathState),
  the diffuse class too: emission, a guided light sample and a guided bounce.
Per lane, through the BSDF's own functions (bsdfs._diffuse_*; bsdfs._coated_eval_pdf,
_coated_sample: the rough coat's GGX or Beckmann lobe and the smooth coat's mirror lobe beside
the diffuse base; bsdfs._metal_eval_pdf, _metal_sample: GGX or Beckmann, a mirror at alpha 0):
the emission with its MIS weight (a diffuse emitter), the AOV albedo of a glossy vertex where
the path's is open (bsdfs.bsdf_albedo's; a smooth metal, a delta BSDF, leaves it open for the
next vertex; lanes.albedo_aov writes the diffuse ones), the guide's roulette where it plays it
at the vertex (GuideState.rr_late), the guide's map (guiding.contract.locate), a light sample
from the alias table with MIS by the power heuristic against the mixture's density (none at a
smooth metal), the continuation from the one-sample mixture of the map and the BSDF (a delta
flag where a mirror lobe was picked), the gain (p_bsdf / p_mixture along the path) and the
roulette, as shade_vertex and shading.next_bounce do them. With no guide (an empty GuideState)
that is plain BSDF sampling. The random numbers are the fast class's (sampling32.rand32 of the
lane's key at tracer.rng's dimensions; the mixture's coin at sampling32.strategy_dim), so the
images agree with the other loops' in expectation. A module of its own: Numba caches by file,
and this kernel inlines the BSDFs' and the guide's functions.
"""
import math

import numpy as np
from numba import prange

from .._jit import jit, kernel
from ..bsdfs import (COATED, DIFFUSE, METAL, ONE_SIDED, _coated_eval_pdf, _coated_sample, _diffuse_eval, _diffuse_pdf,
                     _diffuse_sample, _metal_eval_pdf, _metal_f, _metal_sample, lum)
from ..guiding.contract import locate, slot_sample
from ..guiding.records import RECORD_NONE, record_emission, record_sampled, record_vectors
from ..material import _unit_toward
from ..sampling import dot, frame, to_local, to_world
from ..shading import BLACK, bsdf_in_mixture, guided_weight, mixture_pdf, offset_point, survival
from .rows import (ALIVE, BB, BG, BR, DELTA, DEPTH, DX, DY, DZ, G_N, G_VN, H_T, KEY, L_LIGHTS, L_MAX, L_NEE, L_RR,
                   L_SMOOTH, LR, OX, OY, OZ, PDF, SB, SDX, SDY, SDZ, SG, SHADOW, SLOT, SOX, SOY, SOZ, SR,
                   TL_AREA, TL_EMIT, TL_EPS, TL_SEL, TMAX)
from .sampling32 import (BLOCK, BOUNCE, D_COIN, D_DIR, D_LIGHT, D_LOBE, D_POS, D_RR, SHORT, alias_column, hash32,
                         rand32, strategy_dim)
from .vertex import MAX_BOUNCES

@jit(inline="always")
def corner_normal(geo, p, b1, b2):
    """The shading normal of triangle p at barycentrics (b1, b2), float64, from the lanes' geo table
    (engine.rows): its corner normals interpolated, turned into the geometric normal's hemisphere;
    the geometric normal where they vanish (as material.shading_normal)."""
    b0 = 1.0 - b1 - b2
    n = (b0 * geo[p, G_VN] + b1 * geo[p, G_VN + 3] + b2 * geo[p, G_VN + 6],
         b0 * geo[p, G_VN + 1] + b1 * geo[p, G_VN + 4] + b2 * geo[p, G_VN + 7],
         b0 * geo[p, G_VN + 2] + b1 * geo[p, G_VN + 5] + b2 * geo[p, G_VN + 8])
    ng = (np.float64(geo[p, G_N]), np.float64(geo[p, G_N + 1]), np.float64(geo[p, G_N + 2]))
    return _unit_toward(n, ng, ng)


@jit(inline="always")
def _eval_pdf(kind, prm, table, wo, wi):
    """(f cos, pdf) of the listed vertex's BSDF (kind: bsdfs.DIFFUSE, COATED or METAL) for wo -> wi."""
    if kind == DIFFUSE:
        return _diffuse_eval((prm[0], prm[1], prm[2]), wo, wi), _diffuse_pdf(wo, wi)
    if kind == COATED:
        return _coated_eval_pdf(prm, table, wo, wi)
    return _metal_eval_pdf(prm, wo, wi)


@jit(inline="always")
def _sample(kind, prm, table, wo, u0, u1, ul):
    """(wi, f cos / pdf, pdf, delta) sampled from the listed vertex's BSDF (_eval_pdf's kind)."""
    if kind == DIFFUSE:
        return _diffuse_sample((prm[0], prm[1], prm[2]), wo, u0, u1)
    if kind == COATED:
        return _coated_sample(prm, table, wo, u0, u1, ul)
    return _metal_sample(prm, wo, u0, u1)


@kernel
def shade_listed(lf, li, hit, prim, sh, flags, listed, rows, alias, lim, surf, state, gs, centre, rec, rec_at):
    """Shade the vertex of each lane listed[0 ..] (classify's list; its triangle's material, DIFFUSE,
    COATED or METAL, from the material.Surfaces `surf`, its parameters with the colour kd[:, lane]
    in place of its reflectance (DIFFUSE, COATED) or specular reflectance (METAL); an escape ends
    the path): the emission into the lane's radiance, the AOV albedo of a glossy vertex into the
    wave's PathState `state` where aov_open, the NEE sample into the shadow rows (flags[SHADOW]),
    the sampled next ray, throughput, density, delta flag and depth into the lane and the state
    (with the gain: split_lanes reads them there), the roulette into flags[ALIVE]. The guide's
    GuideState gs (positions: the lanes' plus centre); rows = (geo, tl, kd) and alias = (alias_t,
    alias_i) the rows lanes.shade takes, and lim. rec_at = (record, rec_base): with `record`
    (guiding.records' RECORD_ALL or RECORD_INDIRECT) lane k's vertex is record rec_base + k of the
    guiding.records.Records `rec`, written as the wavefront writes it (record_emission,
    record_sampled). A recording lane keeps its radiance in the slot's row of the PathState's L
    (float64) instead of the lane's float32 rows, so that a record's radiance, the difference of the
    path's radiance at its end and at the vertex, is exactly 0 where nothing came back along its
    direction (float32 rounding would leave tiny positive values there, which the weight window
    would take for an estimate of a voxel's outgoing radiance)."""
    geo, tl, kd = rows
    record, rec_base = rec_at
    rr_depth = lim[L_RR]
    max_depth = lim[L_MAX]
    nee = lim[L_NEE] != 0
    smooth = lim[L_SMOOTH] != 0
    alias_t, alias_i = alias
    nl = alias_t.shape[0]
    lights = lim[L_LIGHTS] > 0
    guided = gs.res[0] > 0 or gs.pixel_slot.shape[0] > 0
    aov = state.aov
    aov_open = state.aov_open
    beta = state.beta
    gain = state.gain
    depth = state.depth
    prev_pdf = state.prev_pdf
    prev_delta = state.prev_delta
    pix = state.pix
    L = state.L
    prev_rec = state.prev_rec
    r_x = rec.x
    r_n = rec.n
    r_wi = rec.wi
    r_pdf = rec.pdf
    r_fcos = rec.fcos
    r_strategy = rec.strategy
    r_node = rec.node
    r_path = rec.path
    r_pixel = rec.pixel
    r_L0 = rec.L0
    r_beta = rec.beta
    r_pb = rec.pb
    r_prev = rec.prev
    r_direct = rec.direct
    r_plight = rec.plight
    material = surf.material
    mat_type = surf.mat_type
    mat_param = surf.mat_param
    table = surf.mat_table
    for j in prange(listed.shape[0]):
        k = listed[j]
        p = prim[k]
        flags[SHADOW, k] = np.int32(0)
        flags[ALIVE, k] = np.int32(0)
        if record != RECORD_NONE:
            r_strategy[rec_base + k] = -1
        if p < 0:  # an escape with no environment: the path ends
            continue
        i = li[SLOT, k]
        if record != RECORD_NONE:  # a recording lane keeps its radiance in L (float64), as the wavefront's
            for c in range(3):
                L[i, c] += lf[LR + c, k]
                lf[LR + c, k] = 0.0
        d = (np.float64(lf[DX, k]), np.float64(lf[DY, k]), np.float64(lf[DZ, k]))
        b1 = np.float64(hit[1, k])
        b2 = np.float64(hit[2, k])
        x = (geo[p, 0] + b1 * np.float64(geo[p, 3]) + b2 * np.float64(geo[p, 6]),
             geo[p, 1] + b1 * np.float64(geo[p, 4]) + b2 * np.float64(geo[p, 7]),
             geo[p, 2] + b1 * np.float64(geo[p, 5]) + b2 * np.float64(geo[p, 8]))
        ng = (np.float64(geo[p, G_N]), np.float64(geo[p, G_N + 1]), np.float64(geo[p, G_N + 2]))
        cos_o = -dot(d, ng)
        bt = (np.float64(lf[BR, k]), np.float64(lf[BG, k]), np.float64(lf[BB, k]))
        dk = li[DEPTH, k]
        pdelta = li[DELTA, k] != 0
        key = li[KEY, k]
        base = BOUNCE + BLOCK * dk

        # emission (a diffuse emitter, one-sided), MIS-weighted against the light sample that could have found it
        if cos_o > 0.0 and tl[p, TL_SEL] > 0.0:
            th = np.float64(hit[H_T, k])
            we = 1.0
            if nee and dk > 0 and not pdelta:
                pl = tl[p, TL_SEL] * th * th / (tl[p, TL_AREA] * cos_o)
                pp = np.float64(lf[PDF, k]) ** 2
                we = pp / (pp + pl * pl)
            le = (np.float64(tl[p, TL_EMIT]), np.float64(tl[p, TL_EMIT + 1]), np.float64(tl[p, TL_EMIT + 2]))
            for c in range(3):
                if record != RECORD_NONE:
                    L[i, c] += bt[c] * le[c] * we
                else:
                    lf[LR + c, k] += bt[c] * le[c] * we
            if record != RECORD_NONE and prev_rec[i] >= 0:
                record_emission(prev_rec[i], record, bt, le, we, np.float64(lf[PDF, k]), r_L0, r_direct, r_plight)

        ns = corner_normal(geo, p, b1, b2)
        s, t = frame(ns)
        wo = to_local((-d[0], -d[1], -d[2]), s, t, ns)
        m = material[p]
        kind = mat_type[m]
        c0, c1, c2 = np.float64(kd[0, k]), np.float64(kd[1, k]), np.float64(kd[2, k])  # the colour
        prm = ((mat_param[m, 0], mat_param[m, 1], mat_param[m, 2], c0, c1, c2) if kind == METAL else
               (c0, c1, c2, mat_param[m, 3], mat_param[m, 4], mat_param[m, 5]))
        prm = prm + (mat_param[m, 6], mat_param[m, 7], mat_param[m, 8], mat_param[m, 9], mat_param[m, 10],
                     mat_param[m, 11], mat_param[m, 12], mat_param[m, 13], mat_param[m, 14], mat_param[m, 15],
                     mat_param[m, 16])
        smooth_metal = kind == METAL and prm[6] <= 0.0  # a delta BSDF: no light sample, no guide
        if kind != DIFFUSE and aov_open[i]:  # bsdfs.bsdf_albedo's; a delta BSDF writes its own, leaves it open
            alb = (c0, c1, c2) if kind == COATED else _metal_f(prm, 1.0)
            for c in range(3):
                aov[i, c] = alb[c]
            aov_open[i] = smooth_metal
        black = (int(prm[14]) & ONE_SIDED) != 0 and wo[2] <= 0.0  # a one-sided surface seen from behind
        on = (max_depth < 0 or dk + 1 < max_depth) and not black
        eps = np.float64(tl[p, TL_EPS])
        gn = gain[i]

        # the guide's roulette of the bounce that arrived here, after its emission (never after a delta bounce)
        if on and gs.rr_late != 0 and dk >= rr_depth and not pdelta:
            qa = survival(bt, gn, gs)
            if np.float64(rand32(key, base - BLOCK + D_RR)) >= qa:
                on = False
            else:
                bt = (bt[0] / qa, bt[1] / qa, bt[2] / qa)

        # the guide's map and the probability a of sampling the BSDF
        node = -1
        slot = -1
        a = 1.0
        nf = ng if cos_o >= 0.0 else (-ng[0], -ng[1], -ng[2])
        xw = (x[0] + centre[0], x[1] + centre[1], x[2] + centre[2])
        if on and guided and not smooth_metal:
            node, slot, a = locate(gs, xw, nf, pix[i], dk)

        # a light sample: an emissive triangle from the alias table, a point uniform on it, MIS
        # against the mixture's density of that direction
        if on and nee and lights and not smooth_metal:
            col = alias_column(key, base + D_LIGHT, nl)
            lj = alias_i[0, col] if hash32(key, base + D_COIN) < alias_t[col] else alias_i[1, col]
            su = math.sqrt(np.float64(rand32(key, base + D_POS)))
            lb1 = 1.0 - su
            lb2 = np.float64(rand32(key, base + D_POS + 1)) * su
            w = (geo[lj, 0] + lb1 * np.float64(geo[lj, 3]) + lb2 * np.float64(geo[lj, 6]) - x[0],
                 geo[lj, 1] + lb1 * np.float64(geo[lj, 4]) + lb2 * np.float64(geo[lj, 7]) - x[1],
                 geo[lj, 2] + lb1 * np.float64(geo[lj, 5]) + lb2 * np.float64(geo[lj, 8]) - x[2])
            d2 = dot(w, w)
            if d2 > 0.0:
                dist = math.sqrt(d2)
                wl = (w[0] / dist, w[1] / dist, w[2] / dist)
                cos_l = -(wl[0] * geo[lj, G_N] + wl[1] * geo[lj, G_N + 1] + wl[2] * geo[lj, G_N + 2])
                if cos_l > 0.0:
                    pls = tl[lj, TL_SEL] * d2 / (tl[lj, TL_AREA] * cos_l)
                    wil = to_local(wl, s, t, ns)
                    f, pb = _eval_pdf(kind, prm, table, wo, wil)
                    pb = mixture_pdf(gs, slot, a, pb, wl)
                    leak = smooth and ((wo[2] * wil[2] > 0.0) != (cos_o * dot(wl, ng) > 0.0))
                    g = pls / (pls * pls + pb * pb)  # the power heuristic's weight over pls
                    if not leak and pls > 0.0 and (f[0] > 0.0 or f[1] > 0.0 or f[2] > 0.0):
                        # from the offset origin to the light point pushed off its triangle, toward x,
                        # by the light's own offset (as shading.shadow_ray)
                        so = offset_point(x, ng, wl, eps)
                        el = np.float64(tl[lj, TL_EPS])
                        e = (x[0] + w[0] + el * geo[lj, G_N] - so[0], x[1] + w[1] + el * geo[lj, G_N + 1] - so[1],
                             x[2] + w[2] + el * geo[lj, G_N + 2] - so[2])
                        te = math.sqrt(dot(e, e))
                        if te > 0.0:
                            flags[SHADOW, k] = np.int32(1)
                            sh[SOX, k] = so[0]
                            sh[SOY, k] = so[1]
                            sh[SOZ, k] = so[2]
                            sh[SDX, k] = e[0] / te
                            sh[SDY, k] = e[1] / te
                            sh[SDZ, k] = e[2] / te
                            sh[TMAX, k] = te * SHORT
                            sh[SR, k] = bt[0] * f[0] * tl[lj, TL_EMIT] * g
                            sh[SG, k] = bt[1] * f[1] * tl[lj, TL_EMIT + 1] * g
                            sh[SB, k] = bt[2] * f[2] * tl[lj, TL_EMIT + 2] * g
        if not on:
            continue

        # the continuation: the guide's map with probability 1 - a, else the BSDF (its lobe by
        # D_LOBE); its weight with the mixture's density; then the roulette
        u0 = np.float64(rand32(key, base + D_DIR))
        u1 = np.float64(rand32(key, base + D_DIR + 1))
        strategy = 0
        if a < 1.0 and np.float64(rand32(key, strategy_dim(dk))) >= a:
            wiw, pg = slot_sample(gs, slot, u0, u1)
            wi = to_local(wiw, s, t, ns)
            f, pbs = _eval_pdf(kind, prm, table, wo, wi)
            wt, pdf, ratio = guided_weight(f, pbs, pg, a)
            dlt = False
            strategy = 1
        else:
            wi, wt, pbs, dlt = _sample(kind, prm, table, wo, u0, u1, np.float64(rand32(key, base + D_LOBE)))
            wiw = to_world(wi, s, t, ns)
            wt, pdf, ratio = bsdf_in_mixture(gs, slot, a, wiw, wt, pbs, dlt)
        if smooth and ((wo[2] * wi[2] > 0.0) != (cos_o * dot(wiw, ng) > 0.0)):
            wt = BLACK
        gn = gn * ratio
        nb = (bt[0] * wt[0], bt[1] * wt[1], bt[2] * wt[2])
        bmax = max(nb[0], max(nb[1], nb[2]))
        go = bmax > 0.0 and math.isfinite(bmax) and dk + 1 < MAX_BOUNCES
        pre = nb  # before the roulette: a record's throughput with gs.rec_q
        if go and dk + 1 >= rr_depth and gs.rr_late == 0:
            qb = survival(nb, gn, gs)
            go = np.float64(rand32(key, base + D_RR)) < qb
            nb = (nb[0] / qb, nb[1] / qb, nb[2] / qb)
        if record != RECORD_NONE:
            rb = pre if gs.rec_q != 0 else (nb if go else BLACK)
            L0 = (L[i, 0], L[i, 1], L[i, 2])  # the lane's rows are flushed into L while recording
            vx = (not smooth_metal and not dlt and pdf > 0.0, xw, nf, wiw, strategy, node, pdf, pbs, lum(wt) * pdf, rb,
                  L0)
            if record_sampled(i, rec_base + k, vx, prev_rec, pix, r_prev, r_strategy, r_node, r_path, r_pixel, r_pdf,
                              r_pb, r_fcos, r_direct, r_plight):
                record_vectors(rec_base + k, vx, r_x, r_n, r_wi, r_L0, r_beta)
        if go:
            o = offset_point(x, ng, wiw, eps)
            lf[OX, k] = o[0]
            lf[OY, k] = o[1]
            lf[OZ, k] = o[2]
            lf[DX, k] = wiw[0]
            lf[DY, k] = wiw[1]
            lf[DZ, k] = wiw[2]
            lf[PDF, k] = pdf
            li[DEPTH, k] = np.int32(dk + 1)
            li[DELTA, k] = np.int32(1) if dlt else np.int32(0)
            for c in range(3):
                lf[BR + c, k] = nb[c]
                beta[i, c] = nb[c]
            gain[i] = gn
            depth[i] = dk + 1
            prev_pdf[i] = pdf
            prev_delta[i] = dlt
            flags[ALIVE, k] = np.int32(1)
