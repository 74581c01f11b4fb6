"""The lanes' glossy class: Mitsuba's plastic and roughplastic (bsdfs.COATED) and its conductor
and roughconductor (bsdfs.METAL), one listed kernel.

`shade_glossy` shades the lanes classify listed as glossy: opaque triangles of those materials
that do not emit, whose colour (the coat's diffuse reflectance, the metal's specular one) may be
a texture (the reflectance kernel's kd rows) but nothing else, in a scene lit by triangles only.
Per lane, in float64 through the BSDF's own functions (bsdfs._coated_eval_pdf, _coated_sample:
the rough coat's GGX or Beckmann lobe and the smooth coat's mirror lobe beside the diffuse base;
bsdfs._metal_eval_pdf, _metal_sample: GGX or Beckmann, a mirror at alpha 0): the AOV albedo
where the path's is open (bsdfs.bsdf_albedo's; a smooth metal, a delta BSDF, leaves it open for
the next vertex), a
light sample from the alias table with MIS by the power heuristic (none at a smooth metal), the
sampled continuation (a delta flag where a mirror lobe was picked), the roulette, as
shade_vertex does them with no guide. The random numbers are the fast class's (sampling32.rand32
of the lane's key at tracer.rng's dimensions), so the images agree with the other loops' in
expectation. A module of its own: Numba caches by file, and this kernel inlines the BSDFs'
functions.
"""
import math

import numpy as np
from numba import prange

from .._jit import jit, kernel
from ..bsdfs import COATED, ONE_SIDED, _coated_eval_pdf, _coated_sample, _metal_eval_pdf, _metal_f, _metal_sample
from ..sampling import dot, frame, to_local, to_world
from ..material import _unit_toward
from ..shading import offset_point
from .rows import (ALIVE, BB, BG, BR, DELTA, DEPTH, DX, DY, DZ, G_N, G_VN, KEY, L_LIGHTS, L_MAX, L_NEE, L_RR,
                   L_SMOOTH, OX, OY, OZ, PDF, SB, SDX, SDY, SDZ, SG, SHADOW, SLOT, SOX, SOY, SOZ, SR, TL_AREA,
                   TL_EMIT, TL_EPS, TL_SEL, TMAX)
from .sampling32 import (BLOCK, BOUNCE, D_COIN, D_DIR, D_LIGHT, D_LOBE, D_POS, D_RR, RR_MAX, SHORT, alias_column, hash32,
                         rand32)
from .vertex import MAX_BOUNCES


@jit(inline="always")
def corner_normal(geo, p, b1, b2):
    """The shading normal of triangle p at barycentrics (b1, b2), float64, from the lanes' geo rows
    (engine.rows): its corner normals interpolated, turned into the geometric normal's hemisphere;
    the geometric normal where they vanish (as material.shading_normal)."""
    b0 = 1.0 - b1 - b2
    n = (b0 * geo[G_VN, p] + b1 * geo[G_VN + 3, p] + b2 * geo[G_VN + 6, p],
         b0 * geo[G_VN + 1, p] + b1 * geo[G_VN + 4, p] + b2 * geo[G_VN + 7, p],
         b0 * geo[G_VN + 2, p] + b1 * geo[G_VN + 5, p] + b2 * geo[G_VN + 8, p])
    ng = (np.float64(geo[G_N, p]), np.float64(geo[G_N + 1, p]), np.float64(geo[G_N + 2, p]))
    return _unit_toward(n, ng, ng)


@kernel
def shade_glossy(lf, li, hit, prim, sh, flags, glossy, geo, tl, kd, alias_t, alias_i, lim, surf, state):
    """Shade the vertex of each lane glossy[0 ..] (classify's list; its triangle's material, COATED
    or METAL, from the material.Surfaces `surf`, its parameters with the colour kd[:, lane] in
    place of its reflectance (COATED) or specular reflectance (METAL)): the AOV
    albedo into the wave's PathState `state` where aov_open, the NEE sample into the shadow rows
    (flags[SHADOW]), the sampled next ray, throughput, density, delta flag and depth into the lane,
    the roulette into flags[ALIVE]. The scene's rows (geo, tl, alias_t, alias_i) and lim as
    lanes.shade takes them."""
    rr_depth = lim[L_RR]
    max_depth = lim[L_MAX]
    nee = lim[L_NEE] != 0
    smooth = lim[L_SMOOTH] != 0
    nl = alias_t.shape[0]
    lights = lim[L_LIGHTS] > 0
    aov = state.aov
    aov_open = state.aov_open
    material = surf.material
    mat_type = surf.mat_type
    mat_param = surf.mat_param
    table = surf.mat_table
    for j in prange(glossy.shape[0]):
        k = glossy[j]
        p = prim[k]
        d = (np.float64(lf[DX, k]), np.float64(lf[DY, k]), np.float64(lf[DZ, k]))
        b1 = np.float64(hit[1, k])
        b2 = np.float64(hit[2, k])
        x = (geo[0, p] + b1 * np.float64(geo[3, p]) + b2 * np.float64(geo[6, p]),
             geo[1, p] + b1 * np.float64(geo[4, p]) + b2 * np.float64(geo[7, p]),
             geo[2, p] + b1 * np.float64(geo[5, p]) + b2 * np.float64(geo[8, p]))
        ng = (np.float64(geo[G_N, p]), np.float64(geo[G_N + 1, p]), np.float64(geo[G_N + 2, p]))
        cos_o = -dot(d, ng)
        ns = corner_normal(geo, p, b1, b2)
        s, t = frame(ns)
        wo = to_local((-d[0], -d[1], -d[2]), s, t, ns)
        m = material[p]
        coat = mat_type[m] == COATED
        c0, c1, c2 = np.float64(kd[0, k]), np.float64(kd[1, k]), np.float64(kd[2, k])  # the colour
        prm = ((c0, c1, c2, mat_param[m, 3], mat_param[m, 4], mat_param[m, 5]) if coat else
               (mat_param[m, 0], mat_param[m, 1], mat_param[m, 2], c0, c1, c2))
        prm = prm + (mat_param[m, 6], mat_param[m, 7], mat_param[m, 8], mat_param[m, 9], mat_param[m, 10],
                     mat_param[m, 11], mat_param[m, 12], mat_param[m, 13], mat_param[m, 14], mat_param[m, 15],
                     mat_param[m, 16])
        smooth_metal = not coat and prm[6] <= 0.0  # a delta BSDF: no light sample
        i = li[SLOT, k]
        if aov_open[i]:  # bsdfs.bsdf_albedo's; a delta BSDF writes its own and leaves the AOV open
            alb = (c0, c1, c2) if coat else _metal_f(prm, 1.0)
            for q in range(3):
                aov[i, q] = alb[q]
            aov_open[i] = smooth_metal
        black = (int(prm[14]) & ONE_SIDED) != 0 and wo[2] <= 0.0  # a one-sided surface seen from behind
        beta = (np.float64(lf[BR, k]), np.float64(lf[BG, k]), np.float64(lf[BB, k]))
        depth = li[DEPTH, k]
        key = li[KEY, k]
        base = BOUNCE + BLOCK * depth
        on = (max_depth < 0 or depth + 1 < max_depth) and not black
        eps = np.float64(tl[TL_EPS, p])

        # a light sample: an emissive triangle from the alias table, a point uniform on it, MIS
        # against the coat's own density of that direction
        shadow = False
        if on and nee and lights and not smooth_metal:
            c = alias_column(key, base + D_LIGHT, nl)
            lj = alias_i[0, c] if hash32(key, base + D_COIN) < alias_t[c] else alias_i[1, c]
            su = math.sqrt(np.float64(rand32(key, base + D_POS)))
            lb1 = 1.0 - su
            lb2 = np.float64(rand32(key, base + D_POS + 1)) * su
            w = (geo[0, lj] + lb1 * np.float64(geo[3, lj]) + lb2 * np.float64(geo[6, lj]) - x[0],
                 geo[1, lj] + lb1 * np.float64(geo[4, lj]) + lb2 * np.float64(geo[7, lj]) - x[1],
                 geo[2, lj] + lb1 * np.float64(geo[5, lj]) + lb2 * np.float64(geo[8, lj]) - x[2])
            d2 = dot(w, w)
            if d2 > 0.0:
                dist = math.sqrt(d2)
                wl = (w[0] / dist, w[1] / dist, w[2] / dist)
                cos_l = -(wl[0] * geo[G_N, lj] + wl[1] * geo[G_N + 1, lj] + wl[2] * geo[G_N + 2, lj])
                if cos_l > 0.0:
                    pls = tl[TL_SEL, lj] * d2 / (tl[TL_AREA, lj] * cos_l)
                    wil = to_local(wl, s, t, ns)
                    f, pb = _coated_eval_pdf(prm, table, wo, wil) if coat else _metal_eval_pdf(prm, wo, wil)
                    leak = smooth and ((wo[2] * wil[2] > 0.0) != (cos_o * dot(wl, ng) > 0.0))
                    g = pls / (pls * pls + pb * pb)  # the power heuristic's weight over pls
                    if not leak and pls > 0.0 and (f[0] > 0.0 or f[1] > 0.0 or f[2] > 0.0):
                        # from the offset origin to the light point pushed off its triangle, toward x,
                        # by the light's own offset (as shading.shadow_ray)
                        so = offset_point(x, ng, wl, eps)
                        el = np.float64(tl[TL_EPS, lj])
                        e = (x[0] + w[0] + el * geo[G_N, lj] - so[0], x[1] + w[1] + el * geo[G_N + 1, lj] - so[1],
                             x[2] + w[2] + el * geo[G_N + 2, lj] - so[2])
                        te = math.sqrt(dot(e, e))
                        shadow = te > 0.0
                        sh[SOX, k] = so[0]
                        sh[SOY, k] = so[1]
                        sh[SOZ, k] = so[2]
                        sh[SDX, k] = e[0] / te if shadow else wl[0]
                        sh[SDY, k] = e[1] / te if shadow else wl[1]
                        sh[SDZ, k] = e[2] / te if shadow else wl[2]
                        sh[TMAX, k] = te * SHORT
                        sh[SR, k] = beta[0] * f[0] * tl[TL_EMIT, lj] * g
                        sh[SG, k] = beta[1] * f[1] * tl[TL_EMIT + 1, lj] * g
                        sh[SB, k] = beta[2] * f[2] * tl[TL_EMIT + 2, lj] * g
        flags[SHADOW, k] = np.int32(1) if shadow else np.int32(0)

        # the continuation: the coat's sample (its lobe by D_LOBE), then the roulette
        go = False
        if on:
            u0 = np.float64(rand32(key, base + D_DIR))
            u1 = np.float64(rand32(key, base + D_DIR + 1))
            ul = np.float64(rand32(key, base + D_LOBE))
            if coat:
                wi, wt, pdf, dlt = _coated_sample(prm, table, wo, u0, u1, ul)
            else:
                wi, wt, pdf, dlt = _metal_sample(prm, wo, u0, u1)
            wiw = to_world(wi, s, t, ns)
            if smooth and ((wo[2] * wi[2] > 0.0) != (cos_o * dot(wiw, ng) > 0.0)):
                wt = (0.0, 0.0, 0.0)
            nb = (beta[0] * wt[0], beta[1] * wt[1], beta[2] * wt[2])
            bmax = max(nb[0], max(nb[1], nb[2]))
            go = bmax > 0.0 and math.isfinite(bmax) and depth + 1 < MAX_BOUNCES
            if go and depth + 1 >= rr_depth:
                q = min(bmax, RR_MAX)
                go = np.float64(rand32(key, base + D_RR)) < q
                nb = (nb[0] / q, nb[1] / q, nb[2] / q)
            if go:
                o = offset_point(x, ng, wiw, eps)
                lf[OX, k] = o[0]
                lf[OY, k] = o[1]
                lf[OZ, k] = o[2]
                lf[DX, k] = wiw[0]
                lf[DY, k] = wiw[1]
                lf[DZ, k] = wiw[2]
                lf[BR, k] = nb[0]
                lf[BG, k] = nb[1]
                lf[BB, k] = nb[2]
                lf[PDF, k] = pdf
                li[DEPTH, k] = np.int32(depth + 1)
                li[DELTA, k] = np.int32(1) if dlt else np.int32(0)
        flags[ALIVE, k] = np.int32(1) if go else np.int32(0)
