"""The hybrid shift's offset paths: their state (HybridBuffers, four offsets per base path, with a
status TRACED, RECENT, CONNECTED or BLOCKED), their camera rays (start_offsets) and their step at
each of the base's hits (shift_offsets: reconnect, or copy the half vector, shift.py)."""

import math
from typing import NamedTuple

import numpy as np
from numba import prange

from .. import bsdfs
from .._jit import jit, kernel
from ..camera import camera_ray
from ..rng import DIM_PIXEL, draw
from ..material import SURFACE_COLS, costly_surfaces, crosses, kept_surface, surface_at_point
from ..sampling import dot, to_local, to_world, triangle_point
from ..shading import offset_point
from .shift import half_vector_shift, is_rough, path_density, reconnection


# offset status: own vertex; reconnected one bounce ago; the base's vertices; reconnected through an
# occluder (a failed shift that still enters the weights of the emission at the base's vertex)
TRACED, RECENT, CONNECTED, BLOCKED = 0, 1, 2, 3


class BaseBounce(NamedTuple):
    """Per base path: its last bounce x_i -> x_{i+1}, which the shift copies."""

    x: np.ndarray  # (n, 3) float64 the vertex x_i
    prim: np.ndarray  # (n,) int64 its triangle
    wo: np.ndarray  # (n, 3) float64 world direction back along the path
    wt: np.ndarray  # (n, 3) float64 f cos / pdf of the sampled direction
    pdf: np.ndarray  # (n,) float64 its density
    delta: np.ndarray  # (n,) bool sampled from a delta lobe
    rough: np.ndarray  # (n,) bool x_i is rough (and the lobe not delta)
    direct: np.ndarray  # (n,) bool the first vertex is near-specular: the light it reflects is direct light
    sf: np.ndarray  # (n, material.SURFACE_COLS) float64 the Surface at x_i (material.keep_surface), where
    # material.costly_surfaces


class Offsets(NamedTuple):
    """Per base path i and offset o (replay.OFFSETS order): the offset path's state, its own rays,
    their hits and shadow rays, and the pair's gradient so far."""

    alive: np.ndarray  # (n, 4) bool
    status: np.ndarray  # (n, 4) int8 TRACED, RECENT, CONNECTED or BLOCKED
    beta: np.ndarray  # (n, 4, 3) float64 F_o J_o / P_b
    R: np.ndarray  # (n, 4) float64 J_o P_o / P_b
    x: np.ndarray  # (n, 4, 3) float64 its vertex
    prim: np.ndarray  # (n, 4) int64 its triangle (-1: escaped)
    wo: np.ndarray  # (n, 4, 3) float64 world direction back along it
    pdf: np.ndarray  # (n, 4) float64 density of its last direction
    delta: np.ndarray  # (n, 4) bool its last direction from a delta lobe
    dist2: np.ndarray  # (n, 4) float64 squared length of its last segment
    rough: np.ndarray  # (n, 4) bool its vertex is rough
    hv: np.ndarray  # (n, 4) bool its last step was a half-vector copy between rough vertices
    lights: np.ndarray  # (n, 4) bool the pair's last bounce counts the light techniques (not a copy)
    trace: np.ndarray  # (n, 4) bool its own ray (ray_o, ray_d) is to be traced
    reconn: np.ndarray  # (n, 4) bool its reconnection (ray_o, ray_d, tmax) is to be tested
    ray_o: np.ndarray  # (n, 4, 3) float64
    ray_d: np.ndarray  # (n, 4, 3) float64
    tmax: np.ndarray  # (n, 4) float64
    G: np.ndarray  # (n, 4, 3) float64 the weighted gradient I(p + e) - I(p) found so far
    hit_t: np.ndarray  # (n, 4) float64 hit of its own traced ray
    hit_prim: np.ndarray  # (n, 4) int64
    hit_b1: np.ndarray  # (n, 4) float64
    hit_b2: np.ndarray  # (n, 4) float64
    sh: np.ndarray  # (n, 4) bool it has a shadow ray of its own
    sh_o: np.ndarray  # (n, 4, 3) float64
    sh_d: np.ndarray  # (n, 4, 3) float64
    sh_tmax: np.ndarray  # (n, 4) float64
    sf: np.ndarray  # (4 n, material.SURFACE_COLS) float64 row 4 i + o: the Surface at its vertex, where kept
    kept: np.ndarray  # (n, 4) bool shade_hybrid evaluated that Surface at this vertex (its NEE) and kept it


class NeeTerms(NamedTuple):
    """A bounce's NEE terms, weighted once the shadow rays are known (add_next_event): the base's
    value, light and BSDF densities and visibility; per offset a mode (offset_shading.NEE_NONE,
    NEE_BASE_ALONE, NEE_BASE_RAY, NEE_OWN_RAY), value, R J_L, light and BSDF densities, and the
    visibility of its own ray."""

    cn: np.ndarray  # (n, 3) float64
    pl: np.ndarray  # (n,) float64
    pb: np.ndarray  # (n,) float64
    vis_b: np.ndarray  # (m,) bool per entry
    mode: np.ndarray  # (n, 4) int8
    co: np.ndarray  # (n, 4, 3) float64
    rj: np.ndarray  # (n, 4) float64
    plo: np.ndarray  # (n, 4) float64
    pbo: np.ndarray  # (n, 4) float64
    vis: np.ndarray  # (n, 4) bool
    direct: np.ndarray  # (n,) bool the base's NEE value is direct light (L_cam), not in the gradients


class HybridBuffers:
    """The offset paths' state for a wave of `size` base paths (4 offsets each, in the order of
    replay.OFFSETS), and the base's last bounce, which the shift copies."""

    def __init__(self, size):
        z = lambda *s, d=np.float64: np.zeros((size,) + s, d)  # noqa: E731
        self.b_x, self.b_wo, self.b_wt = z(3), z(3), z(3)
        self.b_prim = z(d=np.int64)
        self.b_pdf = z()
        self.b_delta, self.b_rough, self.b_direct = z(d=np.bool_), z(d=np.bool_), z(d=np.bool_)
        self.b_sf = z(SURFACE_COLS)
        # NEE terms, weighted once the shadow rays are known: the base's value, light and BSDF
        # densities; per offset a mode (offset_shading.NEE_*), value, R J_L, light and BSDF densities,
        # and the visibility of its own ray
        self.n_cn, self.n_pl, self.n_pb, self.vis_b = z(3), z(), z(), z(d=np.bool_)
        self.n_mode = z(4, d=np.int8)
        self.n_co, self.n_rj, self.n_plo, self.n_pbo, self.vis = z(4, 3), z(4), z(4), z(4), z(4, d=np.bool_)
        self.n_direct = z(d=np.bool_)
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
        self.o_sf = np.zeros((4 * size, SURFACE_COLS))
        self.kept = z(4, d=np.bool_)

    @staticmethod
    def bytes_for(size):
        """Bytes that HybridBuffers(size) allocates."""
        return sum(a.nbytes for a in vars(HybridBuffers(1)).values() if isinstance(a, np.ndarray)) * size

    def base(self):
        return BaseBounce(self.b_x, self.b_prim, self.b_wo, self.b_wt, self.b_pdf, self.b_delta, self.b_rough,
                          self.b_direct, self.b_sf)

    def offsets(self):
        return Offsets(self.alive, self.status, self.beta, self.R, self.x, self.prim, self.wo, self.pdf, self.delta,
                       self.dist2, self.rough, self.hv, self.lights, self.trace, self.reconn, self.ray_o, self.ray_d,
                       self.tmax, self.G, self.hit_t, self.hit_prim, self.hit_b1, self.hit_b2, self.sh, self.sh_o,
                       self.sh_d, self.sh_tmax, self.o_sf, self.kept)

    def nee_terms(self):
        return NeeTerms(self.n_cn, self.n_pl, self.n_pb, self.vis_b, self.n_mode, self.n_co, self.n_rj, self.n_plo,
                        self.n_pbo, self.vis, self.n_direct)


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
def start_offsets(cam, width, height, crop, jitter, ps, key, pix, off):
    """Offset camera rays of base paths 0 .. n-1 (keys and film pixels from the camera source)
    into the Offsets off: through the neighbouring pixel at the base's position inside its pixel."""
    o_alive = off.alive
    o_status = off.status
    o_beta = off.beta
    o_R = off.R
    o_wo = off.wo
    o_hv = off.hv
    G = off.G
    o_trace = off.trace
    o_reconn = off.reconn
    o_ray_o = off.ray_o
    o_ray_d = off.ray_d
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


@kernel
def shift_offsets(active, hits, ray_d, surf, gs, roughness, bb, off):
    """Shift each offset (the Offsets off) across the base's last bounce x_i -> x_{i+1} (the
    BaseBounce bb; entry k: path active[k], its ray ray_d[k] and hit in hits = (t, prim, b1, b2); surf
    the scene's material.Surfaces; gs: the guide's state, whose mixture gives an offset the density
    its own pixel's path tracer would, shift.path_density): reconnection (a visibility ray to test,
    off.reconn) or half-vector copy (a ray to trace, off.trace); updates beta_o, R, and the offset's
    last density. off.lights: whether the pair's weights for this bounce count the light techniques
    (not after a half-vector copy, whose pairs take no NEE either: NEE reconnects, and both
    techniques must map a path to the same partner)."""
    prim = hits[1]
    b1 = hits[2]
    b2 = hits[3]
    b_x = bb.x
    b_prim = bb.prim
    b_wo = bb.wo
    b_wt = bb.wt
    b_pdf = bb.pdf
    b_delta = bb.delta
    b_rough = bb.rough
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
    o_reconn = off.reconn
    o_ray_o = off.ray_o
    o_ray_d = off.ray_d
    o_tmax = off.tmax
    o_sf = off.sf
    o_kept = off.kept
    keeps = costly_surfaces(surf)
    for k in prange(active.shape[0]):
        i = active[k]
        p1 = prim[k]
        rough1 = True  # the environment counts as rough
        x1 = (0.0, 0.0, 0.0)
        if p1 >= 0:
            rough1 = is_rough(surf, surf.material[p1], roughness)
            x1 = triangle_point(surf.tri, p1, b1[k], b2[k])
        wib_w = (ray_d[k, 0], ray_d[k, 1], ray_d[k, 2])
        px = b_prim[i]
        xb = (b_x[i, 0], b_x[i, 1], b_x[i, 2])
        sfx = kept_surface(surf, b_sf, i, px) if keeps else surface_at_point(surf, px, xb)  # (shade_hybrid's)
        ngx = (surf.normal[px, 0], surf.normal[px, 1], surf.normal[px, 2])
        wi_b = to_local(wib_w, sfx.s, sfx.t, sfx.ns)
        wo_b = to_local((b_wo[i, 0], b_wo[i, 1], b_wo[i, 2]), sfx.s, sfx.t, sfx.ns)
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
                wo_w = (o_wo[i, o, 0], o_wo[i, o, 1], o_wo[i, o, 2])
                wo_o = to_local(wo_w, sfx.s, sfx.t, sfx.ns)
                f, pbs = bsdfs.bsdf_eval_pdf(sfx.bp, wo_o, wi_b, True, surf.mat_table)
                if crosses(sfx, dot(wo_w, ngx), ngx, wo_o, wi_b, wib_w):
                    f = (0.0, 0.0, 0.0)
                po = path_density(gs, sfx.bp, xb, ngx, wo_w, wib_w, pbs, False)
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
            y = (o_x[i, o, 0], o_x[i, o, 1], o_x[i, o, 2])
            sfy = kept_surface(surf, o_sf, 4 * i + o, py) if o_kept[i, o] else surface_at_point(surf, py, y)
            ngy = (surf.normal[py, 0], surf.normal[py, 1], surf.normal[py, 2])
            wo_y = (o_wo[i, o, 0], o_wo[i, o, 1], o_wo[i, o, 2])
            wo_o = to_local(wo_y, sfy.s, sfy.t, sfy.ns)
            if b_rough[i] and o_rough[i, o] and rough1:
                # Reconnect y_i to x_{i+1} (or to the environment along the base's direction)
                jac = 1.0
                wn = wib_w
                d2 = 0.0
                n1 = (0.0, 0.0, 1.0)
                if p1 >= 0:
                    n1 = (surf.normal[p1, 0], surf.normal[p1, 1], surf.normal[p1, 2])
                    wn, dist, jac = reconnection((b_x[i, 0], b_x[i, 1], b_x[i, 2]), y, x1, n1)
                    if not jac > 0.0:
                        o_alive[i, o] = False
                        continue
                    d2 = dist * dist
                wi_o = to_local(wn, sfy.s, sfy.t, sfy.ns)
                f, pbs = bsdfs.bsdf_eval_pdf(sfy.bp, wo_o, wi_o, True, surf.mat_table)
                if crosses(sfy, dot(wo_y, ngy), ngy, wo_o, wi_o, wn):
                    f = (0.0, 0.0, 0.0)
                po = path_density(gs, sfy.bp, y, ngy, wo_y, wn, pbs, False)
                if not (po > 0.0 and math.isfinite(jac)):
                    o_alive[i, o] = False
                    continue
                org = offset_point(y, ngy, wn, surf.eps[py])
                tmax = np.inf
                dr = wn
                if p1 >= 0:  # stop short of x_{i+1}: its end offset toward y_i
                    s1 = -surf.eps[p1] if dot(wn, n1) > 0.0 else surf.eps[p1]
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
            # Half-vector copy (between vertices of the same class; a delta lobe and a vertex without
            # one, or a smooth lobe and a delta vertex, have no partner either way, and keep the
            # base's two techniques)
            o_lights[i, o] = not bsdfs.bsdf_has_delta(sfy.bp) if b_delta[i] else bsdfs.bsdf_is_delta(sfy.bp)
            ok, wi_o, f, po, jac = half_vector_shift(sfx.bp, sfy.bp, wo_b, wi_b, wo_o, b_delta[i], surf.mat_table)
            if not ok:
                o_alive[i, o] = False
                continue
            wiw = to_world(wi_o, sfy.s, sfy.t, sfy.ns)
            if crosses(sfy, dot(wo_y, ngy), ngy, wo_o, wi_o, wiw):
                f = (0.0, 0.0, 0.0)
            po = path_density(gs, sfy.bp, y, ngy, wo_y, wiw, po, b_delta[i])
            org = offset_point(y, ngy, wiw, surf.eps[py])
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
