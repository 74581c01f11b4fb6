"""Shading of a base path and its four offsets at one bounce of the hybrid shift (shade_hybrid):
emission and next-event estimation weighted over the four techniques of each pixel pair, the
base's next direction; add_next_event adds the NEE terms once the shadow rays are known. The
weights are derived in hybrid.py's docstring."""

import math
from typing import NamedTuple

from numba import prange

from .. import bsdfs
from .._jit import jit, kernel
from ..integrators.path import MAX_BOUNCES
from ..lights import (ENV_NONE, LIGHT_ENV, delta_arrival, delta_light_of, env_pdf, env_radiance, triangle_emission,
                      triangle_light_pdf)
from ..guiding.contract import locate
from ..rng import LIGHT, LIGHT_POS, RR, bounce_dim, draw
from ..material import costly_surfaces, crosses, keep_surface, surface_at, surface_at_point
from ..sampling import dot, to_local, triangle_point
from ..shading import emitted_env, emitted_surface, light_sample_at, next_bounce, offset_point, survival
from ..shading import shadow_ray, write_aovs, write_shadow
from .offsets import BLOCKED, CONNECTED, TRACED
from .shift import is_near_specular, is_rough, path_density, reconnection

# NeeTerms.mode of an offset at a bounce: no NEE term; the base's own weighted value alone (no
# partner path); the partner shares the base's shadow ray (the offset sits at the base's vertex);
# the partner traces its own shadow ray
NEE_NONE, NEE_BASE_ALONE, NEE_BASE_RAY, NEE_OWN_RAY = 0, 1, 2, 3


class ShiftLimits(NamedTuple):
    """The scalars of a hybrid bounce: path length limits and the shift's thresholds."""

    max_depth: int  # bounces at most (-1: none)
    rr_depth: int  # the depth from which the base plays Russian roulette
    roughness: float  # bsdfs.bsdf_roughness above which a vertex is rough (reconnectable)
    direct_roughness: float  # a first vertex smoother than it: its reflected light is direct light


@jit(inline="always")
def _emitted_by(lt, tri_normal, q, wo, dist2, delta):
    """(radiance, light density) of what an offset's vertex emits toward its previous vertex: triangle
    q (-1: the environment along -wo), wo the unit direction back, dist2 the squared segment length;
    the light density is NEE's density of the same point (0 after a delta lobe)."""
    if q < 0:
        if lt.env_type == ENV_NONE:
            return (0.0, 0.0, 0.0), 0.0
        w = (-wo[0], -wo[1], -wo[2])
        return env_radiance(lt, w), 0.0 if delta else env_pdf(lt, w)
    if lt.light_of_tri[q] < 0:
        return (0.0, 0.0, 0.0), 0.0
    cos_o = wo[0] * tri_normal[q, 0] + wo[1] * tri_normal[q, 1] + wo[2] * tri_normal[q, 2]
    return triangle_emission(lt, q, cos_o), 0.0 if delta else triangle_light_pdf(lt, q, dist2, cos_o)


@kernel
def shade_hybrid(active, ray_d, hits, surf, lt, gs, ps, limits, state, cont, shr, bb, off, nt):
    """One bounce of base and offset paths: the vertices the offsets reached, emission (the base's
    as the path tracer's, the gradients' with the pair weights), NEE shifted to the offsets, the
    base's direction and roulette. Entry k is path active[k], its ray direction ray_d[k] and its hit
    in hits = (t, prim, b1, b2); surf: the scene's material.Surfaces; lt: lights; gs: guide state;
    ps: primary samples; limits: a ShiftLimits (max_depth, rr_depth, the shift's roughness and
    direct_roughness: a first vertex smoother than it puts the light it reflects, by NEE or by its
    BSDF sample, into L_cam with the light seen directly, out of the gradients). The base's
    wave.PathState state, Continuation cont and ShadowRays shr (its value for L); the
    offsets.BaseBounce bb this bounce writes; the Offsets off (their hits of traced rays in hit_*,
    where trace; their own shadow rays sh, sh_*); the NeeTerms nt, weighted by add_next_event once
    the shadow rays are traced."""
    t = hits[0]
    prim = hits[1]
    b1 = hits[2]
    b2 = hits[3]
    max_depth = limits[0]
    rr_depth = limits[1]
    roughness = limits[2]
    direct_roughness = limits[3]
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
    alive = cont.alive
    next_o = cont.next_o
    next_d = cont.next_d
    sh_o = shr.o
    sh_d = shr.d
    sh_tmax = shr.tmax
    sh_L = shr.L
    has_shadow = shr.has
    b_x = bb.x
    b_prim = bb.prim
    b_wo = bb.wo
    b_wt = bb.wt
    b_pdf = bb.pdf
    b_delta = bb.delta
    b_rough = bb.rough
    b_direct = bb.direct
    b_sf = bb.sf
    o_alive = off.alive
    o_status = off.status
    o_beta = off.beta
    o_R = off.R
    o_x = off.x
    o_prim = off.prim
    o_wo = off.wo
    o_pdf = off.pdf
    o_delta = off.delta
    o_dist2 = off.dist2
    o_rough = off.rough
    o_hv = off.hv
    o_lights = off.lights
    o_trace = off.trace
    G = off.G
    hit_t = off.hit_t
    hit_prim = off.hit_prim
    hit_b1 = off.hit_b1
    hit_b2 = off.hit_b2
    o_sh = off.sh
    o_sh_o = off.sh_o
    o_sh_d = off.sh_d
    o_sh_tmax = off.sh_tmax
    o_sf = off.sf
    o_kept = off.kept
    n_cn = nt.cn
    n_pl = nt.pl
    n_pb = nt.pb
    n_mode = nt.mode
    n_co = nt.co
    n_rj = nt.rj
    n_plo = nt.plo
    n_pbo = nt.pbo
    vis = nt.vis
    n_direct = nt.direct
    keeps = costly_surfaces(surf)  # keep the Surfaces that shift_offsets needs at the next bounce
    for k in prange(active.shape[0]):
        i = active[k]
        alive[k] = False
        has_shadow[k] = False
        n_direct[i] = False
        dk = depth[i]
        wray = (ray_d[k, 0], ray_d[k, 1], ray_d[k, 2])
        b = (beta[i, 0], beta[i, 1], beta[i, 2])
        p = prim[k]
        for o in range(4):
            o_sh[i, o] = False
            o_kept[i, o] = False
            vis[i, o] = False
            n_mode[i, o] = NEE_NONE
        if dk == 0:
            for c in range(3):
                L_cam[i, c] = 0.0
        x = (0.0, 0.0, 0.0)
        ng = (0.0, 0.0, 1.0)
        if p >= 0:
            x = triangle_point(surf.tri, p, b1[k], b2[k])
            ng = (surf.normal[p, 0], surf.normal[p, 1], surf.normal[p, 2])

        # Where the offsets are now
        for o in range(4):
            if not o_alive[i, o]:
                continue
            st = o_status[i, o]
            if st == CONNECTED:
                o_prim[i, o] = p
                o_dist2[i, o] = t[k] * t[k]
                for c in range(3):
                    o_x[i, o, c] = x[c]
                    o_wo[i, o, c] = -wray[c]
            elif st == TRACED and o_trace[i, o]:
                q = hit_prim[i, o]
                o_prim[i, o] = q
                o_dist2[i, o] = hit_t[i, o] * hit_t[i, o]
                if q >= 0:
                    y = triangle_point(surf.tri, q, hit_b1[i, o], hit_b2[i, o])
                    for c in range(3):
                        o_x[i, o, c] = y[c]
                # The reverse of a half-vector copy would reconnect here: not a bijection, fail
                if o_hv[i, o] and (q < 0 or is_rough(surf, surf.material[q], roughness)):
                    o_alive[i, o] = False

        # Emission: the base's (the path tracer's, MIS against NEE), and each pair's gradient
        le = (0.0, 0.0, 0.0)
        w = 1.0
        pl = 0.0
        if p < 0:
            if lt.env_type != ENV_NONE:
                le, w = emitted_env(lt, wray, dk, prev_pdf[i], prev_delta[i])
                if dk > 0 and not prev_delta[i]:
                    pl = env_pdf(lt, wray)
        elif lt.light_of_tri[p] >= 0:
            le, w = emitted_surface(lt, p, t[k] * t[k], -dot(wray, ng), dk, prev_pdf[i], prev_delta[i])
            if dk > 0 and not prev_delta[i]:
                pl = triangle_light_pdf(lt, p, t[k] * t[k], -dot(wray, ng))
        cb = (b[0] * le[0], b[1] * le[1], b[2] * le[2])
        direct = dk == 0 or (dk == 1 and b_direct[i])  # (the pair's offsets share it: see below)
        for c in range(3):
            L[i, c] += cb[c] * w
            if direct:
                L_cam[i, c] += cb[c] * w
        if not direct:
            rb = pl / prev_pdf[i]
            for o in range(4):
                if not o_alive[i, o]:  # the base's techniques alone: the path tracer's weight
                    for c in range(3):
                        G[i, o, c] -= cb[c] * w
                    continue
                leo, plo = _emitted_by(lt, surf.normal, o_prim[i, o], (o_wo[i, o, 0], o_wo[i, o, 1], o_wo[i, o, 2]),
                                       o_dist2[i, o], o_delta[i, o])
                ro = plo / o_pdf[i, o]
                R2 = o_R[i, o] * o_R[i, o]
                wb = 1.0
                wo_ = 1.0
                if o_status[i, o] == BLOCKED:  # no BSDF sample reaches x through the occluder: no light
                    den = 1.0 + rb * rb + R2 * ro * ro
                    leo = (0.0, 0.0, 0.0)
                elif o_lights[i, o]:
                    den = 1.0 + rb * rb + R2 * (1.0 + ro * ro)
                else:  # a half-vector copy: each side's NEE stays its own (NEE_BASE_ALONE), so each path
                    den = 1.0 + R2  # keeps its path tracer's BSDF weight, shared by the pair's two sides
                    wb = w
                    wo_ = 1.0 / (1.0 + ro * ro)
                for c in range(3):
                    G[i, o, c] += (o_beta[i, o, c] * leo[c] * wo_ - cb[c] * wb) / den
        for o in range(4):  # an offset that escaped, or was blocked, ends here
            if o_alive[i, o] and (o_prim[i, o] < 0 or o_status[i, o] == BLOCKED):
                o_alive[i, o] = False
        if p < 0:
            continue

        m = surf.material[p]
        cos_o = -dot(wray, ng)
        sf = surface_at(surf, p, b1[k], b2[k])
        delta = write_aovs(sf, i, dk, cos_o, t[k], aov, aov_open)
        if max_depth >= 0 and dk + 1 >= max_depth:
            continue
        wo = to_local((-wray[0], -wray[1], -wray[2]), sf.s, sf.t, sf.ns)
        kk = key[i]
        rough = is_rough(surf, m, roughness)
        near = dk == 0 and is_near_specular(surf, m, direct_roughness)
        if dk == 0:
            b_direct[i] = near
        for o in range(4):
            if o_alive[i, o]:
                if o_status[i, o] == TRACED:
                    mo = surf.material[o_prim[i, o]]
                    o_rough[i, o] = is_rough(surf, mo, roughness)
                    # A rough vertex and a glossy one have no shift between them: a half-vector copy
                    # would pair a diffuse bounce with a near-delta lobe (an offset of density ~0) and
                    # leave the gradient without NEE. The shift fails at both ends alike (the rule
                    # reads the two vertices' classes only), so each side keeps the path tracer's
                    # weights and the pair's gradient is the two pixels' own difference. So it does
                    # between first vertices on either side of direct_roughness: a pair's paths are
                    # then both direct light or both not.
                    if o_rough[i, o] != rough or (dk == 0 and is_near_specular(surf, mo, direct_roughness) != near):
                        o_alive[i, o] = False
                else:
                    o_rough[i, o] = rough

        # Where the guide's map is for the base (the path tracer's locate; a is 1 without one)
        slot = -1
        a = 1.0
        if not delta and gs.res[0] > 0:
            _, slot, a = locate(gs, x, ng if cos_o >= 0.0 else (-ng[0], -ng[1], -ng[2]), pix[i], dk)

        # NEE: the base's sample (the path tracer's), shifted to each offset (at a near-specular first
        # vertex: direct light, the base's alone, L_cam's and no gradient's)
        n_direct[i] = near
        if not delta:
            ls = light_sample_at(
                sf, lt, surf.tri, x, ng, cos_o, wo, b, gs, slot, a, surf.eps[p], surf.eps,
                (draw(ps, kk, i, bounce_dim(dk, LIGHT)), draw(ps, kk, i, bounce_dim(dk, LIGHT_POS)),
                 draw(ps, kk, i, bounce_dim(dk, LIGHT_POS + 1))), surf.mat_table)
            ok, so, sd, tmax, contrib = ls.ok, ls.origin, ls.direction, ls.tmax, ls.contrib
            wl, dist, lel, pll, lt_tri, fb, pbb = ls.wl, ls.dist, ls.le, ls.pl, ls.tri, ls.f, ls.pdf
            # (a delta light's sample counts where the base gets no light from it: past a spot's cutoff
            # its offsets may be lit, and their NEE must enter the gradients all the same)
            valid = pll > 0.0 and (lel[0] > 0.0 or lel[1] > 0.0 or lel[2] > 0.0 or lt_tri < LIGHT_ENV)
            if valid and not ok:  # no value, but its visibility enters the pairs' weights
                so, sd, tmax = shadow_ray(x, ng, surf.eps[p], wl, dist, lt, lt_tri, surf.eps)
                ok = tmax > 0.0
                contrib = (0.0, 0.0, 0.0)
            if ok:
                write_shadow(k, so, sd, tmax, contrib, sh_o, sh_d, sh_tmax, sh_L, has_shadow)
            if valid:
                n_pl[i] = pll
                n_pb[i] = pbb
                for c in range(3):
                    n_cn[i, c] = b[c] * fb[c] * lel[c] / pll
                zl = (x[0] + dist * wl[0], x[1] + dist * wl[1], x[2] + dist * wl[2])
                # A connected offset sits at the base's vertex and arrived along the base's ray: its f
                # and density of the light's direction are the base's, which light_sample_at evaluated
                # where the light gives anything (and without a guide, whose map the offset would look
                # up for itself: shift.path_density)
                same_nee = gs.res[0] == 0 and (lel[0] > 0.0 or lel[1] > 0.0 or lel[2] > 0.0)
                rough_z = lt_tri < 0 or is_rough(surf, surf.material[lt_tri], roughness)
                for o in range(4 if not near else 0):
                    if not o_alive[i, o]:
                        n_mode[i, o] = NEE_BASE_ALONE
                        continue
                    st = o_status[i, o]
                    if st == TRACED and not (rough and o_rough[i, o] and rough_z):
                        # The pair's BSDF sample would be copied, not reconnected: NEE has no partner
                        # (it reconnects, and both techniques must map a path to the same partner), so
                        # each side keeps its own NEE with the path tracer's weight, and the copied
                        # BSDF samples share the rest (the emission's weights above)
                        n_mode[i, o] = NEE_BASE_ALONE
                        continue
                    y = x
                    ngy = ng
                    sfy = sf
                    py = p
                    if st == TRACED:
                        py = o_prim[i, o]
                        y = (o_x[i, o, 0], o_x[i, o, 1], o_x[i, o, 2])
                        ngy = (surf.normal[py, 0], surf.normal[py, 1], surf.normal[py, 2])
                        sfy = surface_at_point(surf, py, y)
                        if keeps:  # for shift_offsets at the next bounce
                            keep_surface(o_sf, 4 * i + o, sfy)
                            o_kept[i, o] = True
                    wo_y = (o_wo[i, o, 0], o_wo[i, o, 1], o_wo[i, o, 2])
                    wlo = wl
                    disto = dist
                    jl = 1.0
                    leo = lel
                    plo = pll
                    if st == TRACED and lt_tri >= 0:
                        li = lt.light_of_tri[lt_tri]
                        nl = (lt.normal[li, 0], lt.normal[li, 1], lt.normal[li, 2])
                        wlo, disto, jl = reconnection(x, y, zl, nl)
                        if not jl > 0.0:  # no partner path: the base's techniques alone
                            n_mode[i, o] = NEE_BASE_ALONE
                            continue
                        cos_l = -dot(wlo, nl)
                        leo = triangle_emission(lt, lt_tri, cos_l)
                        plo = triangle_light_pdf(lt, lt_tri, disto * disto, cos_l)
                    elif st == TRACED and lt_tri < LIGHT_ENV:  # the same delta light, seen from y: Jacobian 1
                        wlo, disto, leo = delta_arrival(lt, delta_light_of(lt_tri), y)
                        if not disto > 0.0:
                            n_mode[i, o] = NEE_BASE_ALONE
                            continue
                    if st == CONNECTED and same_nee:  # the base's own vertex, directions and density
                        fo = fb
                        n_pbo[i, o] = pbb
                    else:
                        wo_o = to_local(wo_y, sfy.s, sfy.t, sfy.ns)
                        wil = to_local(wlo, sfy.s, sfy.t, sfy.ns)
                        fo, pbo = bsdfs.bsdf_eval_pdf(sfy.bp, wo_o, wil, True, surf.mat_table)
                        if crosses(sfy, dot(wo_y, ngy), ngy, wo_o, wil, wlo):
                            fo = (0.0, 0.0, 0.0)
                        n_pbo[i, o] = 0.0 if lt_tri < LIGHT_ENV else path_density(
                            gs, sfy.bp, y, ngy, wo_y, wlo, pbo, False)
                    n_plo[i, o] = plo
                    n_rj[i, o] = o_R[i, o] * jl
                    for c in range(3):
                        n_co[i, o, c] = o_beta[i, o, c] * jl * fo[c] * leo[c] / pll
                    if st != TRACED:  # at the base's vertex: the base's shadow ray
                        n_mode[i, o] = NEE_BASE_RAY
                        continue
                    n_mode[i, o] = NEE_OWN_RAY
                    oo, od, otmax = shadow_ray(y, ngy, surf.eps[py], wlo, disto, lt, lt_tri, surf.eps)
                    if otmax > 0.0:
                        o_sh[i, o] = True
                        o_sh_tmax[i, o] = otmax
                        for c in range(3):
                            o_sh_o[i, o, c] = oo[c]
                            o_sh_d[i, o, c] = od[c]

        # The base's next direction and roulette (the path tracer's, from the guide's mixture)
        nx = next_bounce(sf, gs, slot, a, wo, ng, cos_o, b, gain[i], dk, rr_depth, MAX_BOUNCES, ps, kk, i, surf.mat_table)
        wiw, wt, pdf, dlt, nb, gn, q = nx.wi, nx.weight, nx.pdf, nx.delta, nx.beta, nx.gain, nx.q
        if not nx.ok:
            # A base whose throughput is 0 (a black BSDF, such as a light's) still carries its offsets:
            # the other side of each pair weighs its paths as if this side found them too. Past
            # rr_depth the offsets' own throughput plays the roulette.
            if not (pdf > 0.0 and q == 1.0 and max(nb[0], max(nb[1], nb[2])) == 0.0 and dk + 1 < MAX_BOUNCES):
                continue
            bo = 0.0
            for o in range(4):
                if o_alive[i, o]:
                    bo = max(bo, max(o_beta[i, o, 0], max(o_beta[i, o, 1], o_beta[i, o, 2])))
            if not (bo > 0.0 and math.isfinite(bo)):
                continue
            if dk + 1 >= rr_depth:
                q = survival((bo, bo, bo), gn, gs)  # the base's roulette, on the offsets' throughput
                if draw(ps, kk, i, bounce_dim(dk, RR)) >= q:
                    continue
        no = offset_point(x, ng, wiw, surf.eps[p])
        for c in range(3):
            beta[i, c] = nb[c]
            next_o[k, c] = no[c]
            next_d[k, c] = wiw[c]
            b_x[i, c] = x[c]
            b_wo[i, c] = -wray[c]
            b_wt[i, c] = wt[c]
        for o in range(4):
            for c in range(3):
                o_beta[i, o, c] /= q
        b_prim[i] = p
        b_pdf[i] = pdf
        if keeps:
            keep_surface(b_sf, i, sf)
        b_delta[i] = dlt
        b_rough[i] = rough and not dlt
        gain[i] = gn
        depth[i] = dk + 1
        prev_pdf[i] = pdf
        prev_delta[i] = dlt
        alive[k] = True


@kernel
def add_next_event(active, shr, L, L_cam, G, nt):
    """Add the bounce's NEE once its shadow rays are traced (the base's wave.ShadowRays shr, and
    the NeeTerms nt with the visibilities): the base's value to L, and to each pair's
    gradient w (vis_o C_o - vis_b C_b), w = pL^2 / (pL^2 + pB^2 + (R J_L)^2 (pL_o^2 + pB_o^2)), where a
    blocked side's BSDF density is 0 (a BSDF sample cannot reach the light through the occluder).
    NEE_BASE_ALONE (no partner): minus the base's own weighted value. nt.direct: the base's value is
    direct light (L_cam) too."""
    sh_L = shr.L
    has_shadow = shr.has
    n_cn = nt.cn
    n_pl = nt.pl
    n_pb = nt.pb
    vis_b = nt.vis_b
    n_mode = nt.mode
    n_co = nt.co
    n_rj = nt.rj
    n_plo = nt.plo
    n_pbo = nt.pbo
    vis = nt.vis
    n_direct = nt.direct
    for k in prange(active.shape[0]):
        i = active[k]
        vb = has_shadow[k] and vis_b[k]
        if vb:
            for c in range(3):
                L[i, c] += sh_L[k, c]
                if n_direct[i]:
                    L_cam[i, c] += sh_L[k, c]
        for o in range(4):
            mode = n_mode[i, o]
            if mode == NEE_NONE:
                continue
            if mode == NEE_BASE_ALONE:
                if vb:
                    for c in range(3):
                        G[i, o, c] -= sh_L[k, c]
                continue
            vo = vb if mode == NEE_BASE_RAY else vis[i, o]
            pl = n_pl[i]
            pb = n_pb[i] if vb else 0.0
            po = n_pbo[i, o] if vo else 0.0
            rj = n_rj[i, o]
            wg = pl * pl / (pl * pl + pb * pb + rj * rj * (n_plo[i, o] * n_plo[i, o] + po * po))
            for c in range(3):
                G[i, o, c] += wg * ((n_co[i, o, c] if vo else 0.0) - (n_cn[i, c] if vb else 0.0))
