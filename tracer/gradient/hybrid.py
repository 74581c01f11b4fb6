"""Gradient-domain path tracing with the hybrid shift (Kettunen et al. 2015; the details as in their
public implementation, gradient-domain Mitsuba 0.5).

Every sample of pixel p is a base path, the path tracer's own (the same random numbers, NEE and
MIS: its value is the path tracer's sample), and four offset paths, one per neighbour p + e
(e = +-x, +-y), that step with it:

- At the camera the offset ray goes through p + e at the same position inside the pixel.
- At each bounce from base vertex x_i to x_{i+1}, an offset at y_i
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

Weights. Each pair (p, p + e) is estimated from both sides; each estimate is weighted by the power
heuristic over four techniques: the base's light and BSDF sampling and the neighbour's (the offset
path's densities times the Jacobian). Path state keeps beta = F / P_b (F the product of f |cos|,
P_b the base's density) for the base and beta_o = F_o J_o / P_b for the offset, and the ratio
R = J_o P_o / P_b, so no product of densities is ever formed (it would overflow in long glossy
paths). With light density pL and BSDF density pB of the last vertex, an NEE sample adds

    w (beta_o J_L f_o Le_o - beta f Le) / pL,   w = pL^2 / (pL^2 + pB^2 + (R J_L)^2 (pL_o^2 + pB_o^2)),

and an emitter found by a BSDF sample (R, beta after the bounce)

    (beta_o Le_o - beta Le) / (1 + (pL / pB)^2 + R^2 (1 + (pL_o / pB_o)^2)).

A failed offset leaves the base its ordinary two-technique weight, and a gradient of minus the
base's weighted value. Russian roulette is the base's; a survivor divides beta and beta_o by q.
Light seen directly from the camera goes to the direct buffer (L_cam), not into the gradients.
"""
import math
import time as _time

import numpy as np
from numba import prange

from .. import bsdfs
from .._jit import jit, kernel
from ..camera import camera_ray
from ..integrator import MAX_BOUNCES
from ..lights import ENV_NONE, env_pdf, env_radiance, triangle_emission, triangle_light_pdf
from ..rng import DIM_PIXEL, DIR, LIGHT, LIGHT_POS, LOBE, RR, bounce_dim, draw, no_primary_samples
from ..sampling import dot, frame, to_local, to_world, triangle_point
from ..shading import emitted_env, emitted_surface, light_sample_at, offset_point, russian_roulette, sample_mixture
from ..shading import shadow_ray, write_aovs, write_shadow
from ..sources import CameraSource
from ..wave import sanitize

# offset status: own vertex; reconnected one bounce ago; the base's vertices; reconnected through an
# occluder (a failed shift that still enters the weights of the emission at the base's vertex)
TRACED, RECENT, CONNECTED, BLOCKED = 0, 1, 2, 3


class HybridBuffers:
    """The offset paths' state for a wave of `size` base paths (4 offsets each, in the order of
    replay.OFFSETS), and the base's last bounce, which the shift copies."""

    def __init__(self, size):
        z = lambda *s, d=np.float64: np.zeros((size,) + s, d)  # noqa: E731
        self.b_x, self.b_wo, self.b_wt = z(3), z(3), z(3)
        self.b_prim = z(d=np.int64)
        self.b_pdf = z()
        self.b_delta, self.b_rough = z(d=np.bool_), z(d=np.bool_)
        # NEE terms, weighted once the shadow rays are known: the base's value, light and BSDF
        # densities; per offset a mode (0 no term, 1 the base alone, 2 the base's shadow ray,
        # 3 its own), value, R J_L, light and BSDF densities, and the visibility of its own ray
        self.n_cn, self.n_pl, self.n_pb, self.vis_b = z(3), z(), z(), z(d=np.bool_)
        self.n_mode = z(4, d=np.int8)
        self.n_co, self.n_rj, self.n_plo, self.n_pbo, self.vis = z(4, 3), z(4), z(4), z(4), z(4, d=np.bool_)
        self.G = z(4, 3)  # per path and offset: the weighted gradient I(p + e) - I(p) found so far
        self.alive, self.rough, self.hv = z(4, d=np.bool_), z(4, d=np.bool_), z(4, d=np.bool_)
        self.lights = z(4, d=np.bool_)  # the pair's last bounce counts the light techniques (not a copy)
        self.trace, self.reconn, self.sh = z(4, d=np.bool_), z(4, d=np.bool_), z(4, d=np.bool_)
        self.status, self.prim = z(4, d=np.int8), z(4, d=np.int64)
        self.beta, self.x, self.wo = z(4, 3), z(4, 3), z(4, 3)
        self.R, self.pdf, self.dist2 = z(4), z(4), z(4)
        self.delta = z(4, d=np.bool_)
        self.ray_o, self.ray_d, self.tmax = z(4, 3), z(4, 3), z(4)
        self.hit_t, self.hit_b1, self.hit_b2 = z(4), z(4), z(4)
        self.hit_prim = z(4, d=np.int64)
        self.sh_o, self.sh_d, self.sh_tmax = z(4, 3), z(4, 3), z(4)

    @staticmethod
    def bytes_for(size):
        """Bytes that HybridBuffers(size) allocates."""
        return sum(a.nbytes for a in vars(HybridBuffers(1)).values() if isinstance(a, np.ndarray)) * size

    def offset_state(self):
        """The offset arrays in the order the kernels take them."""
        return (self.alive, self.status, self.beta, self.R, self.x, self.prim, self.wo, self.pdf, self.delta,
                self.dist2, self.rough, self.hv, self.lights, self.trace, self.reconn, self.ray_o, self.ray_d,
                self.tmax)


@jit(inline="always")
def _offset(o):
    """(dx, dy) of offset o: +x, -x, +y, -y."""
    if o == 0:
        return 1, 0
    if o == 1:
        return -1, 0
    if o == 2:
        return 0, 1
    return 0, -1


@kernel
def start_offsets(cam, width, height, crop, jitter, ps, key, pix, o_ray_o, o_ray_d, o_alive, o_status, o_beta, o_R,
                  o_wo, o_hv, o_trace, o_reconn, G):
    """Offset camera rays of base paths 0 .. n-1 (keys and film pixels from the camera source):
    through the neighbouring pixel at the base's position inside its pixel."""
    cw = crop[2]
    for i in prange(key.shape[0]):
        px = crop[0] + pix[i] % cw
        py = crop[1] + pix[i] // cw
        jx = draw(ps, key[i], i, DIM_PIXEL) if jitter else 0.5
        jy = draw(ps, key[i], i, DIM_PIXEL + 1) if jitter else 0.5
        for o in range(4):
            dx, dy = _offset(o)
            org, d = camera_ray(cam, width, height, px + dx, py + dy, jx, jy)
            for c in range(3):
                o_ray_o[i, o, c] = org[c]
                o_ray_d[i, o, c] = d[c]
                o_wo[i, o, c] = -d[c]
                o_beta[i, o, c] = 1.0
                G[i, o, c] = 0.0
            o_alive[i, o] = True
            o_status[i, o] = TRACED
            o_R[i, o] = 1.0
            o_hv[i, o] = False
            o_trace[i, o] = True
            o_reconn[i, o] = False


@jit(inline="always")
def _finite(o_beta, o_R, i, o):
    """beta_o and R of offset o of path i are finite (a failed shift where they overflow)."""
    return (math.isfinite(o_R[i, o]) and math.isfinite(o_beta[i, o, 0]) and math.isfinite(o_beta[i, o, 1])
            and math.isfinite(o_beta[i, o, 2]))


@jit(inline="always")
def _is_rough(mat_type, mat_param, m, roughness):
    return bsdfs.bsdf_roughness(mat_type, mat_param, m) > roughness


@jit(inline="always")
def reconnection(x, y, z, nz):
    """Reconnect a path from y to the point z (normal nz) that the base reached from x: (unit
    direction y -> z, distance, Jacobian d omega_y / d omega_x = |cos_y| d(x, z)^2 / (|cos_x|
    d(y, z)^2), both cosines at nz). Jacobian 0 where it is undefined (z at y, or either segment
    grazing z's plane)."""
    d = (z[0] - y[0], z[1] - y[1], z[2] - y[2])
    d2 = dot(d, d)
    db = (z[0] - x[0], z[1] - x[1], z[2] - x[2])
    db2 = dot(db, db)
    if not (d2 > 0.0 and db2 > 0.0):
        return (0.0, 0.0, 1.0), 0.0, 0.0
    dist = math.sqrt(d2)
    w = (d[0] / dist, d[1] / dist, d[2] / dist)
    cos_x = abs(dot(db, nz)) / math.sqrt(db2)
    cos_y = abs(dot(w, nz))
    if not (cos_x > 0.0 and cos_y > 0.0):
        return w, dist, 0.0
    return w, dist, cos_y * db2 / (cos_x * d2)


@jit(inline="always")
def half_vector_shift(mat_type, mat_param, mx, my, wo_b, wi_b, wo_o, delta):
    """The direction of the offset at y (material my, incoming wo_o, local) that copies the base's
    bounce at x (material mx, wo_b -> wi_b, local; delta: from a delta lobe). Returns (ok, wi_o,
    f |cos| (discrete value for a delta lobe), density, Jacobian d wi_o / d wi_b). It fails (ok False)
    where the offset would change lobe: reflect where the base refracted or the reverse, a delta lobe
    where the base's was not or the reverse, total internal reflection."""
    zero = (0.0, 0.0, 0.0)
    transmit = wo_b[2] * wi_b[2] < 0.0
    if delta:
        wi, val, prob = bsdfs.delta_lobe(mat_type, mat_param, my, wo_o, transmit, True)
        return prob > 0.0, wi, val, prob, 1.0
    if bsdfs.bsdf_is_delta(mat_type, mat_param, my):
        return False, zero, zero, 0.0, 0.0
    if not transmit:
        hb = (wo_b[0] + wi_b[0], wo_b[1] + wi_b[1], wo_b[2] + wi_b[2])
        et_b = 1.0
        et_o = 1.0
    else:
        if mat_type[mx] != bsdfs.ROUGH_DIELECTRIC or mat_type[my] != bsdfs.ROUGH_DIELECTRIC:
            return False, zero, zero, 0.0, 0.0
        ior = mat_param[mx, 7]
        ei_b, et_b = (1.0, ior) if wo_b[2] > 0.0 else (ior, 1.0)
        hb = (-(ei_b * wo_b[0] + et_b * wi_b[0]), -(ei_b * wo_b[1] + et_b * wi_b[1]),
              -(ei_b * wo_b[2] + et_b * wi_b[2]))
    hb2 = dot(hb, hb)
    if not hb2 > 0.0:
        return False, zero, zero, 0.0, 0.0
    inv = 1.0 / math.sqrt(hb2)
    h = (hb[0] * inv, hb[1] * inv, hb[2] * inv)
    c = dot(wo_o, h)
    if not transmit:
        wi = (2.0 * c * h[0] - wo_o[0], 2.0 * c * h[1] - wo_o[1], 2.0 * c * h[2] - wo_o[2])
        ho = (wo_o[0] + wi[0], wo_o[1] + wi[1], wo_o[2] + wi[2])
    else:
        ior = mat_param[my, 7]
        ei_o, et_o = (1.0, ior) if wo_o[2] > 0.0 else (ior, 1.0)
        hh = h if c >= 0.0 else (-h[0], -h[1], -h[2])
        c = abs(c)
        eta = ei_o / et_o
        sin2 = eta * eta * (1.0 - c * c)
        if sin2 >= 1.0:  # total internal reflection: the shift fails
            return False, zero, zero, 0.0, 0.0
        ct = math.sqrt(1.0 - sin2)
        k = eta * c - ct
        wi = (-eta * wo_o[0] + k * hh[0], -eta * wo_o[1] + k * hh[1], -eta * wo_o[2] + k * hh[2])
        ho = (-(ei_o * wo_o[0] + et_o * wi[0]), -(ei_o * wo_o[1] + et_o * wi[1]), -(ei_o * wo_o[2] + et_o * wi[2]))
    den = et_o * et_o * abs(dot(wi, h)) * hb2
    if not den > 0.0 or (wo_o[2] * wi[2] < 0.0) != transmit:  # the offset's lobe must be the base's
        return False, zero, zero, 0.0, 0.0
    jac = et_b * et_b * abs(dot(wi_b, h)) * dot(ho, ho) / den
    f = bsdfs.bsdf_eval(mat_type, mat_param, my, wo_o, wi, True)
    pdf = bsdfs.bsdf_pdf(mat_type, mat_param, my, wo_o, wi)
    return pdf > 0.0 and math.isfinite(jac), wi, f, pdf, jac


@kernel
def shift_offsets(active, t, prim, b1, b2, ray_d, tri, tri_normal, tri_material, tri_eps, mat_type, mat_param, roughness,
                  b_x, b_prim, b_wo, b_wt, b_pdf, b_delta, b_rough,
                  o_alive, o_status, o_beta, o_R, o_x, o_prim, o_wo, o_pdf, o_delta, o_dist2, o_rough, o_hv, o_lights,
                  o_trace, o_reconn, o_ray_o, o_ray_d, o_tmax):
    """Shift each offset across the base's last bounce x_i -> x_{i+1} (entry k: path active[k], its
    ray ray_d[k] and hit t, prim): reconnection (a visibility ray to test, o_reconn) or half-vector
    copy (a ray to trace, o_trace); updates beta_o, R, and the offset's last density. o_lights: whether
    the pair's weights for this bounce count the light techniques (not after a half-vector copy, whose
    pairs take no NEE either: NEE reconnects, and both techniques must map a path to the same partner)."""
    for k in prange(active.shape[0]):
        i = active[k]
        p1 = prim[k]
        rough1 = True  # the environment counts as rough
        x1 = (0.0, 0.0, 0.0)
        if p1 >= 0:
            rough1 = _is_rough(mat_type, mat_param, tri_material[p1], roughness)
            x1 = triangle_point(tri, p1, b1[k], b2[k])
        wib_w = (ray_d[k, 0], ray_d[k, 1], ray_d[k, 2])
        px = b_prim[i]
        mx = tri_material[px]
        ngx = (tri_normal[px, 0], tri_normal[px, 1], tri_normal[px, 2])
        sx, tx = frame(ngx)
        wi_b = to_local(wib_w, sx, tx, ngx)
        wo_b = to_local((b_wo[i, 0], b_wo[i, 1], b_wo[i, 2]), sx, tx, ngx)
        pb = b_pdf[i]
        for o in range(4):
            o_trace[i, o] = False
            o_reconn[i, o] = False
            o_lights[i, o] = True
            if not o_alive[i, o]:
                continue
            st = o_status[i, o]
            if st == CONNECTED:
                for c in range(3):
                    o_beta[i, o, c] *= b_wt[i, c]
                o_pdf[i, o] = pb
                o_delta[i, o] = b_delta[i]
                continue
            if st == RECENT:  # at x_i with its own incoming direction
                wo_o = to_local((o_wo[i, o, 0], o_wo[i, o, 1], o_wo[i, o, 2]), sx, tx, ngx)
                f = bsdfs.bsdf_eval(mat_type, mat_param, mx, wo_o, wi_b, True)
                po = bsdfs.bsdf_pdf(mat_type, mat_param, mx, wo_o, wi_b)
                if not po > 0.0:
                    o_alive[i, o] = False
                    continue
                for c in range(3):
                    o_beta[i, o, c] *= f[c] / pb
                o_R[i, o] *= po / pb
                o_pdf[i, o] = po
                o_delta[i, o] = False
                o_status[i, o] = CONNECTED
                continue
            py = o_prim[i, o]
            my = tri_material[py]
            y = (o_x[i, o, 0], o_x[i, o, 1], o_x[i, o, 2])
            ngy = (tri_normal[py, 0], tri_normal[py, 1], tri_normal[py, 2])
            sy, ty = frame(ngy)
            wo_o = to_local((o_wo[i, o, 0], o_wo[i, o, 1], o_wo[i, o, 2]), sy, ty, ngy)
            if b_rough[i] and o_rough[i, o] and rough1:
                # Reconnect y_i to x_{i+1} (or to the environment along the base's direction)
                jac = 1.0
                wn = wib_w
                d2 = 0.0
                n1 = (0.0, 0.0, 1.0)
                if p1 >= 0:
                    n1 = (tri_normal[p1, 0], tri_normal[p1, 1], tri_normal[p1, 2])
                    wn, dist, jac = reconnection((b_x[i, 0], b_x[i, 1], b_x[i, 2]), y, x1, n1)
                    if not jac > 0.0:
                        o_alive[i, o] = False
                        continue
                    d2 = dist * dist
                wi_o = to_local(wn, sy, ty, ngy)
                f = bsdfs.bsdf_eval(mat_type, mat_param, my, wo_o, wi_o, True)
                po = bsdfs.bsdf_pdf(mat_type, mat_param, my, wo_o, wi_o)
                if not (po > 0.0 and math.isfinite(jac)):
                    o_alive[i, o] = False
                    continue
                org = offset_point(y, ngy, wn, tri_eps[py])
                tmax = np.inf
                dr = wn
                if p1 >= 0:  # stop short of x_{i+1}: its end offset toward y_i
                    s1 = -tri_eps[p1] if dot(wn, n1) > 0.0 else tri_eps[p1]
                    e = (x1[0] + s1 * n1[0], x1[1] + s1 * n1[1], x1[2] + s1 * n1[2])
                    v = (e[0] - org[0], e[1] - org[1], e[2] - org[2])
                    tmax = math.sqrt(dot(v, v))
                    if not tmax > 0.0:
                        o_alive[i, o] = False
                        continue
                    dr = (v[0] / tmax, v[1] / tmax, v[2] / tmax)
                    for c in range(3):
                        o_x[i, o, c] = x1[c]
                for c in range(3):
                    o_beta[i, o, c] *= f[c] * jac / pb
                    o_ray_o[i, o, c] = org[c]
                    o_ray_d[i, o, c] = dr[c]
                    o_wo[i, o, c] = -wn[c]
                o_tmax[i, o] = tmax
                o_R[i, o] *= po * jac / pb
                o_pdf[i, o] = po
                o_delta[i, o] = False
                o_prim[i, o] = p1
                o_dist2[i, o] = d2
                o_status[i, o] = RECENT
                o_hv[i, o] = False
                o_reconn[i, o] = _finite(o_beta, o_R, i, o)
                o_alive[i, o] = o_reconn[i, o]
                continue
            # Half-vector copy (between vertices of the same class; a delta vertex and one that is not
            # have no partner either way, and keep the base's two techniques)
            o_lights[i, o] = b_delta[i] != bsdfs.bsdf_is_delta(mat_type, mat_param, my)
            ok, wi_o, f, po, jac = half_vector_shift(mat_type, mat_param, mx, my, wo_b, wi_b, wo_o, b_delta[i])
            if not ok:
                o_alive[i, o] = False
                continue
            wiw = to_world(wi_o, sy, ty, ngy)
            org = offset_point(y, ngy, wiw, tri_eps[py])
            for c in range(3):
                o_beta[i, o, c] *= f[c] * jac / pb
                o_ray_o[i, o, c] = org[c]
                o_ray_d[i, o, c] = wiw[c]
                o_wo[i, o, c] = -wiw[c]
            o_R[i, o] *= po * jac / pb
            o_pdf[i, o] = po
            o_delta[i, o] = b_delta[i]
            o_hv[i, o] = b_rough[i] and o_rough[i, o]
            o_trace[i, o] = True
            if not _finite(o_beta, o_R, i, o):
                o_alive[i, o] = False


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
def shade_hybrid(active, ray_d, t, prim, b1, b2, tri, tri_normal, tri_material, tri_eps, mat_type, mat_param, lt, gs,
                 ps, max_depth, rr_depth, roughness,
                 beta, L, L_cam, depth, prev_pdf, prev_delta, key, aov, aov_open,
                 alive, next_o, next_d, sh_o, sh_d, sh_tmax, sh_L, has_shadow,
                 b_x, b_prim, b_wo, b_wt, b_pdf, b_delta, b_rough, G,
                 o_alive, o_status, o_beta, o_R, o_x, o_prim, o_wo, o_pdf, o_delta, o_dist2, o_rough, o_hv, o_lights,
                 o_trace, hit_t, hit_prim, hit_b1, hit_b2, o_sh, o_sh_o, o_sh_d, o_sh_tmax,
                 n_cn, n_pl, n_pb, n_mode, n_co, n_rj, n_plo, n_pbo, vis):
    """One bounce of base and offset paths: the vertices the offsets reached, emission (the base's
    as the path tracer's, the gradients' with the pair weights), NEE shifted to the offsets, the
    base's direction and roulette. Entry k is path active[k]; the offsets' hits of traced rays are in
    hit_* (where o_trace). Shadow rays: the base's (has_shadow, sh_*: sh_L its value for L) and the
    offsets' own (o_sh, o_sh_*); the NEE terms n_* are weighted by add_next_event once they are
    traced."""
    for k in prange(active.shape[0]):
        i = active[k]
        alive[k] = False
        has_shadow[k] = False
        dk = depth[i]
        wray = (ray_d[k, 0], ray_d[k, 1], ray_d[k, 2])
        b = (beta[i, 0], beta[i, 1], beta[i, 2])
        p = prim[k]
        for o in range(4):
            o_sh[i, o] = False
            vis[i, o] = False
            n_mode[i, o] = 0
        if dk == 0:
            for c in range(3):
                L_cam[i, c] = 0.0
        x = (0.0, 0.0, 0.0)
        ng = (0.0, 0.0, 1.0)
        if p >= 0:
            x = triangle_point(tri, p, b1[k], b2[k])
            ng = (tri_normal[p, 0], tri_normal[p, 1], tri_normal[p, 2])

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
                    y = triangle_point(tri, q, hit_b1[i, o], hit_b2[i, o])
                    for c in range(3):
                        o_x[i, o, c] = y[c]
                # The reverse of a half-vector copy would reconnect here: not a bijection, fail
                if o_hv[i, o] and (q < 0 or _is_rough(mat_type, mat_param, tri_material[q], roughness)):
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
        for c in range(3):
            L[i, c] += cb[c] * w
            if dk == 0:
                L_cam[i, c] = cb[c] * w
        if dk > 0:
            rb = pl / prev_pdf[i]
            for o in range(4):
                if not o_alive[i, o]:  # the base's techniques alone: the path tracer's weight (BSDF's
                    wd = w if o_lights[i, o] else 1.0  # alone after a failed half-vector copy)
                    for c in range(3):
                        G[i, o, c] -= cb[c] * wd
                    continue
                leo, plo = _emitted_by(lt, tri_normal, o_prim[i, o], (o_wo[i, o, 0], o_wo[i, o, 1], o_wo[i, o, 2]),
                                       o_dist2[i, o], o_delta[i, o])
                ro = plo / o_pdf[i, o]
                R2 = o_R[i, o] * o_R[i, o]
                if o_status[i, o] == BLOCKED:  # no BSDF sample reaches x through the occluder: no light
                    den = 1.0 + rb * rb + R2 * ro * ro
                    leo = (0.0, 0.0, 0.0)
                elif o_lights[i, o]:
                    den = 1.0 + rb * rb + R2 * (1.0 + ro * ro)
                else:
                    den = 1.0 + R2
                for c in range(3):
                    G[i, o, c] += (o_beta[i, o, c] * leo[c] - cb[c]) / den
        for o in range(4):  # an offset that escaped, or was blocked, ends here
            if o_alive[i, o] and (o_prim[i, o] < 0 or o_status[i, o] == BLOCKED):
                o_alive[i, o] = False
        if p < 0:
            continue

        m = tri_material[p]
        delta = write_aovs(mat_type, mat_param, m, i, dk, -dot(wray, ng), ng, t[k], aov, aov_open)
        if max_depth >= 0 and dk + 1 >= max_depth:
            continue
        s, tt = frame(ng)
        wo = to_local((-wray[0], -wray[1], -wray[2]), s, tt, ng)
        kk = key[i]
        rough = _is_rough(mat_type, mat_param, m, roughness)
        for o in range(4):
            if o_alive[i, o]:
                if o_status[i, o] == TRACED:
                    o_rough[i, o] = _is_rough(mat_type, mat_param, tri_material[o_prim[i, o]], roughness)
                else:
                    o_rough[i, o] = rough

        # NEE: the base's sample (the path tracer's), shifted to each offset
        if not delta:
            ok, so, sd, tmax, contrib, wl, dist, lel, pll, lt_tri, fb, pbb = light_sample_at(
                mat_type, mat_param, m, lt, tri, x, ng, s, tt, wo, b, gs, -1, 1.0, tri_eps[p], tri_eps,
                draw(ps, kk, i, bounce_dim(dk, LIGHT)), draw(ps, kk, i, bounce_dim(dk, LIGHT_POS)),
                draw(ps, kk, i, bounce_dim(dk, LIGHT_POS + 1)))
            valid = pll > 0.0 and (lel[0] > 0.0 or lel[1] > 0.0 or lel[2] > 0.0)
            if valid and not ok:  # no value, but its visibility enters the pairs' weights
                so, sd, tmax = shadow_ray(x, ng, tri_eps[p], wl, dist, lt, lt_tri, tri_eps)
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
                rough_z = lt_tri < 0 or _is_rough(mat_type, mat_param, tri_material[lt_tri], roughness)
                for o in range(4):
                    if not o_alive[i, o]:
                        n_mode[i, o] = 1
                        continue
                    st = o_status[i, o]
                    if st == TRACED and not (rough and o_rough[i, o] and rough_z):
                        # The pair's BSDF sample would be copied, not reconnected: no NEE for it (NEE
                        # reconnects, and both techniques must map a path to the same partner). An
                        # offset at a delta vertex has no partner either way: the base's two techniques.
                        if bsdfs.bsdf_is_delta(mat_type, mat_param, tri_material[o_prim[i, o]]):
                            n_mode[i, o] = 1
                        continue
                    y = x
                    ngy = ng
                    sy = s
                    ty = tt
                    py = p
                    if st == TRACED:
                        py = o_prim[i, o]
                        y = (o_x[i, o, 0], o_x[i, o, 1], o_x[i, o, 2])
                        ngy = (tri_normal[py, 0], tri_normal[py, 1], tri_normal[py, 2])
                        sy, ty = frame(ngy)
                    my = tri_material[py]
                    wo_o = to_local((o_wo[i, o, 0], o_wo[i, o, 1], o_wo[i, o, 2]), sy, ty, ngy)
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
                            n_mode[i, o] = 1
                            continue
                        cos_l = -dot(wlo, nl)
                        leo = triangle_emission(lt, lt_tri, cos_l)
                        plo = triangle_light_pdf(lt, lt_tri, disto * disto, cos_l)
                    wil = to_local(wlo, sy, ty, ngy)
                    fo = bsdfs.bsdf_eval(mat_type, mat_param, my, wo_o, wil, True)
                    n_pbo[i, o] = bsdfs.bsdf_pdf(mat_type, mat_param, my, wo_o, wil)
                    n_plo[i, o] = plo
                    n_rj[i, o] = o_R[i, o] * jl
                    for c in range(3):
                        n_co[i, o, c] = o_beta[i, o, c] * jl * fo[c] * leo[c] / pll
                    if st != TRACED:  # at the base's vertex: the base's shadow ray
                        n_mode[i, o] = 2
                        continue
                    n_mode[i, o] = 3
                    oo, od, otmax = shadow_ray(y, ngy, tri_eps[py], wlo, disto, lt, lt_tri, tri_eps)
                    if otmax > 0.0:
                        o_sh[i, o] = True
                        o_sh_tmax[i, o] = otmax
                        for c in range(3):
                            o_sh_o[i, o, c] = oo[c]
                            o_sh_d[i, o, c] = od[c]

        # The base's next direction (the path tracer's) and roulette
        wiw, wt, pdf, _, dlt, _, _ = sample_mixture(
            mat_type, mat_param, m, gs, -1, 1.0, wo, s, tt, ng, draw(ps, kk, i, bounce_dim(dk, DIR)),
            draw(ps, kk, i, bounce_dim(dk, DIR + 1)), draw(ps, kk, i, bounce_dim(dk, LOBE)), 1.0)
        nb = (b[0] * wt[0], b[1] * wt[1], b[2] * wt[2])
        bmax = max(nb[0], max(nb[1], nb[2]))
        go = bmax > 0.0 and math.isfinite(bmax)
        q = 1.0
        if go and dk + 1 >= rr_depth:
            go, nb, q = russian_roulette(nb, 1.0, draw(ps, kk, i, bounce_dim(dk, RR)))
        if dk + 1 >= MAX_BOUNCES:
            go = False
        if not go:
            continue
        no = offset_point(x, ng, wiw, tri_eps[p])
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
        b_delta[i] = dlt
        b_rough[i] = rough and not dlt
        depth[i] = dk + 1
        prev_pdf[i] = pdf
        prev_delta[i] = dlt
        alive[k] = True


@kernel
def add_next_event(active, has_shadow, vis_b, sh_L, L, G, n_mode, n_cn, n_pl, n_pb, n_co, n_rj, n_plo, n_pbo, vis):
    """Add the bounce's NEE once its shadow rays are traced: the base's value to L, and to each pair's
    gradient w (vis_o C_o - vis_b C_b), w = pL^2 / (pL^2 + pB^2 + (R J_L)^2 (pL_o^2 + pB_o^2)), where a
    blocked side's BSDF density is 0 (a BSDF sample cannot reach the light through the occluder).
    Mode 1 (no partner): minus the base's own weighted value."""
    for k in prange(active.shape[0]):
        i = active[k]
        vb = has_shadow[k] and vis_b[k]
        if vb:
            for c in range(3):
                L[i, c] += sh_L[k, c]
        for o in range(4):
            mode = n_mode[i, o]
            if mode == 0:
                continue
            if mode == 1:
                if vb:
                    for c in range(3):
                        G[i, o, c] -= sh_L[k, c]
                continue
            vo = vb if mode == 2 else vis[i, o]
            pl = n_pl[i]
            pb = n_pb[i] if vb else 0.0
            po = n_pbo[i, o] if vo else 0.0
            rj = n_rj[i, o]
            wg = pl * pl / (pl * pl + pb * pb + rj * rj * (n_plo[i, o] * n_plo[i, o] + po * po))
            for c in range(3):
                G[i, o, c] += wg * ((n_co[i, o, c] if vo else 0.0) - (n_cn[i, c] if vb else 0.0))


_CAMERA = CameraSource()


def warm_up(ctx, buf, roughness):
    """Compile (or load) the hybrid kernels: a wave of no paths still calls each one."""
    hb = HybridBuffers(1)
    idx = np.zeros(0, np.int64)
    t, prim, b1, b2 = ctx.accel.intersect(buf.ray_o[:0], buf.ray_d[:0])
    surf = ctx.surfaces
    start_offsets(ctx.cam, ctx.scene.width, ctx.scene.height, ctx.crop, ctx.jitter, no_primary_samples(),
                  buf.key[:0], buf.pix[:0], hb.ray_o, hb.ray_d, hb.alive, hb.status, hb.beta, hb.R, hb.wo, hb.hv,
                  hb.trace, hb.reconn, hb.G)
    shift_offsets(idx, t, prim, b1, b2, buf.ray_d[:0], surf.tri, surf.normal, surf.material, surf.eps,
                  surf.mat_type, surf.mat_param, roughness, hb.b_x, hb.b_prim, hb.b_wo, hb.b_wt, hb.b_pdf,
                  hb.b_delta, hb.b_rough, *hb.offset_state())
    _shade(ctx, buf, hb, idx, buf.ray_d[:0], (t, prim, b1, b2), no_primary_samples(), roughness)
    _add_next_event(buf, hb, idx)


def _shade(ctx, buf, hb, active, rd, hits, ps, roughness):
    shade_hybrid(active, rd, *hits, *ctx.surfaces, ctx.lights, ctx.guide_state, ps, ctx.max_depth,
                 ctx.rr_depth, roughness, buf.beta, buf.L, buf.L_cam, buf.depth, buf.prev_pdf, buf.prev_delta,
                 buf.key, buf.aov, buf.aov_open, buf.alive, buf.next_o, buf.next_d, buf.sh_o, buf.sh_d,
                 buf.sh_tmax, buf.sh_L, buf.has_shadow, hb.b_x, hb.b_prim, hb.b_wo, hb.b_wt, hb.b_pdf,
                 hb.b_delta, hb.b_rough, hb.G, hb.alive, hb.status, hb.beta, hb.R, hb.x, hb.prim,
                 hb.wo, hb.pdf, hb.delta, hb.dist2, hb.rough, hb.hv, hb.lights, hb.trace, hb.hit_t, hb.hit_prim,
                 hb.hit_b1, hb.hit_b2, hb.sh, hb.sh_o, hb.sh_d, hb.sh_tmax, *_nee(hb))


def _nee(hb):
    return hb.n_cn, hb.n_pl, hb.n_pb, hb.n_mode, hb.n_co, hb.n_rj, hb.n_plo, hb.n_pbo, hb.vis


def _add_next_event(buf, hb, active):
    add_next_event(active, buf.has_shadow, hb.vis_b, buf.sh_L, buf.L, hb.G, hb.n_mode, hb.n_cn, hb.n_pl, hb.n_pb,
                   hb.n_co, hb.n_rj, hb.n_plo, hb.n_pbo, hb.vis)


def trace_hybrid_wave(ctx, buf, hb, films, sample0, g0, n, stats, roughness):
    """Trace paths g0 .. g0+n-1 of a pass (base and four offsets, hybrid shift) and add them to
    `films` (replay.GradientFilms). buf: a WaveBuffers, hb: HybridBuffers, both of at least n."""
    from .replay import add_gradients

    accel = ctx.accel
    t0 = _time.perf_counter()
    ps = _CAMERA.start(ctx, buf, sample0, g0, n)
    start_offsets(ctx.cam, ctx.scene.width, ctx.scene.height, ctx.crop, ctx.jitter, ps, buf.key[:n], buf.pix[:n],
                  hb.ray_o, hb.ray_d, hb.alive, hb.status, hb.beta, hb.R, hb.wo, hb.hv, hb.trace, hb.reconn, hb.G)
    active = np.arange(n)
    surf = ctx.surfaces
    t0 = stats.tick("camera", t0)
    for bounce in range(MAX_BOUNCES + 1):
        na = active.shape[0]
        if na == 0:
            break
        ro, rd = buf.ray_o[:na], buf.ray_d[:na]
        t, prim, b1, b2 = accel.intersect(ro, rd)
        stats.rays += na
        t0 = stats.tick("intersect", t0)
        if bounce > 0:
            shift_offsets(active, t, prim, b1, b2, rd, surf.tri, surf.normal, surf.material, surf.eps, surf.mat_type,
                          surf.mat_param, roughness, hb.b_x, hb.b_prim, hb.b_wo, hb.b_wt, hb.b_pdf, hb.b_delta,
                          hb.b_rough, *hb.offset_state())
            t0 = stats.tick("shift", t0)
        # The offsets' own rays, and the visibility of their reconnections
        pi, po = np.nonzero(hb.trace[active])
        if pi.size:
            sl = active[pi]
            ht, hp, h1, h2 = accel.intersect(hb.ray_o[sl, po], hb.ray_d[sl, po])
            hb.hit_t[sl, po], hb.hit_prim[sl, po], hb.hit_b1[sl, po], hb.hit_b2[sl, po] = ht, hp, h1, h2
            stats.rays += pi.size
        ri, ro_ = np.nonzero(hb.reconn[active])
        if ri.size:
            sl = active[ri]
            occ = accel.occluded(hb.ray_o[sl, ro_], hb.ray_d[sl, ro_], hb.tmax[sl, ro_])
            hb.status[sl[occ], ro_[occ]] = BLOCKED
            stats.shadow_rays += ri.size
        t0 = stats.tick("intersect", t0)
        _shade(ctx, buf, hb, active, rd, (t, prim, b1, b2), ps, roughness)
        t0 = stats.tick("shade", t0)
        # Shadow rays: the base's, then the offsets' own; then the NEE terms with their weights
        kb = np.flatnonzero(buf.has_shadow[:na])
        si, so = np.nonzero(hb.sh[active])
        ss = active[si]
        if kb.size + si.size:
            org = np.concatenate([buf.sh_o[kb], hb.sh_o[ss, so]])
            dirs = np.concatenate([buf.sh_d[kb], hb.sh_d[ss, so]])
            tmax = np.concatenate([buf.sh_tmax[kb], hb.sh_tmax[ss, so]])
            vis = ~accel.occluded(org, dirs, tmax)
            stats.shadow_rays += kb.size + si.size
            hb.vis_b[kb] = vis[:kb.size]
            hb.vis[ss, so] = vis[kb.size:]
            t0 = stats.tick("occluded", t0)
            _add_next_event(buf, hb, active)
            t0 = stats.tick("shade", t0)
        keep = buf.alive[:na]
        m = int(np.count_nonzero(keep))
        buf.ray_o[:m] = buf.next_o[:na][keep]
        buf.ray_d[:m] = buf.next_d[:na][keep]
        active = active[keep]
        t0 = stats.tick("compact", t0)
    stats.nonfinite += sanitize(buf.L[:n]) + sanitize(hb.G[:n].reshape(-1, 3))
    add_gradients(ctx, buf, films, n, 2.0 * hb.G[:n])
    stats.samples += n
    stats.tick("film", t0)
