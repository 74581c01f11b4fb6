"""The steps of shading one path vertex, as jitted helpers any path kernel can call.

tracer.integrator.shade strings them together for the unidirectional path tracer; a second
kernel (e.g. the gradient-domain tracer's offset paths) calls the same ones, so NEE, MIS and the
guide mixture exist once:

    emitted_surface / emitted_env   emission found by a path, with its MIS weight against NEE
    next_event                      next-event estimation: light sample, BSDF, MIS weight, shadow ray
    sample_mixture / mixture_pdf    the direction from the one-sample MIS mixture of BSDF and guide
                                    (practical path guiding's sampleMat / pdfMat), and its density
    survival, russian_roulette      continue or end, on the throughput BSDF sampling would have had
    next_bounce                     the two together, with their random numbers: a path's next step

Conventions: `table` is the scene's COATED tables (material.Surfaces.mat_table, tracer.bsdfs);
directions are unit 3-tuples; `wo`, `wi` in the local shading frame (s, t, ns) of
the point's tracer.material.Surface `sf` unless named `*w` (world); `ng` is the true (geometric)
normal, `cos_o` the world wo's cosine with it (sides, ray offsets and the light-leak test
material.crosses); densities are per unit solid angle; colours are RGB 3-tuples. `a` is the probability of BSDF sampling in the mixture p = a p_bsdf + (1 - a) p_guide
(1: no guide at this vertex), `slot` the guide's sampling map there (tracer.guiding.contract.locate).
"""
import math
from typing import NamedTuple

import numpy as np

from . import bsdfs
from ._jit import jit
from .guiding.contract import slot_pdf, slot_sample
from .material import crosses
from .lights import (DELTA_DIRECTIONAL, LIGHT_ENV, delta_light_of, env_pdf, env_radiance, sample_light,
                     triangle_emission, triangle_light_pdf)
from .rng import DIR, LOBE, RR, STRATEGY, bounce_dim, draw
from .sampling import dot, power_heuristic, to_local, to_world

BLACK = (0.0, 0.0, 0.0)


class LightSample(NamedTuple):
    """What light_sample_at returns: NEE's shadow ray and value, and the light sample itself."""

    ok: bool  # a shadow ray to trace
    origin: tuple  # its origin, unit direction and length
    direction: tuple
    tmax: float
    contrib: tuple  # what it adds if unblocked: beta f le w / pl (RGB)
    wl: tuple  # unit world direction to the light sample
    dist: float  # its distance (inf: the environment)
    le: tuple  # its emitted radiance (RGB)
    pl: float  # its solid-angle density (0: no sample)
    tri: int  # its triangle (-1: the environment)
    f: tuple  # f |cos| toward it (RGB)
    pdf: float  # the mixture density of wl


@jit
def offset_point(x, ng, w, eps):
    """x pushed off the surface by eps along the normal ng, to the side direction w leaves on (eps:
    the triangle's entry of tracer.bvh.ray_offsets)."""
    s = eps if dot(w, ng) >= 0.0 else -eps
    return (x[0] + s * ng[0], x[1] + s * ng[1], x[2] + s * ng[2])


# A shadow ray to a point of a light ends this fraction of its length short of it (pbrt-v4's
# ShadowEpsilon). The light's own offset (ray_offsets) covers the rounding of its triangle, not
# Embree's float32 distance along a long ray, which errs by more: 1000 units from a small light, the
# ray hit the light itself (a 2000-unit floor lit at grazing angles in veach-mis came out 20% dark).
SHADOW_EPSILON = 1e-4


@jit(inline="always")
def shadow_ray(x, ng, eps, wl, dist, lt, lt_tri, tri_eps):
    """(origin, unit direction, tmax) of the shadow ray from x (normal ng, offset eps) toward the
    light sample at distance dist along wl, on triangle lt_tri (lights.LIGHT_ENV or a directional
    light: at infinity, tmax inf; a point or spot light: tmax the distance to it from the offset
    origin).
    Both ends are offset by their own triangle's ray_offsets, the light's end along its normal
    toward x (pbrt-v4's SpawnRayTo), and tmax is SHADOW_EPSILON of the length short of that end, so
    the ray stops short of the light's plane as Embree sees it. tmax <= 0 means there is no room
    for a ray (x on the light)."""
    o = offset_point(x, ng, wl, eps)
    y = (x[0] + dist * wl[0], x[1] + dist * wl[1], x[2] + dist * wl[2])  # a point or spot light
    if lt_tri >= 0:
        li = lt.light_of_tri[lt_tri]
        el = tri_eps[lt_tri]
        y = (y[0] + el * lt.normal[li, 0], y[1] + el * lt.normal[li, 1], y[2] + el * lt.normal[li, 2])
    elif lt_tri == LIGHT_ENV or lt.delta_kind[delta_light_of(lt_tri)] == DELTA_DIRECTIONAL:
        return o, wl, np.inf
    d = (y[0] - o[0], y[1] - o[1], y[2] - o[2])
    tmax = math.sqrt(dot(d, d))
    if not tmax > 0.0:
        return o, wl, 0.0
    inv = 1.0 / tmax
    return o, (d[0] * inv, d[1] * inv, d[2] * inv), tmax * (1.0 - SHADOW_EPSILON)


@jit(inline="always")
def emitted_env(lt, wray, depth, prev_pdf, prev_delta):
    """(radiance, MIS weight) of the environment (lt.env_type != ENV_NONE) seen along wray (world)
    by a path that escaped after `depth` bounces; its last direction had solid-angle density
    prev_pdf (prev_delta: from a delta lobe, or the camera at depth 0: weight 1)."""
    le = env_radiance(lt, wray)
    w = 1.0
    if depth > 0 and not prev_delta:
        w = power_heuristic(prev_pdf, env_pdf(lt, wray))
    return le, w


@jit(inline="always")
def emitted_surface(lt, p, dist2, cos_o, depth, prev_pdf, prev_delta):
    """(radiance, MIS weight) emitted by light triangle p (lt.light_of_tri[p] >= 0) toward a path
    arriving at squared distance dist2 with cos_o the cosine to its normal (> 0 on the emitting
    side); weights as emitted_env."""
    le = triangle_emission(lt, p, cos_o)
    w = 1.0
    if depth > 0 and not prev_delta:
        w = power_heuristic(prev_pdf, triangle_light_pdf(lt, p, dist2, cos_o))
    return le, w


@jit(inline="always")
def write_aovs(sf, i, depth, cos_o, dist, aov, aov_open):
    """The AOVs of path i at a vertex whose Surface is sf (its depth-th bounce, arrived at distance
    dist with cos_o to the geometric normal): shading normal facing the camera and distance at the
    first hit; albedo (textured) at the first vertex that is not a delta BSDF (until then, the delta
    BSDF's own). Returns whether the BSDF there is a delta BSDF."""
    delta = bsdfs.bsdf_is_delta(sf.bp)
    if depth == 0:
        sgn = 1.0 if cos_o >= 0.0 else -1.0
        for c in range(3):
            aov[i, 3 + c] = sgn * sf.ns[c]
        aov[i, 6] = dist
    if aov_open[i]:
        al = bsdfs.bsdf_albedo(sf.bp)
        for c in range(3):
            aov[i, c] = al[c]
        aov_open[i] = delta
    return delta


@jit(inline="always")
def write_shadow(k, so, sd, tmax, contrib, sh_o, sh_d, sh_tmax, sh_L, has_shadow):
    """Store entry k's shadow ray (origin, unit direction, tmax) and the value it adds if unblocked."""
    for c in range(3):
        sh_o[k, c] = so[c]
        sh_d[k, c] = sd[c]
        sh_L[k, c] = contrib[c]
    sh_tmax[k] = tmax
    has_shadow[k] = True


@jit(inline="always")
def mixture_pdf(gs, slot, a, pb, wiw):
    """Density of world direction wiw under the mixture a p_bsdf + (1 - a) p_guide, given the
    BSDF's own density pb of it (pdfMat); pb where a is 1."""
    if a < 1.0:
        return a * pb + (1.0 - a) * slot_pdf(gs, slot, wiw)
    return pb


@jit(inline="always")
def next_event(sf, lt, tri, x, ng, cos_o, wo, beta, gs, slot, a, eps, tri_eps, u, table):
    """Next-event estimation at a non-delta vertex x (Surface sf, geometric normal ng, outgoing wo
    local), path throughput beta: one light sample (u = (u_light, u_pos0, u_pos1)), MIS-weighted by
    the power heuristic against the mixture density of the same direction. Returns (ok, origin,
    unit direction, tmax, contribution beta f le w / p_light): the shadow ray to trace, and what it
    adds if unblocked. ok is False where nothing is to be traced."""
    ls = light_sample_at(sf, lt, tri, x, ng, cos_o, wo, beta, gs, slot, a, eps, tri_eps, u, table)
    return ls.ok, ls.origin, ls.direction, ls.tmax, ls.contrib


@jit(inline="always")
def light_sample_at(sf, lt, tri, x, ng, cos_o, wo, beta, gs, slot, a, eps, tri_eps, u, table):
    """next_event with the light sample itself, as a LightSample. The gradient-domain tracer shifts
    this sample to its offset paths. A delta light's sample (lt_tri < lights.LIGHT_ENV) has MIS weight 1
    and mixture density 0: no direction the path samples reaches it."""
    wl, dist, le, pl, lt_tri = sample_light(lt, tri, x, u[0], u[1], u[2])
    ok = False
    so = x
    sd = wl
    tmax = 0.0
    contrib = BLACK
    f = BLACK
    pb = 0.0
    if pl > 0.0 and (le[0] > 0.0 or le[1] > 0.0 or le[2] > 0.0):
        wil = to_local(wl, sf.s, sf.t, sf.ns)
        f, pbs = bsdfs.bsdf_eval_pdf(sf.bp, wo, wil, True, table)
        if crosses(sf, cos_o, ng, wo, wil, wl):
            f = BLACK
        pb = mixture_pdf(gs, slot, a, pbs, wl) if lt_tri >= LIGHT_ENV else 0.0
        if f[0] > 0.0 or f[1] > 0.0 or f[2] > 0.0:
            w = power_heuristic(pl, pb)
            so, sd, tmax = shadow_ray(x, ng, eps, wl, dist, lt, lt_tri, tri_eps)
            if tmax > 0.0:
                ok = True
                contrib = (beta[0] * f[0] * le[0] * w / pl, beta[1] * f[1] * le[1] * w / pl,
                           beta[2] * f[2] * le[2] * w / pl)
    return LightSample(ok, so, sd, tmax, contrib, wl, dist, le, pl, lt_tri, f, pb)


@jit(inline="always")
def guided_weight(f, pbs, pg, a):
    """A direction drawn from the guide's map (its density pg) as a sample of the mixture with
    probability a of the BSDF (f cos and density pbs of that direction): (f cos / pdf, the
    mixture's pdf, p_bsdf / pdf); a zero weight and ratio 1 where pdf is 0."""
    pdf = a * pbs + (1.0 - a) * pg
    wt = BLACK
    ratio = 1.0
    if pdf > 0.0:
        inv = 1.0 / pdf
        wt = (f[0] * inv, f[1] * inv, f[2] * inv)
        ratio = pbs * inv
    return wt, pdf, ratio


@jit(inline="always")
def bsdf_in_mixture(gs, slot, a, wiw, wt, pdf, dlt):
    """A direction wiw the BSDF sampled (weight wt, density pdf, dlt: from a delta lobe) as a sample
    of the mixture with map `slot`: (its weight, the mixture's density, p_bsdf / p_mixture), as
    given (ratio 1) where a is 1 or pdf 0. A delta lobe (of a material that also has a smooth one)
    is chosen with probability a x its own; the guide never produces its direction."""
    ratio = 1.0
    if a < 1.0 and pdf > 0.0:
        pm = a * pdf if dlt else mixture_pdf(gs, slot, a, pdf, wiw)
        ratio = pdf / pm
        wt = (wt[0] * ratio, wt[1] * ratio, wt[2] * ratio)
        pdf = pm
    return wt, pdf, ratio


@jit(inline="always")
def sample_mixture(sf, gs, slot, a, wo, ng, cos_o, u0, u1, u_lobe, u_strategy, table):
    """Sample the continuation from the mixture (sampleMat): the guide's map `slot` with probability
    1 - a (u_strategy >= a), else the BSDF (u_lobe picks its lobe); u0, u1 the direction.
    Returns (wiw world direction, weight f cos / pdf (RGB), pdf of the mixture, p_bsdf of wiw, delta
    (sampled a delta lobe: pdf is then the probability of picking it, a x the lobe's), strategy 0
    BSDF / 1 guide, ratio p_bsdf / pdf (1 without a guide))."""
    if a < 1.0 and u_strategy >= a:
        wiw, pg = slot_sample(gs, slot, u0, u1)
        wi = to_local(wiw, sf.s, sf.t, sf.ns)
        f, pbs = bsdfs.bsdf_eval_pdf(sf.bp, wo, wi, True, table)
        if crosses(sf, cos_o, ng, wo, wi, wiw):
            f = BLACK
        wt, pdf, ratio = guided_weight(f, pbs, pg, a)
        return wiw, wt, pdf, pbs, False, 1, ratio
    wi, wt, pdf, dlt = bsdfs.bsdf_sample(sf.bp, wo, u0, u1, u_lobe, True, table)
    wiw = to_world(wi, sf.s, sf.t, sf.ns)
    if crosses(sf, cos_o, ng, wo, wi, wiw):
        wt = BLACK
    pbs = pdf
    wt, pdf, ratio = bsdf_in_mixture(gs, slot, a, wiw, wt, pdf, dlt)
    return wiw, wt, pdf, pbs, dlt, 0, ratio


@jit(inline="always")
def survival(beta, gain, gs):
    """The roulette's survival probability for throughput beta and gain: clamp(max(beta) / gain,
    gs.rr_min, gs.rr_max) (by default min(max(beta) / gain, 0.95)). beta / gain is the throughput
    BSDF sampling would have had: on beta itself the roulette would undo a guide, since a guided
    direction's small weight f cos / p would be raised back to ~1 by a matching chance of death (a
    path's survival density ~ f cos)."""
    bmax = max(beta[0], max(beta[1], beta[2]))
    return min(max(bmax / gain, gs.rr_min), gs.rr_max)


@jit(inline="always")
def russian_roulette(beta, gain, u, gs):
    """Continue with probability q = survival(beta, gain, gs), deciding by u: (survives, beta / q, q)."""
    q = survival(beta, gain, gs)
    if u >= q:
        return False, beta, q
    return True, (beta[0] / q, beta[1] / q, beta[2] / q), q


class NextBounce(NamedTuple):
    """What next_bounce returns."""

    ok: bool  # the path goes on
    wi: tuple  # the sampled world direction
    weight: tuple  # f cos / pdf (RGB)
    pdf: float  # the mixture's density of wi (a delta lobe's probability)
    pdf_bsdf: float  # the BSDF's own density of wi
    delta: bool  # sampled from a delta lobe
    strategy: int  # 0 BSDF, 1 guide
    beta: tuple  # the throughput after the bounce and the roulette
    gain: float  # product of p_bsdf / p_mixture along the path (1 without a guide)
    q: float  # the roulette's survival probability (1: no roulette)
    beta_pre: tuple  # the throughput after the bounce, before the roulette


@jit(inline="always")
def next_bounce(sf, gs, slot, a, wo, ng, cos_o, beta, gain, depth, rr_depth, max_bounces, ps, key, row, table):
    """A path's next step at a vertex with Surface sf (geometric normal ng, cos_o; outgoing wo local) after
    `depth` bounces, with throughput beta and gain so far: the direction from the mixture of the
    guide's map `slot` (probability 1 - a) and the BSDF, its random numbers drawn for path `row`
    of stream `key` (rng.draw: STRATEGY where a < 1, LOBE where the BSDF samples, DIR, DIR + 1),
    then Russian roulette from rr_depth on (RR; not here where gs.rr_late: the path tracer draws it
    at the next vertex) and the cap max_bounces. A NextBounce."""
    u_strategy = draw(ps, key, row, bounce_dim(depth, STRATEGY)) if a < 1.0 else 1.0
    u_lobe = 0.0 if a < 1.0 and u_strategy >= a else draw(ps, key, row, bounce_dim(depth, LOBE))  # BSDF only
    wiw, wt, pdf, pbs, dlt, strategy, ratio = sample_mixture(
        sf, gs, slot, a, wo, ng, cos_o, draw(ps, key, row, bounce_dim(depth, DIR)),
        draw(ps, key, row, bounce_dim(depth, DIR + 1)), u_lobe, u_strategy, table)
    gn = gain * ratio
    nb = (beta[0] * wt[0], beta[1] * wt[1], beta[2] * wt[2])
    bmax = max(nb[0], max(nb[1], nb[2]))
    ok = bmax > 0.0 and math.isfinite(bmax)
    q = 1.0
    pre = nb
    if ok and depth + 1 >= rr_depth and gs.rr_late == 0:
        ok, nb, q = russian_roulette(nb, gn, draw(ps, key, row, bounce_dim(depth, RR)), gs)
    if depth + 1 >= max_bounces:
        ok = False
    return NextBounce(ok, wiw, wt, pdf, pbs, dlt, strategy, nb, gn, q, pre)
