"""A path's vertex shaded in float64, for every material, light and guide: `shade_vertex`.

The wavefront's `shade` (tracer.integrators.path), the per-thread loop (tracer.integrators.
thread_loop) and the lanes' general kernel (tracer.engine.general.shade_general) all shade a
vertex with it: emission with its MIS weight (and the light the camera sees, L_cam), the AOVs,
the NEE sample, the direction from the guide's mixture and the roulette, the path's state
updated in place. Its steps are the helpers of tracer.shading; its random numbers go through the
sample seam `rng.draw`.
"""
from typing import NamedTuple

from .._jit import jit
from ..guiding.contract import locate
from ..lights import ENV_NONE
from ..material import surface_at
from ..rng import LIGHT, LIGHT_POS, RR, bounce_dim, draw
from ..sampling import dot, to_local, triangle_point
from ..shading import emitted_env, emitted_surface, next_bounce, next_event, offset_point, survival, write_aovs

MAX_BOUNCES = 4096  # no path continues past this many bounces (max_depth -1: unlimited)


@jit(inline="always")
def add_emission(i, depth, b, le, w, L, L_cam):
    """Emission le with MIS weight w found by path i (throughput b) after `depth` bounces: added to
    its radiance, and at the first hit (depth 0) kept as the light the camera ray sees directly."""
    for c in range(3):
        L[i, c] += b[c] * le[c] * w
    if depth == 0:
        for c in range(3):
            L_cam[i, c] = b[c] * le[c] * w


class Vertex(NamedTuple):
    """What shade_vertex returns: the path's next ray, its shadow ray, and what a record needs."""

    alive: bool  # the path goes on along next_o, next_d
    next_o: tuple
    next_d: tuple
    shadow: bool  # a shadow ray from sh_o along unit sh_d up to sh_tmax adds sh_L if unblocked
    sh_o: tuple
    sh_d: tuple
    sh_tmax: float
    sh_L: tuple
    found: bool  # emission le (MIS weight w) was found by a path of throughput b along a direction of density pdf
    le: tuple
    w: float
    b: tuple
    pdf: float
    sampled: bool  # a continuation was sampled (or the path ended by it): the vertex's record closes
    recorded: bool  # ... and the vertex is recorded (not delta, a density): the fields below
    x: tuple
    nf: tuple  # normal on the side the path arrived
    wi: tuple
    strategy: int
    node: int
    pdf_mix: float
    pdf_bsdf: float
    fcos: float  # luminance of |f cos|
    beta: tuple  # the record's throughput after the vertex: before the roulette with gs.rec_q, else after it (0 where the path ended)


@jit(inline="always")
def shade_vertex(hit, surf, lt, gs, ps, lim, beta, L, L_cam, depth, prev_pdf, prev_delta, gain, stream, aov,
                 aov_open):
    """Shade the vertex of path slot i that its ray (direction wray) hit at distance tk, on triangle
    p (< 0: escaped) at barycentrics u1, u2, given as hit = (i, wray's x, y, z, tk, p, u1, u2): emission
    (added to L, and L_cam at the first hit), AOVs, the NEE sample, the continuation from the
    mixture and the roulette (the path state of slot i updated). lim = (max_depth, rr_depth, nee);
    stream = (key, pix), the paths' random keys and pixels (read only). Returns a Vertex: the next
    ray and shadow ray to trace, and what a record of the vertex takes. The other arguments as the
    wavefront's `shade` (tracer.integrators.path); the callers are that `shade`, the per-thread
    loop of tracer.integrators.thread_loop and the lanes' general kernel
    (engine.general.shade_general). Scalars travel in tuples, and the arrays the vertex writes one
    by one: arrays written through a tuple lose Numba's writes (tests/test_seams.py)."""
    i = hit[0]
    wray = (hit[1], hit[2], hit[3])
    tk = hit[4]
    p = hit[5]
    u1 = hit[6]
    u2 = hit[7]
    max_depth = lim[0]
    rr_depth = lim[1]
    nee = lim[2]
    key = stream[0]
    pix = stream[1]
    alive = False
    no = wray
    shadow = False
    so = wray
    sd = wray
    tmax = 0.0
    contrib = (0.0, 0.0, 0.0)
    found = False
    le = contrib
    w = 0.0
    pdf_in = prev_pdf[i]
    sampled = False
    recorded = False
    x = wray
    nf = wray
    wiw = wray
    strategy = -1
    node = -1
    pdf = 0.0
    pbs = 0.0
    fcos = 0.0
    nb = contrib
    dk = depth[i]                                   # bounces so far (0 at the first hit)
    b = (beta[i, 0], beta[i, 1], beta[i, 2])        # throughput up to this vertex
    b_in = b  # ... as the emission found here counts it (b / q after a late roulette)
    if dk == 0:
        for c in range(3):
            L_cam[i, c] = 0.0
    if p < 0:
        # Escaped: environment light, MIS-weighted against NEE's choice of it
        if lt.env_type != ENV_NONE:
            le, w = emitted_env(lt, wray, dk, prev_pdf[i], prev_delta[i] or not nee)
            found = True
            add_emission(i, dk, b, le, w, L, L_cam)
    else:
        # Hit point (from barycentrics: on the triangle's plane) and geometric normal
        x = triangle_point(surf.tri, p, u1, u2)
        ng = (surf.normal[p, 0], surf.normal[p, 1], surf.normal[p, 2])  # unit, counter-clockwise side
        cos_o = -dot(wray, ng)  # > 0 when the path arrived on the counter-clockwise side
        # Emission, MIS-weighted against NEE's choice of this triangle
        if lt.light_of_tri[p] >= 0:
            le, w = emitted_surface(lt, p, tk * tk, cos_o, dk, prev_pdf[i], prev_delta[i] or not nee)
            found = True
            add_emission(i, dk, b, le, w, L, L_cam)
        sf = surface_at(surf, p, u1, u2)  # the BSDF there, textures evaluated, and its frame
        delta = write_aovs(sf, i, dk, cos_o, tk, aov, aov_open)
        kk = key[i]  # the path's random stream
        # Continue past this vertex? With gs.rr_late, the roulette of the bounce that arrived here
        # is drawn now, after its emission was counted (never after a delta bounce)
        go = not (max_depth >= 0 and dk + 1 >= max_depth)
        if go and gs.rr_late != 0 and dk >= rr_depth and not prev_delta[i]:
            q = survival(b, gain[i], gs)
            if draw(ps, kk, i, bounce_dim(dk - 1, RR)) >= q:
                go = False
            else:
                b = (b[0] / q, b[1] / q, b[2] / q)
                for c in range(3):
                    beta[i, c] = b[c]
        if go:
            wo = to_local((-wray[0], -wray[1], -wray[2]), sf.s, sf.t, sf.ns)

            # Where the guide's map is (node, slot) and the mixing weight a (probability of BSDF sampling)
            slot = -1
            a = 1.0
            nf = ng if cos_o >= 0.0 else (-ng[0], -ng[1], -ng[2])
            if not delta and (gs.res[0] > 0 or gs.pixel_slot.shape[0] > 0):
                node, slot, a = locate(gs, x, nf, pix[i], dk)

            # Next-event estimation (not at delta BSDFs)
            if nee and not delta:
                shadow, so, sd, tmax, contrib = next_event(
                    sf, lt, surf.tri, x, ng, cos_o, wo, b, gs, slot, a, surf.eps[p],
                    surf.eps, (draw(ps, kk, i, bounce_dim(dk, LIGHT)), draw(ps, kk, i, bounce_dim(dk, LIGHT_POS)),
                               draw(ps, kk, i, bounce_dim(dk, LIGHT_POS + 1))), surf.mat_table)

            # The continuation from the mixture (the guide with probability 1 - a, else the BSDF), then
            # possibly the end of the path by Russian roulette
            nx = next_bounce(sf, gs, slot, a, wo, ng, cos_o, b, gain[i], dk, rr_depth, MAX_BOUNCES, ps, kk, i,
                             surf.mat_table)
            sampled = True
            wiw, pdf, pbs, strategy = nx.wi, nx.pdf, nx.pdf_bsdf, nx.strategy
            recorded = not delta and not nx.delta and pdf > 0.0
            wt = nx.weight
            fcos = (0.2126 * wt[0] + 0.7152 * wt[1] + 0.0722 * wt[2]) * pdf
            if gs.rec_q != 0:
                nb = nx.beta_pre  # the record's radiance is then X / q, unbiased for L_i
            if nx.ok:
                if gs.rec_q == 0:
                    nb = nx.beta
                alive = True
                no = offset_point(x, ng, wiw, surf.eps[p])
                for c in range(3):
                    beta[i, c] = nx.beta[c]
                depth[i] = dk + 1
                prev_pdf[i] = pdf
                prev_delta[i] = nx.delta
                gain[i] = nx.gain
    return Vertex(alive, no, wiw, shadow, so, sd, tmax, contrib, found, le, w, b_in, pdf_in, sampled, recorded,
                  x, nf, wiw, strategy, node, pdf, pbs, fcos, nb)


