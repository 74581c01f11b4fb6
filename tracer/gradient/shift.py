"""The hybrid shift's maps (Kettunen et al. 2015): whether a vertex is rough enough to reconnect,
the reconnection's direction and Jacobian, and the half-vector copy with its Jacobian. Each rule
keeps the mapping its own inverse (tests/gradient/test_hybrid.py)."""

import math


from .. import bsdfs
from .._jit import jit
from ..guiding.contract import locate
from ..sampling import dot
from ..shading import mixture_pdf


@jit(inline="always")
def is_rough(surf, m, roughness):
    """Material m (of the material.Surfaces surf) is rough enough to reconnect (roughness is not
    textured: the table's row decides)."""
    return bsdfs.bsdf_roughness(bsdfs.bsdf_at(surf.mat_type, surf.mat_param, m)) > roughness


@jit(inline="always")
def is_near_specular(surf, m, limit):
    """Material m (of surf) is smoother than `limit` (a GGX alpha; delta materials count as 0,
    diffuse as infinitely rough): the light a first vertex of it reflects is the direct buffer's."""
    return bsdfs.bsdf_roughness(bsdfs.bsdf_at(surf.mat_type, surf.mat_param, m)) < limit


@jit(inline="always")
def is_delta(surf, m):
    """Material m (of surf) scatters into discrete directions only."""
    return bsdfs.bsdf_is_delta(bsdfs.bsdf_at(surf.mat_type, surf.mat_param, m))


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
def path_density(gs, bp, x, ng, wo_w, wi_w, pb, delta):
    """The density the path tracer samples world direction wi_w with at vertex x (BSDF bp there,
    geometric normal ng) reached from world direction wo_w (pointing back along the path), given
    the BSDF's own density pb: pb, or with a guide's map there the mixture a pb + (1 - a) p_guide
    (integrators.path.shade's, for guides without per-pixel maps); for a delta lobe (delta: pb its
    probability) of a material that also has a smooth one, a pb. What makes an offset's density
    the one its own pixel's path tracer would give it."""
    if gs.res[0] == 0 or bsdfs.bsdf_is_delta(bp):
        return pb
    nf = ng if dot(wo_w, ng) >= 0.0 else (-ng[0], -ng[1], -ng[2])
    _, slot, a = locate(gs, x, nf, -1, 1)
    if delta:
        return a * pb
    return mixture_pdf(gs, slot, a, pb, wi_w)


@jit(inline="always")
def half_vector_shift(bpx, bpy, wo_b, wi_b, wo_o, delta, table):
    """The direction of the offset at y (BSDF bpy, incoming wo_o, local) that copies the base's
    bounce at x (BSDF bpx, wo_b -> wi_b, local; delta: from a delta lobe). Returns (ok, wi_o,
    f |cos| (discrete value for a delta lobe), density, Jacobian d wi_o / d wi_b). It fails (ok False)
    where the offset would change lobe: reflect where the base refracted or the reverse, a delta lobe
    where the base's was not or the reverse, total internal reflection."""
    zero = (0.0, 0.0, 0.0)
    transmit = wo_b[2] * wi_b[2] < 0.0
    if delta:
        wi, val, prob = bsdfs.delta_lobe(bpy, wo_o, transmit, True)
        return prob > 0.0, wi, val, prob, 1.0
    if bsdfs.bsdf_is_delta(bpy):
        return False, zero, zero, 0.0, 0.0
    if not transmit:
        hb = (wo_b[0] + wi_b[0], wo_b[1] + wi_b[1], wo_b[2] + wi_b[2])
        et_b = 1.0
        et_o = 1.0
    else:
        if bpx[0] != bsdfs.ROUGH_DIELECTRIC or bpy[0] != bsdfs.ROUGH_DIELECTRIC:
            return False, zero, zero, 0.0, 0.0
        ior = bpx[1][7]
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
        ior = bpy[1][7]
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
    f, pdf = bsdfs.bsdf_eval_pdf(bpy, wo_o, wi, True, table)
    return pdf > 0.0 and math.isfinite(jac), wi, f, pdf, jac
