"""Photons: light paths traced from the emitters, binned by the voxels they land in (eq. 10).

An emitter is chosen by power (the light tables NEE uses). From a triangle, the photon leaves a
point uniform by area in a cosine-distributed direction on the emitting side, carrying
Le * A * pi / P(triangle). From a point light, a uniform direction carrying 4 pi I / P(light);
from a spot, a direction uniform in its cone carrying I falloff (times its projected texture)
2 pi (1 - cos cutoff) / P(light);
from a directional light, a point of a disk of radius R across its direction, outside the scene,
carrying E pi R^2 / P(light). From the environment, a direction is drawn by the environment's own
importance sampling and the photon starts on a disk of the bounding sphere's radius R,
perpendicular to it and outside the scene, carrying Le * pi R^2 / pdf(direction). Bounces sample
the BSDF in importance mode (the adjoint), with Russian roulette on the throughput from the
`rr_depth`-th hit on.

Aimed environment photons (`EnvAim`): where camera paths were seen to escape to the environment,
environment photons start only in the directions and through the openings those paths took. The
directions are binned (AIM_THETA x AIM_PHI cylindrical bins); a photon whose direction falls in a
bin (or a neighbour of one) where no camera path escaped is dropped before it is traced, and the
others start on a rectangle of the plane 1.01 R from the centre facing the bin's centre direction
n_b, the box of the escaped rays' crossings of that plane (over the bin and its neighbours, widened
by the distance a direction inside the bin can drift on its way in), carrying
Le * area * |ws . n_b| / pdf(direction). That is the flux through the rectangle, so photons that
enter keep their expected power; photons that would have entered elsewhere are lost to the maps
(never to the render, whose BSDF share of the mixture keeps every direction).

At every hit on a non-delta surface whose voxel has a data slot, the photon deposits its power
(luminance) in the bin of the direction it arrived from. Photons are traced as a wavefront, like
camera paths; `trace_photons` hands each bounce's deposits to a sink.
"""
import functools
import math
from typing import NamedTuple

import numpy as np
from numba import prange

from ... import bsdfs
from ..._jit import jit, kernel
from ...lights import DELTA_DIRECTIONAL, DELTA_POINT, sample_light, spot_value
from ...material import adjoint_factor, crosses, surface_at
from ...rng import P_DIR, P_LIGHT, P_POS, P_RR, photon_dim, photon_key, uniform
from ...wave import Continuation
from ...sampling import (
    dot,
    frame,
    sample_concentric_disk,
    sample_cosine_hemisphere,
    sample_distribution_1d,
    sample_uniform_sphere,
    sample_uniform_triangle,
    to_local,
    to_world,
    triangle_point,
)
from ..directional import bin_direction, bin_of_batch, direction_bin, map_pdf, map_sample
from ..contract import find_voxel


AIM_THETA = 32
AIM_PHI = 64


class EnvAim(NamedTuple):
    """Where environment photons may start (see the module docstring); `allowed` empty: anywhere."""

    allowed: np.ndarray  # (K,) bool per direction bin (AIM_THETA x AIM_PHI)
    box: np.ndarray  # (K, 4) float64: s0, s1, t0, t1 of the start rectangle in the bin's frame
    axes: np.ndarray  # (K, 3, 3) float64: the bin's centre direction n_b and its frame s, t


def no_aim():
    return EnvAim(np.zeros(0, np.bool_), np.zeros((0, 4)), np.zeros((0, 3, 3)))


@functools.lru_cache(maxsize=1)
def _bin_axes():
    """(K, 3, 3): the centre direction of every aim bin and its frame (sampling.frame)."""
    axes = np.empty((AIM_THETA * AIM_PHI, 3, 3))
    for k in range(axes.shape[0]):
        nb = bin_direction(k, AIM_THETA, AIM_PHI, 0.5, 0.5)
        axes[k] = (nb, *frame(nb))
    return axes


def env_aim(x, w, centre, radius):
    """EnvAim from escaped camera rays: origins x (m, 3) and unit directions w (m, 3)."""
    if len(x) == 0:
        return no_aim()
    axes = _bin_axes().copy()
    K = axes.shape[0]
    b = bin_of_batch(np.ascontiguousarray(w), AIM_THETA, AIM_PHI)
    seen = np.zeros((AIM_THETA, AIM_PHI), np.bool_)
    seen.reshape(-1)[b] = True
    # a bin is allowed if it or a neighbour (phi wraps around) saw an escape
    pad = np.pad(seen, ((1, 1), (0, 0)))
    allowed = np.zeros_like(seen)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            allowed |= np.roll(pad[1 + dr: 1 + dr + AIM_THETA], dc, axis=1)
    allowed = allowed.reshape(-1)
    box = np.zeros((K, 4))
    box[:, 0] = box[:, 2] = np.inf
    box[:, 1] = box[:, 3] = -np.inf
    # crossings of each escaped ray with the start planes of its bin and the neighbours
    row, col = b // AIM_PHI, b % AIM_PHI
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            r2 = row + dr
            ok = (r2 >= 0) & (r2 < AIM_THETA)
            nbin = r2[ok] * AIM_PHI + (col[ok] + dc) % AIM_PHI
            nb, sb, tb = axes[nbin, 0], axes[nbin, 1], axes[nbin, 2]
            rel = x[ok] - centre
            cosw = np.einsum("ij,ij->i", w[ok], nb)
            good = cosw > 0.05
            tau = (1.01 * radius - np.einsum("ij,ij->i", rel, nb)) / np.where(good, cosw, 1.0)
            q = rel + tau[:, None] * w[ok]
            qs, qt = np.einsum("ij,ij->i", q, sb), np.einsum("ij,ij->i", q, tb)
            nbin, qs, qt = nbin[good], qs[good], qt[good]
            np.minimum.at(box[:, 0], nbin, qs)
            np.maximum.at(box[:, 1], nbin, qs)
            np.minimum.at(box[:, 2], nbin, qt)
            np.maximum.at(box[:, 3], nbin, qt)
    # a direction inside a bin is within `half` of its centre; over the ~2.02 R it travels to the
    # far side of the scene, it drifts sideways by up to 2.02 R tan(half)
    half = max(math.pi / AIM_PHI, 2.0 / AIM_THETA)
    margin = 2.02 * radius * math.tan(half)
    box[:, 0] -= margin
    box[:, 2] -= margin
    box[:, 1] += margin
    box[:, 3] += margin
    allowed &= np.isfinite(box).all(axis=1)
    box[~allowed] = 0.0
    return EnvAim(allowed, box, axes)


@kernel
def emit(lt, tri, centre, radius, tri_eps, seed, iteration, g0, aim, key, o, d, power, thr, depth, src):
    """Photons g0 .. g0+n-1 of an iteration: origin, direction, power (RGB), throughput 1; src 1
    for an environment photon, 0 for one from a triangle (power 0: dropped)."""
    n = key.shape[0]
    aimed = aim.allowed.shape[0] > 0
    for i in prange(n):
        k = photon_key(seed, iteration, g0 + i)
        key[i] = k
        depth[i] = 0
        src[i] = 0
        for c in range(3):
            thr[i, c] = 1.0
            power[i, c] = 0.0
            o[i, c] = centre[c]
            d[i, c] = 0.0
        d[i, 2] = 1.0
        u_sel = uniform(k, P_LIGHT)
        if u_sel < lt.p_env:
            src[i] = 1
            # From the environment: a direction by the environment's sampling, a disk of radius R
            ws, _, rad, pdf, _ = sample_light(lt, tri, (centre[0], centre[1], centre[2]), u_sel,
                                           uniform(k, P_POS), uniform(k, P_POS + 1))
            if not (pdf > 0.0):
                continue
            if aimed:
                # ... or the start rectangle of its bin, where camera paths escaped
                bn = direction_bin(ws, AIM_THETA, AIM_PHI)
                if not aim.allowed[bn]:
                    continue
                nb = (aim.axes[bn, 0, 0], aim.axes[bn, 0, 1], aim.axes[bn, 0, 2])
                cw = dot(ws, nb)
                if not (cw > 0.0):
                    continue
                bs = aim.box[bn, 0] + uniform(k, P_DIR) * (aim.box[bn, 1] - aim.box[bn, 0])
                bt = aim.box[bn, 2] + uniform(k, P_DIR + 1) * (aim.box[bn, 3] - aim.box[bn, 2])
                area = (aim.box[bn, 1] - aim.box[bn, 0]) * (aim.box[bn, 3] - aim.box[bn, 2])
                for c in range(3):
                    o[i, c] = centre[c] + 1.01 * radius * nb[c] + bs * aim.axes[bn, 1, c] + bt * aim.axes[bn, 2, c]
                    d[i, c] = -ws[c]
                    power[i, c] = rad[c] * area * cw / pdf
                continue
            s, t = frame(ws)
            dx, dy = sample_concentric_disk(uniform(k, P_DIR), uniform(k, P_DIR + 1))
            area = math.pi * radius * radius
            for c in range(3):
                o[i, c] = centre[c] + radius * (1.01 * ws[c] + dx * s[c] + dy * t[c])
                d[i, c] = -ws[c]
                power[i, c] = rad[c] * area / pdf
            continue
        # From a triangle chosen by power, a point by area, a cosine-distributed direction
        u = min((u_sel - lt.p_env) / (1.0 - lt.p_env), 1.0 - 1e-12)
        _, _, li = sample_distribution_1d(lt.func, lt.cdf, u)
        p_sel = (1.0 - lt.p_env) * (lt.cdf[li + 1] - lt.cdf[li])
        if not (p_sel > 0.0):
            continue
        if li >= lt.tri.shape[0]:  # a delta light
            j = li - lt.tri.shape[0]
            kind = lt.delta_kind[j]
            ax = (lt.delta_dir[j, 0], lt.delta_dir[j, 1], lt.delta_dir[j, 2])
            s, t = frame(ax)
            u0, u1 = uniform(k, P_DIR), uniform(k, P_DIR + 1)
            if kind == DELTA_DIRECTIONAL:
                dx, dy = sample_concentric_disk(u0, u1)
                scale = math.pi * radius * radius / p_sel
                for c in range(3):
                    o[i, c] = centre[c] + radius * (-1.01 * ax[c] + dx * s[c] + dy * t[c])
                    d[i, c] = ax[c]
                    power[i, c] = lt.delta_value[j, c] * scale
                continue
            if kind == DELTA_POINT:
                w = sample_uniform_sphere(u0, u1)
                scale = 4.0 * math.pi / p_sel
                f = (scale, scale, scale)
            else:  # a spot: uniform in its cone
                cz = 1.0 - u0 * (1.0 - lt.delta_cone[j, 0])
                sz = math.sqrt(max(1.0 - cz * cz, 0.0))
                w = to_world((sz * math.cos(2.0 * math.pi * u1), sz * math.sin(2.0 * math.pi * u1), cz), s, t, ax)
                scale = 2.0 * math.pi * (1.0 - lt.delta_cone[j, 0]) / p_sel
                f = spot_value(lt, j, w)
                f = (f[0] * scale, f[1] * scale, f[2] * scale)
            for c in range(3):
                o[i, c] = lt.delta_pos[j, c]
                d[i, c] = w[c]
                power[i, c] = lt.delta_value[j, c] * f[c]
            continue
        tr = lt.tri[li]
        b1, b2 = sample_uniform_triangle(uniform(k, P_POS), uniform(k, P_POS + 1))
        b0 = 1.0 - b1 - b2
        nrm = (lt.normal[li, 0], lt.normal[li, 1], lt.normal[li, 2])
        s, t = frame(nrm)
        wl = sample_cosine_hemisphere(uniform(k, P_DIR), uniform(k, P_DIR + 1))
        w = to_world(wl, s, t, nrm)
        for c in range(3):
            x = b0 * tri[tr, 0, c] + b1 * tri[tr, 1, c] + b2 * tri[tr, 2, c]
            o[i, c] = x + tri_eps[tr] * nrm[c]
            d[i, c] = w[c]
            power[i, c] = lt.radiance[li, c] * lt.area[li] * math.pi / p_sel


@kernel
def scatter(active, d, hits, surf, gs, data_slot, photons, limits, cont, dep, imp):
    """One hit for every active photon: deposit, then sample the BSDF (importance mode) and roulette.

    Entry k of the hits (t, prim, b1, b2) and of the rays' directions d belongs to photon active[k]
    (its PhotonState in `photons`); writes its Deposits entry (node -1 for none) and its
    wave.Continuation (alive[k], next_o/next_d[k]). limits = (max_hits, rr_depth, first_hit,
    p_imp). Photons deposit at their first hit (direct light) only if `first_hit`. Guided light
    tracing: at a non-delta hit whose voxel has an importance map in `imp` (a GuideState on gs's
    tree), the direction comes from that map with probability p_imp, else from the BSDF, and the
    photon's weight is f |cos| / the mixture's pdf.
    surf: the scene's material.Surfaces; with shading normals the weight carries Veach's adjoint
    correction (material.adjoint_factor) and is zero across the true surface (material.crosses).
    """
    prim = hits[1]
    b1 = hits[2]
    b2 = hits[3]
    key = photons.key
    power = photons.power
    thr = photons.thr
    depth = photons.depth
    max_hits = limits[0]
    rr_depth = limits[1]
    first_hit = limits[2]
    p_imp = limits[3]
    alive = cont.alive
    next_o = cont.next_o
    next_d = cont.next_d
    dep_node = dep.node
    dep_bin = dep.bin
    dep_val = dep.val
    dep_x = dep.x
    dep_n = dep.n
    n = active.shape[0]
    for k in prange(n):
        i = active[k]
        alive[k] = False
        dep_node[k] = -1
        p = prim[k]
        if p < 0:
            continue
        x = triangle_point(surf.tri, p, b1[k], b2[k])
        ng = (surf.normal[p, 0], surf.normal[p, 1], surf.normal[p, 2])
        sf = surface_at(surf, p, b1[k], b2[k])
        win = (-d[k, 0], -d[k, 1], -d[k, 2])  # toward where the photon came from
        delta = bsdfs.bsdf_is_delta(sf.bp)
        pw = (power[i, 0] * thr[i, 0], power[i, 1] * thr[i, 1], power[i, 2] * thr[i, 2])
        node = -1
        if not delta and (first_hit or depth[i] > 0 or p_imp > 0.0):
            cw = dot(win, ng)
            nf = ng if cw >= 0.0 else (-ng[0], -ng[1], -ng[2])  # the side the photon arrives on
            node = find_voxel(gs, x, nf)
            if node >= 0 and data_slot[node] >= 0 and (first_hit or depth[i] > 0):
                dep_node[k] = node
                dep_bin[k] = direction_bin(win, gs.n_theta, gs.n_phi)
                dep_val[k] = 0.2126 * pw[0] + 0.7152 * pw[1] + 0.0722 * pw[2]
                dep_x[k, 0], dep_x[k, 1], dep_x[k, 2] = x
                dep_n[k, 0], dep_n[k, 1], dep_n[k, 2] = nf
        dk = depth[i]
        if dk + 1 >= max_hits:
            continue
        s, tt, ns = sf.s, sf.t, sf.ns
        kk = key[i]
        wo = to_local(win, s, tt, ns)
        u0 = uniform(kk, photon_dim(dk, 0))
        u1 = uniform(kk, photon_dim(dk, 1))
        u2 = uniform(kk, photon_dim(dk, 2))  # the strategy, then (rescaled) the BSDF's lobe
        islot = imp.slot[node] if node >= 0 else -1
        if islot >= 0 and u2 < p_imp:
            wiw, pg = map_sample(imp.rowcum, imp.dens, imp.wsum, imp.pscale, islot, imp.n_theta, imp.n_phi, u0, u1)
            wi = to_local(wiw, s, tt, ns)
            f, pbs = bsdfs.bsdf_eval_pdf(sf.bp, wo, wi, False, surf.mat_table)
            pm = (1.0 - p_imp) * pbs + p_imp * pg
            wt = (0.0, 0.0, 0.0)
            if pm > 0.0:
                wt = (f[0] / pm, f[1] / pm, f[2] / pm)
        else:
            if islot >= 0:
                u2 = min((u2 - p_imp) / (1.0 - p_imp), 1.0 - 1e-12)
            wi, wt, pdf, dlt = bsdfs.bsdf_sample(sf.bp, wo, u0, u1, u2, False, surf.mat_table)
            if islot >= 0 and pdf > 0.0:
                # a delta lobe beside a smooth one: picked with probability (1 - p_imp) x its own
                pm = (1.0 - p_imp) * pdf
                if not dlt:
                    pm += p_imp * map_pdf(imp.dens, imp.pscale, islot, imp.n_theta, imp.n_phi, to_world(wi, s, tt, ns))
                r = pdf / pm
                wt = (wt[0] * r, wt[1] * r, wt[2] * r)
        if sf.smooth:
            ww = to_world(wi, s, tt, ns)
            cf = 0.0 if crosses(sf, dot(win, ng), ng, wo, wi, ww) else adjoint_factor(ng, ns, win, ww)
            wt = (wt[0] * cf, wt[1] * cf, wt[2] * cf)
        nb = (thr[i, 0] * wt[0], thr[i, 1] * wt[1], thr[i, 2] * wt[2])
        bmax = max(nb[0], max(nb[1], nb[2]))
        if not (bmax > 0.0) or not math.isfinite(bmax):
            continue
        if dk + 1 >= rr_depth:
            q = min(bmax, 0.95)
            if uniform(kk, photon_dim(dk, P_RR)) >= q:
                continue
            nb = (nb[0] / q, nb[1] / q, nb[2] / q)
        w = to_world(wi, s, tt, ns)
        sg = surf.eps[p] if dot(w, ng) >= 0.0 else -surf.eps[p]
        for c in range(3):
            thr[i, c] = nb[c]
            next_o[k, c] = x[c] + sg * ng[c]
            next_d[k, c] = w[c]
        depth[i] = dk + 1
        alive[k] = True


@jit
def compact_wave(m, alive, next_o, next_d, active, o, d, dep_node, dep_bin, dep_val, dep_x, dep_n):
    """After a bounce of the m photons active[:m]: move the survivors' rays (next_o/next_d) and ids
    to the front of o, d and active, and the deposits (dep_node >= 0) to the front of the dep_*
    arrays, keeping their order. In place (writes never pass reads). Returns (survivors, deposits)."""
    na = 0
    nd = 0
    for k in range(m):
        if alive[k]:
            active[na] = active[k]
            for c in range(3):
                o[na, c] = next_o[k, c]
                d[na, c] = next_d[k, c]
            na += 1
        if dep_node[k] >= 0:
            dep_node[nd] = dep_node[k]
            dep_bin[nd] = dep_bin[k]
            dep_val[nd] = dep_val[k]
            for c in range(3):
                dep_x[nd, c] = dep_x[k, c]
                dep_n[nd, c] = dep_n[k, c]
            nd += 1
    return na, nd


class PhotonState(NamedTuple):
    """Per photon of a wave: what scatter reads and updates."""

    key: np.ndarray  # (n,) uint64 its random stream
    power: np.ndarray  # (n, 3) float64 its power at emission
    thr: np.ndarray  # (n, 3) float64 its throughput since
    depth: np.ndarray  # (n,) int32 hits so far


class Deposits(NamedTuple):
    """Per wave entry: the deposit of its hit (node -1: none)."""

    node: np.ndarray  # (m,) int64 guide voxel
    bin: np.ndarray  # (m,) int64 direction bin of the voxel's map
    val: np.ndarray  # (m,) float64 luminance of the photon's power
    x: np.ndarray  # (m, 3) float64 where
    n: np.ndarray  # (m, 3) float64 the normal on the side it arrived from


class PhotonBuffers:
    def __init__(self, size):
        self.size = size
        z3 = lambda: np.zeros((size, 3))  # noqa: E731
        self.key = np.zeros(size, np.uint64)
        self.o, self.d, self.power, self.thr = z3(), z3(), z3(), z3()
        self.depth = np.zeros(size, np.int32)
        self.src = np.zeros(size, np.int8)
        self.alive = np.zeros(size, np.bool_)
        self.next_o, self.next_d = z3(), z3()
        self.active = np.zeros(size, np.int64)  # the photons still travelling, and their rays
        self.ray_o, self.ray_d = z3(), z3()
        self.dep_node = np.zeros(size, np.int64)
        self.dep_bin = np.zeros(size, np.int64)
        self.dep_val = np.zeros(size)
        self.dep_x = z3()
        self.dep_n = z3()


def trace_photons(ctx, gs, data_slot, n_photons, iteration, sink, wave_size=1 << 16, max_hits=None,
                  first_hit=True, imp=None, p_imp=0.0, aim=None):
    """Trace `n_photons` photons of guide iteration `iteration`; after every bounce call
    sink(node, bin, value, x, n) with that bounce's deposits (arrays of equal length, views into
    buffers that the next bounce overwrites; n is the normal on the side the photon arrived on); with
    first_hit False, photons deposit from their second hit on (indirect light only). With an
    importance state `imp` (HierarchicalGrid.state(importance=True)) and p_imp > 0, light tracing
    is guided (see scatter). `aim`: an EnvAim for the environment photons (None: from the whole
    disk). Returns (photons, deposits, rays, environment photons emitted, of them traced (not
    dropped), of them that deposited at least once)."""
    scene, accel, lt = ctx.scene, ctx.accel, ctx.lights
    if max_hits is None:
        max_hits = ctx.max_depth - 1 if ctx.max_depth > 0 else 64
    max_hits = max(int(max_hits), 1)
    centre = 0.5 * (scene.bounds[0] + scene.bounds[1])
    radius = 0.5 * float(np.linalg.norm(scene.bounds[1] - scene.bounds[0])) * 1.01
    buf = PhotonBuffers(min(wave_size, max(n_photons, 1)))
    if imp is None or not p_imp > 0.0:
        imp = gs._replace(slot=np.full(gs.slot.shape[0], -1, np.int32))
        p_imp = 0.0
    aim = no_aim() if aim is None else aim
    deposits = 0
    rays = 0
    env = [0, 0, 0]
    for g0 in range(0, n_photons, buf.size):
        n = min(buf.size, n_photons - g0)
        emit(lt, scene.tri, centre, radius, ctx.tri_eps, ctx.seed, iteration, g0, aim, buf.key[:n], buf.o[:n],
             buf.d[:n], buf.power[:n], buf.thr[:n], buf.depth[:n], buf.src[:n])
        live = np.flatnonzero(np.any(buf.power[:n] > 0.0, axis=1))
        m = live.size
        is_env = buf.src[:n] == 1
        env[0] += int(is_env.sum())
        env[1] += int(is_env[live].sum())
        entered = np.zeros(n, np.bool_)
        active = buf.active
        active[:m] = live
        buf.ray_o[:m], buf.ray_d[:m] = buf.o[live], buf.d[live]
        while m:
            o, d = buf.ray_o[:m], buf.ray_d[:m]
            t, prim, b1, b2 = accel.intersect(o, d)
            rays += m
            scatter(active[:m], d, (t, prim, b1, b2), ctx.surfaces, gs, data_slot,
                    PhotonState(buf.key, buf.power, buf.thr, buf.depth), (max_hits, int(ctx.rr_depth), bool(first_hit),
                                                                          float(p_imp)),
                    Continuation(buf.alive[:m], buf.next_o[:m], buf.next_d[:m]),
                    Deposits(buf.dep_node[:m], buf.dep_bin[:m], buf.dep_val[:m], buf.dep_x[:m], buf.dep_n[:m]), imp)
            entered[active[:m][buf.dep_node[:m] >= 0]] = True
            m, nd = compact_wave(m, buf.alive, buf.next_o, buf.next_d, active, buf.ray_o, buf.ray_d,
                                 buf.dep_node, buf.dep_bin, buf.dep_val, buf.dep_x, buf.dep_n)
            if nd:
                deposits += nd
                sink(buf.dep_node[:nd], buf.dep_bin[:nd], buf.dep_val[:nd], buf.dep_x[:nd], buf.dep_n[:nd])
        env[2] += int((entered & is_env).sum())
    return n_photons, deposits, rays, env[0], env[1], env[2]
