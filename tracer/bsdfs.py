"""BSDFs: evaluation, importance sampling and densities, as scalar Numba functions.

Materials are a struct of arrays shared with the scene loader and the integrator:

    mat_type  : (M,) int32, one of the type constants below
    mat_param : (M, N_PARAM) float64, columns [kd_r, kd_g, kd_b, ks_r, ks_g, ks_b, alpha, ior,
                eta_r, eta_g, eta_b, k_r, k_g, k_b, flags, bump scale, clear] (P_* below; eta and k:
                METAL's complex index; flags: ONE_SIDED, BECKMANN, NONLINEAR; clear = 1 - opacity)

Every function takes the BSDF at one point, `bp = (type, params)`: the type constant and the
columns above as a tuple, with textures already evaluated there (tracer.material.surface_at makes
it at a hit, `bsdf_at` from the table, `bsdf_row` from Python). Sampling, eval and pdf also take
`table`, the scene's (M, tracer.coating.TABLE_RES) COATED transmittance tables (the rough coat
reads row params[P_TABLE_ROW]); it travels beside bp, not in it, because a tuple that holds an
array costs a reference count per BSDF at every hit (15% of Cornell's throughput, measured).

Frames and measures
-------------------
Directions are unit 3-tuples of float64 in a LOCAL frame whose +z is the geometric normal as
stored (not flipped toward the viewer). `wo` points toward the viewer (previous vertex), `wi`
toward the next vertex. Densities are per unit solid angle of `wi`; for delta lobes the "pdf"
is the discrete probability of the lobe. What the integrator multiplies into the throughput
is always `f * |cos wi|` (from `bsdf_eval`) or the sample weight `f * |cos wi| / pdf` (from
`bsdf_sample`), never a raw 1/pdf.

- DIFFUSE, CONDUCTOR, MIRROR, PLASTIC, METAL, COATED are two-sided unless their ONE_SIDED flag is set
  (then black for wo.z <= 0, as Mitsuba's BSDFs without `twosided`): when wo.z < 0 they mirror
  the frame, and reflection requires wo.z * wi.z > 0. THIN_DIELECTRIC is symmetric.
- DIELECTRIC, ROUGH_DIELECTRIC: wo.z > 0 means wo is outside (index 1), wo.z < 0 inside (index
  ior). Transmission requires wo.z * wi.z < 0.
- `radiance=True` (camera paths) scales refraction by (n_o / n_i)^2, n_o the index on the side of
  wo and n_i on the side of wi (pbrt-v4 `ft /= Sqr(etap)`); `radiance=False` (importance or
  photon transport) leaves it out, so a lossless interface conserves energy exactly.

Microfacet models use the isotropic GGX distribution with the height-correlated Smith masking
G2 and sample visible normals (Heitz 2018, "Sampling the GGX Distribution of Visible Normals");
the rough dielectric follows Walter et al. 2007 ("Microfacet Models for Refraction through
Rough Surfaces"). METAL is Mitsuba 3's conductor as Mitsuba computes it: separable masking
G1(wo) G1(wi), GGX sampled by visible normals or Beckmann by D(h) cos (tests/test_mitsuba_bsdfs.py).
COATED is Mitsuba's plastic / roughplastic (tracer.coating): the smooth one has a delta lobe beside
its diffuse one, so it is not a delta material (`bsdf_is_delta`) but has one (`bsdf_has_delta`), and
only the samples flagged delta come from it.
"""
import math

import numpy as np
from numba import prange

from ._jit import jit, kernel
from .sampling import INV_PI, cross, dot, normalize, sample_cosine_hemisphere

DIFFUSE = 0  # Lambertian, reflectance kd, two-sided
CONDUCTOR = 1  # rough metal: GGX, Schlick Fresnel with F0 = ks, two-sided, VNDF sampling
MIRROR = 2  # smooth perfect conductor tinted by ks (F = ks), two-sided, delta
DIELECTRIC = 3  # smooth dielectric, interior index ior, exterior 1, exact Fresnel, delta
ROUGH_DIELECTRIC = 4  # GGX rough dielectric (Walter et al. 2007), VNDF sampling
PLASTIC = 5  # kd / pi + ks * D G / (4 cos_i cos_o), no Fresnel, two-sided
METAL = 6  # Mitsuba's conductor / roughconductor: complex Fresnel (eta, k) x ks; GGX or Beckmann; delta at alpha 0
THIN_DIELECTRIC = 7  # Mitsuba's thindielectric: a thin slab, reflection and straight transmission, delta
COATED = 8  # Mitsuba's plastic (alpha 0: a delta lobe beside the diffuse one) / roughplastic (tracer.coating)
TYPE_NAMES = ("diffuse", "conductor", "mirror", "dielectric", "rough_dielectric", "plastic", "metal",
              "thin_dielectric", "coated")
ALPHA_MIN = 1e-4  # every GGX evaluation clamps alpha to at least this

# Columns of a material's parameters (mat_param[m], the `params` of bp)
N_PARAM = 17
P_KD, P_KS, P_ALPHA, P_IOR, P_ETA, P_K, P_FLAGS = 0, 3, 6, 7, 8, 11, 14
P_CLEAR = 16  # 1 - opacity (Mitsuba's `mask`, MTL `d`): the share of light that passes straight through
P_SPEC_WEIGHT, P_INTERNAL, P_TABLE_ROW = 8, 9, 10  # COATED (in METAL's eta columns): coating.prepare fills them
# Bits of params[P_FLAGS]
ONE_SIDED = 1  # reflects only on the side of its normal (Mitsuba's BSDFs unless `twosided`); black behind
BECKMANN = 2  # the Beckmann distribution (METAL, COATED), sampled by D(h) cos (Mitsuba's sample_visible false)
NONLINEAR = 4  # COATED: Mitsuba's `nonlinear` (the internal reflections tint: kd / (1 - kd r_in))

_ZERO3 = (0.0, 0.0, 0.0)


# --- Small helpers ---------------------------------------------------------------------------
@jit
def lum(rgb):
    """Rec. 709 luminance of an RGB triple (tuple or length-3 array)."""
    return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]


@jit
def ns_to_alpha(ns):
    """GGX/Beckmann roughness for a Phong exponent (MTL `Ns`): sqrt(2 / (ns + 2)) (Walter 2007)."""
    return np.sqrt(2.0 / (ns + 2.0))


@jit
def _fail():
    """The (wi, weight, pdf, delta) record of a sample that produced no direction."""
    return _ZERO3, _ZERO3, 0.0, False


@jit
def _upper(w):
    """`w` mirrored into the upper hemisphere (two-sided materials, dielectrics seen from wo)."""
    return (w[0], w[1], abs(w[2]))


@jit
def _reflect(w, h):
    """Mirror `w` about the unit normal `h` (both pointing away from the surface)."""
    c = 2.0 * dot(w, h)
    return (c * h[0] - w[0], c * h[1] - w[1], c * h[2] - w[2])


@jit
def _scale3(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@jit
def bsdf_at(mat_type, mat_param, m):
    """The BSDF of material m as its table row gives it, untextured: (type, params), the form
    every function below takes (tracer.material.surface_at gives the one at a hit point)."""
    return (mat_type[m], (mat_param[m, 0], mat_param[m, 1], mat_param[m, 2], mat_param[m, 3], mat_param[m, 4],
                          mat_param[m, 5], mat_param[m, 6], mat_param[m, 7], mat_param[m, 8], mat_param[m, 9],
                          mat_param[m, 10], mat_param[m, 11], mat_param[m, 12], mat_param[m, 13],
                          mat_param[m, 14], mat_param[m, 15], mat_param[m, 16]))


def bsdf_row(mat_type, mat_param, m, mat_table=None):
    """bsdf_at from Python (tests): tables of fewer than N_PARAM columns read zeros past them;
    COATED rows are prepared (tracer.coating.prepare, as build_scene does) unless mat_table is
    given. Pass bsdf_tables(...) as the functions' `table`."""
    t, p, _ = _table(mat_type, mat_param, mat_table)
    return int(t[m]), tuple(float(x) for x in p[m])


@jit
def _kd(prm):
    return (prm[0], prm[1], prm[2])


@jit
def _ks(prm):
    return (prm[3], prm[4], prm[5])


@jit
def _alpha(prm):
    return max(prm[6], ALPHA_MIN)


# --- Fresnel -----------------------------------------------------------------------------------
@jit
def fresnel_schlick(f0, cos_h):
    """Schlick's approximation per channel: F0 + (1 - F0) (1 - cos)^5, cos clamped to [0, 1]."""
    c = 1.0 - min(max(cos_h, 0.0), 1.0)
    c5 = c * c * c * c * c
    return (f0[0] + (1.0 - f0[0]) * c5, f0[1] + (1.0 - f0[1]) * c5, f0[2] + (1.0 - f0[2]) * c5)


@jit
def fresnel_dielectric(cos_i, eta):
    """Exact unpolarised Fresnel reflectance of a smooth dielectric interface.

    cos_i : cosine of the incident direction with the normal on its own side (>= 0).
    eta   : index on the far (transmitted) side over the index on the incident side.
    Returns (F, cos_t): reflectance and cosine of the refracted direction; (1, 0) under total
    internal reflection.
    """
    c = min(max(cos_i, 0.0), 1.0)
    sin2_t = (1.0 - c * c) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0, 0.0
    cos_t = math.sqrt(1.0 - sin2_t)
    r_par = (eta * c - cos_t) / (eta * c + cos_t)
    r_perp = (c - eta * cos_t) / (c + eta * cos_t)
    return 0.5 * (r_par * r_par + r_perp * r_perp), cos_t


# --- GGX microfacet distribution -----------------------------------------------------------
@jit
def ggx_d(h, alpha):
    """GGX density of microfacet normals D(h), normalised so that the integral of D(h) h.z over
    the hemisphere is 1. h: unit 3-tuple, local frame. 0 below the surface."""
    if h[2] <= 0.0:
        return 0.0
    a2 = alpha * alpha
    # cos^2 (a^2 - 1) + 1 written as sin^2 + a^2 cos^2: no cancellation near the normal
    t = h[0] * h[0] + h[1] * h[1] + a2 * h[2] * h[2]
    if t <= 0.0:
        return 0.0
    return a2 / (math.pi * t * t)


@jit
def ggx_lambda(w, alpha):
    """Smith Lambda(w) for GGX, (sqrt(1 + a^2 tan^2) - 1) / 2 written without cancellation;
    inf for w in the surface plane."""
    s2 = w[0] * w[0] + w[1] * w[1]
    if s2 == 0.0:
        return 0.0
    z2 = w[2] * w[2]
    if z2 == 0.0:
        return math.inf
    a2t2 = alpha * alpha * s2 / z2
    if math.isinf(a2t2):
        return math.inf
    return a2t2 / (2.0 * (1.0 + math.sqrt(1.0 + a2t2)))


@jit
def ggx_g1(w, alpha):
    """Smith masking G1(w) = 1 / (1 + Lambda(w))."""
    return 1.0 / (1.0 + ggx_lambda(w, alpha))


@jit
def ggx_g2(wo, wi, alpha):
    """Height-correlated Smith masking-shadowing 1 / (1 + Lambda(wo) + Lambda(wi))."""
    return 1.0 / (1.0 + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha))


@jit
def sample_ggx_vndf(w, alpha, u0, u1):
    """Microfacet normal h distributed as the visible normals from w (Heitz 2018).

    Density of h per unit solid angle: D_w(h) = G1(w) max(0, w.h) D(h) / w.z (`ggx_vndf_pdf`).
    w: unit 3-tuple with w.z > 0. Returns a unit 3-tuple with h.z >= 0.
    """
    # Stretch the view direction to the configuration with alpha = 1 (hemisphere)
    vh = normalize((alpha * w[0], alpha * w[1], w[2]))
    # Orthonormal basis (t1, t2, vh)
    lensq = vh[0] * vh[0] + vh[1] * vh[1]
    if lensq > 0.0:
        inv = 1.0 / math.sqrt(lensq)
        t1 = (-vh[1] * inv, vh[0] * inv, 0.0)
    else:
        t1 = (1.0, 0.0, 0.0)
    t2 = cross(vh, t1)
    # Uniform point on the unit disk, squeezed onto the visible part of the projected hemisphere
    r = math.sqrt(u0)
    phi = 2.0 * math.pi * u1
    p1 = r * math.cos(phi)
    p2 = r * math.sin(phi)
    s = 0.5 * (1.0 + vh[2])
    p2 = (1.0 - s) * math.sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2
    # Lift the point onto the hemisphere
    p3 = math.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    nh = (
        p1 * t1[0] + p2 * t2[0] + p3 * vh[0],
        p1 * t1[1] + p2 * t2[1] + p3 * vh[1],
        p1 * t1[2] + p2 * t2[2] + p3 * vh[2],
    )
    # Unstretch back to the ellipsoid configuration
    return normalize((alpha * nh[0], alpha * nh[1], max(0.0, nh[2])))


@jit
def ggx_vndf_pdf(w, h, alpha):
    """Density of `sample_ggx_vndf` at h per unit solid angle: G1(w) max(0, w.h) D(h) / w.z."""
    cos_wh = dot(w, h)
    if cos_wh <= 0.0 or w[2] <= 0.0:
        return 0.0
    return ggx_g1(w, alpha) * cos_wh * ggx_d(h, alpha) / w[2]


# --- Diffuse --------------------------------------------------------------------------------
@jit
def _diffuse_sample(kd, wo, u0, u1):
    if wo[2] == 0.0:
        return _fail()
    # Cosine-weighted direction on the side of wo
    w = sample_cosine_hemisphere(u0, u1)
    if w[2] <= 0.0:
        return _fail()
    wi = (w[0], w[1], w[2] if wo[2] > 0.0 else -w[2])
    return wi, kd, w[2] * INV_PI, False


@jit
def _diffuse_eval(kd, wo, wi):
    if wo[2] * wi[2] <= 0.0:
        return _ZERO3
    return _scale3(kd, abs(wi[2]) * INV_PI)


@jit
def _diffuse_pdf(wo, wi):
    if wo[2] * wi[2] <= 0.0:
        return 0.0
    return abs(wi[2]) * INV_PI


# --- Conductor (GGX, Schlick) --------------------------------------------------------------------
@jit
def _conductor_sample(ks, alpha, wo, u0, u1):
    if wo[2] == 0.0:
        return _fail()
    # Mirror the frame so that wo is above the surface
    w = _upper(wo)
    g1 = ggx_g1(w, alpha)
    if g1 <= 0.0:
        return _fail()
    # Visible normal, then mirror reflection about it
    h = sample_ggx_vndf(w, alpha, u0, u1)
    cos_oh = dot(w, h)
    wl = _reflect(w, h)
    if cos_oh <= 0.0 or wl[2] <= 0.0:
        return _fail()
    pdf = g1 * ggx_d(h, alpha) / (4.0 * w[2])
    if not pdf > 0.0:
        return _fail()
    # weight = F D G2 / (4 cos_o) / pdf = F G2 / G1
    f = fresnel_schlick(ks, cos_oh)
    beta = _scale3(f, ggx_g2(w, wl, alpha) / g1)
    wi = (wl[0], wl[1], wl[2] if wo[2] > 0.0 else -wl[2])
    return wi, beta, pdf, False


@jit
def _conductor_eval(ks, alpha, wo, wi):
    if wo[2] * wi[2] <= 0.0:
        return _ZERO3
    w = _upper(wo)
    wl = _upper(wi)
    h = normalize((w[0] + wl[0], w[1] + wl[1], w[2] + wl[2]))
    f = fresnel_schlick(ks, dot(w, h))
    # f cos_i = F D G2 / (4 cos_o cos_i) * cos_i
    s = ggx_d(h, alpha) * ggx_g2(w, wl, alpha) / (4.0 * w[2])
    return _scale3(f, s)


@jit
def _microfacet_reflection_pdf(alpha, wo, wi):
    """D_wo(h) / (4 wo.h) = G1(wo) D(h) / (4 wo.z) for reflection on the side of wo, else 0."""
    if wo[2] * wi[2] <= 0.0:
        return 0.0
    w = _upper(wo)
    wl = _upper(wi)
    h = normalize((w[0] + wl[0], w[1] + wl[1], w[2] + wl[2]))
    return ggx_g1(w, alpha) * ggx_d(h, alpha) / (4.0 * w[2])


# --- Mirror -----------------------------------------------------------------------------------
@jit
def _mirror_sample(ks, wo):
    if wo[2] == 0.0:
        return _fail()
    return (-wo[0], -wo[1], wo[2]), ks, 1.0, True


# --- Smooth dielectric ---------------------------------------------------------------------------
@jit
def _dielectric_sample(ior, wo, u2, radiance):
    if wo[2] == 0.0 or not ior > 0.0:
        return _fail()
    # Relative index eta = n_i / n_o across the interface as seen from wo
    sgn = 1.0 if wo[2] > 0.0 else -1.0
    eta = ior if wo[2] > 0.0 else 1.0 / ior
    f, cos_t = fresnel_dielectric(abs(wo[2]), eta)
    # Choose the lobe with the Fresnel probability
    if u2 < f:
        return (-wo[0], -wo[1], wo[2]), (1.0, 1.0, 1.0), f, True
    # Snell's law: tangential part scales by 1 / eta, wi leaves on the far side
    wi = (-wo[0] / eta, -wo[1] / eta, -sgn * cos_t)
    s = 1.0 / (eta * eta) if radiance else 1.0
    return wi, (s, s, s), 1.0 - f, True


# --- Rough dielectric (Walter et al. 2007) ------------------------------------------------------
@jit
def _rough_dielectric_sample(alpha, ior, wo, u0, u1, u2, radiance):
    if wo[2] == 0.0 or not ior > 0.0:
        return _fail()
    # Work in the frame mirrored so that wo is above; eta = n_i / n_o
    sgn = 1.0 if wo[2] > 0.0 else -1.0
    eta = ior if wo[2] > 0.0 else 1.0 / ior
    w = _upper(wo)
    g1 = ggx_g1(w, alpha)
    if g1 <= 0.0:
        return _fail()
    # Visible microfacet normal and its Fresnel reflectance
    h = sample_ggx_vndf(w, alpha, u0, u1)
    cos_oh = dot(w, h)
    if cos_oh <= 0.0 or h[2] <= 0.0:
        return _fail()
    d = ggx_d(h, alpha)
    pdf_h = g1 * cos_oh * d / w[2]
    f, cos_t = fresnel_dielectric(cos_oh, eta)
    if u2 < f:
        # Reflect about h: pdf = F D_wo(h) / (4 wo.h), weight = G2 / G1
        wl = _reflect(w, h)
        if wl[2] <= 0.0:
            return _fail()
        pdf = f * pdf_h / (4.0 * cos_oh)
        beta = ggx_g2(w, wl, alpha) / g1
    else:
        # Refract through h: pdf = (1 - F) D_wo(h) |dh/dwi|, weight = G2 / G1 (/ eta^2)
        k = cos_oh / eta - cos_t
        wl = (-w[0] / eta + k * h[0], -w[1] / eta + k * h[1], -w[2] / eta + k * h[2])
        if wl[2] >= 0.0:
            return _fail()
        denom = cos_oh - eta * cos_t  # wo.h + eta wi.h, with wi.h = -cos_t
        if denom == 0.0:
            return _fail()
        pdf = (1.0 - f) * pdf_h * eta * eta * cos_t / (denom * denom)
        beta = ggx_g2(w, wl, alpha) / g1
        if radiance:
            beta /= eta * eta
    if not (pdf > 0.0 and pdf < math.inf):
        return _fail()
    wi = (wl[0], wl[1], sgn * wl[2])
    return wi, (beta, beta, beta), pdf, False


@jit
def _rough_dielectric_eval_pdf(alpha, ior, wo, wi, radiance):
    """(f |cos wi| (scalar), pdf) of the rough dielectric."""
    if wo[2] == 0.0 or wi[2] == 0.0 or not ior > 0.0:
        return 0.0, 0.0
    eta = ior if wo[2] > 0.0 else 1.0 / ior
    # Mirror the frame so that wo is above
    w = _upper(wo)
    wl = (wi[0], wi[1], wi[2] if wo[2] > 0.0 else -wi[2])
    g1 = ggx_g1(w, alpha)
    if wl[2] > 0.0:
        # Reflection: half vector
        h = normalize((w[0] + wl[0], w[1] + wl[1], w[2] + wl[2]))
        cos_oh = dot(w, h)
        if cos_oh <= 0.0:
            return 0.0, 0.0
        f, _ = fresnel_dielectric(cos_oh, eta)
        d = ggx_d(h, alpha)
        fcos = f * d * ggx_g2(w, wl, alpha) / (4.0 * w[2])
        pdf = f * g1 * d / (4.0 * w[2])
        return fcos, pdf
    # Refraction: generalised half vector h ~ wo + eta wi, turned toward the side of wo
    h = normalize((w[0] + eta * wl[0], w[1] + eta * wl[1], w[2] + eta * wl[2]))
    if h[2] < 0.0:
        h = (-h[0], -h[1], -h[2])
    cos_oh = dot(w, h)
    cos_ih = dot(wl, h)
    if h[2] <= 0.0 or cos_oh <= 0.0 or cos_ih >= 0.0:
        return 0.0, 0.0
    f, _ = fresnel_dielectric(cos_oh, eta)
    denom = cos_oh + eta * cos_ih
    if f >= 1.0 or denom == 0.0:
        return 0.0, 0.0
    d = ggx_d(h, alpha)
    jac = eta * eta * abs(cos_ih) / (denom * denom)  # |dh / dwi|
    # f cos_i = (1 - F) D G2 |wi.h| |wo.h| / (|wo.z| (wo.h + eta wi.h)^2), times eta^2 when
    # transporting importance
    fcos = (1.0 - f) * d * ggx_g2(w, wl, alpha) * abs(cos_ih) * cos_oh / (w[2] * denom * denom)
    if not radiance:
        fcos *= eta * eta
    pdf = (1.0 - f) * g1 * cos_oh * d / w[2] * jac
    return fcos, pdf


# --- Plastic (Lambert + GGX, no Fresnel) ---------------------------------------------------------
@jit
def _plastic_spec_prob(kd, ks):
    """Probability of sampling the GGX lobe: lum(ks) / (lum(ks) + lum(kd)), 0.5 if both are 0."""
    ls = max(lum(ks), 0.0)
    ld = max(lum(kd), 0.0)
    if ls + ld <= 0.0:
        return 0.5
    return ls / (ls + ld)


@jit
def _plastic_eval_pdf(kd, ks, alpha, wo, wi):
    """(f |cos wi| (3-tuple), pdf) of the plastic, both zero unless wo and wi share a side."""
    if wo[2] * wi[2] <= 0.0:
        return _ZERO3, 0.0
    w = _upper(wo)
    wl = _upper(wi)
    h = normalize((w[0] + wl[0], w[1] + wl[1], w[2] + wl[2]))
    d = ggx_d(h, alpha)
    spec = d * ggx_g2(w, wl, alpha) / (4.0 * w[2])
    diff = wl[2] * INV_PI
    fcos = (
        kd[0] * diff + ks[0] * spec,
        kd[1] * diff + ks[1] * spec,
        kd[2] * diff + ks[2] * spec,
    )
    p_s = _plastic_spec_prob(kd, ks)
    pdf = p_s * ggx_g1(w, alpha) * d / (4.0 * w[2]) + (1.0 - p_s) * diff
    return fcos, pdf


@jit
def _plastic_sample(kd, ks, alpha, wo, u0, u1, u2):
    if wo[2] == 0.0:
        return _fail()
    w = _upper(wo)
    # Pick the lobe, then a direction above the surface from it
    if u2 < _plastic_spec_prob(kd, ks):
        h = sample_ggx_vndf(w, alpha, u0, u1)
        wl = _reflect(w, h)
    else:
        wl = sample_cosine_hemisphere(u0, u1)
    if wl[2] <= 0.0:
        return _fail()
    wi = (wl[0], wl[1], wl[2] if wo[2] > 0.0 else -wl[2])
    # One-sample mixture: weight = f cos / (p_s pdf_spec + (1 - p_s) pdf_diffuse)
    fcos, pdf = _plastic_eval_pdf(kd, ks, alpha, wo, wi)
    if not (pdf > 0.0 and pdf < math.inf):
        return _fail()
    return wi, _scale3(fcos, 1.0 / pdf), pdf, False


# --- Mitsuba's conductor (complex Fresnel; GGX or Beckmann; separable masking) ----------------
@jit
def fresnel_conductor(cos_i, eta, k):
    """Unpolarised Fresnel reflectance of a conductor of complex index eta + i k (relative to the
    outside) at incidence cosine cos_i in [0, 1] (the exact formula, as in Moeller's "Optics");
    exactly 1 for eta = k = 0 (Mitsuba's material "none")."""
    c2 = cos_i * cos_i
    s2 = 1.0 - c2
    s4 = s2 * s2
    t1 = eta * eta - k * k - s2
    a2b2 = math.sqrt(max(t1 * t1 + 4.0 * k * k * eta * eta, 0.0))
    a = math.sqrt(max(0.5 * (a2b2 + t1), 0.0))
    term1 = a2b2 + c2
    term2 = 2.0 * cos_i * a
    rs = (term1 - term2) / (term1 + term2)
    term3 = a2b2 * c2 + s4
    term4 = term2 * s2
    den = term3 + term4  # 0 only at normal incidence on eta = k = 0, where rp = rs
    rp = rs * (term3 - term4) / den if den > 0.0 else rs
    return 0.5 * (rs + rp)


@jit
def _metal_f(prm, cos_h):
    """ks x Fresnel per channel at cos_h."""
    return (prm[3] * fresnel_conductor(cos_h, prm[8], prm[11]), prm[4] * fresnel_conductor(cos_h, prm[9], prm[12]),
            prm[5] * fresnel_conductor(cos_h, prm[10], prm[13]))


@jit
def beckmann_d(h, alpha):
    """Beckmann density of microfacet normals exp(-tan^2 / a^2) / (pi a^2 cos^4); 0 below."""
    if h[2] <= 0.0:
        return 0.0
    c2 = h[2] * h[2]
    e = (h[0] * h[0] + h[1] * h[1]) / (c2 * alpha * alpha)
    if e > 700.0:  # exp(-e) underflows (and c2^2 may too)
        return 0.0
    return math.exp(-e) / (math.pi * alpha * alpha * c2 * c2)


@jit
def smith_g1(w, h, alpha, beckmann):
    """Smith's G1 of direction w for microfacet normal h, as Mitsuba 3 evaluates it: GGX exact,
    Beckmann by Walter et al.'s rational fit; 0 where w sees the back of the microfacet."""
    if dot(w, h) * w[2] <= 0.0:
        return 0.0
    xy2 = alpha * alpha * (w[0] * w[0] + w[1] * w[1])
    if xy2 == 0.0:
        return 1.0
    t2 = xy2 / (w[2] * w[2])
    if not beckmann:
        return 2.0 / (1.0 + math.sqrt(1.0 + t2))
    a = 1.0 / math.sqrt(t2)
    if a >= 1.6:
        return 1.0
    return (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)


@jit
def _metal_frame(prm, wo):
    """(w, ok): wo in the upper hemisphere, or not ok (a one-sided metal seen from behind)."""
    if wo[2] == 0.0 or (wo[2] < 0.0 and int(prm[14]) & ONE_SIDED):
        return wo, False
    return _upper(wo), True


@jit
def _metal_sample(prm, wo, u0, u1):
    w, ok = _metal_frame(prm, wo)
    if not ok:
        return _fail()
    alpha = prm[6]
    if alpha <= 0.0:
        return (-wo[0], -wo[1], wo[2]), _metal_f(prm, w[2]), 1.0, True
    alpha = max(alpha, ALPHA_MIN)
    beck = int(prm[14]) & BECKMANN
    h = _sample_normal(w, alpha, beck, u0, u1)
    cos_oh = dot(w, h)
    wl = _reflect(w, h)
    if cos_oh <= 0.0 or wl[2] <= 0.0:
        return _fail()
    pdf = _metal_pdf_h(w, h, alpha, beck)
    if not pdf > 0.0:
        return _fail()
    fc = _metal_fcos(prm, w, wl, h, alpha, beck)
    wi = (wl[0], wl[1], wl[2] if wo[2] > 0.0 else -wl[2])
    return wi, _scale3(fc, 1.0 / pdf), pdf, False


@jit
def _sample_normal(w, alpha, beck, u0, u1):
    """A microfacet normal for METAL and COATED: GGX's visible normals from w, or Beckmann's D(h)
    cos(h) (tan^2 = -a^2 log(1 - u0)); densities in _metal_pdf_h."""
    if beck:
        t2 = -alpha * alpha * math.log(1.0 - u0)
        c = 1.0 / math.sqrt(1.0 + t2)
        sn = math.sqrt(max(0.0, 1.0 - c * c))
        phi = 2.0 * math.pi * u1
        return (sn * math.cos(phi), sn * math.sin(phi), c)
    return sample_ggx_vndf(w, alpha, u0, u1)


@jit
def _metal_pdf_h(w, h, alpha, beck):
    """Density of the reflected direction about h: visible normals (GGX) or D(h) cos(h)
    (Beckmann), over the Jacobian 4 w.h."""
    cos_oh = dot(w, h)
    if cos_oh <= 0.0:
        return 0.0
    if beck:
        return beckmann_d(h, alpha) * h[2] / (4.0 * cos_oh)
    return smith_g1(w, h, alpha, False) * ggx_d(h, alpha) / (4.0 * w[2])


@jit
def _metal_fcos(prm, w, wl, h, alpha, beck):
    """F D G1(w) G1(wl) / (4 w.z) (f |cos wl|), both in the upper hemisphere."""
    d = beckmann_d(h, alpha) if beck else ggx_d(h, alpha)
    g = smith_g1(w, h, alpha, beck) * smith_g1(wl, h, alpha, beck)
    return _scale3(_metal_f(prm, dot(w, h)), d * g / (4.0 * w[2]))


@jit
def _metal_eval_pdf(prm, wo, wi):
    if wo[2] * wi[2] <= 0.0 or prm[6] <= 0.0:
        return _ZERO3, 0.0
    w, ok = _metal_frame(prm, wo)
    if not ok:
        return _ZERO3, 0.0
    wl = _upper(wi)
    alpha = max(prm[6], ALPHA_MIN)
    beck = int(prm[14]) & BECKMANN
    h = normalize((w[0] + wl[0], w[1] + wl[1], w[2] + wl[2]))
    return _metal_fcos(prm, w, wl, h, alpha, beck), _metal_pdf_h(w, h, alpha, beck)


# --- Mitsuba's plastic and roughplastic: a dielectric coat over a diffuse base -----------------
@jit
def _coat_t(table, row, c):
    """The rough coat's transmittance at cosine c, lerped in its table row (Mitsuba's lerp_gather)."""
    n = table.shape[1]
    x = c * (n - 1)
    i = min(int(x), n - 2)
    f = x - i
    return table[row, i] * (1.0 - f) + table[row, i + 1] * f


@jit
def _coat_transmittance(prm, table, c):
    """Transmittance of the coat at cosine c: 1 - F (smooth), the table's (rough)."""
    if prm[6] <= 0.0:
        return 1.0 - fresnel_dielectric(c, prm[7])[0]
    return _coat_t(table, int(prm[10]), c)


@jit
def _coat_spec_prob(prm, table, c):
    """Probability that sampling picks the coat's specular lobe at the viewer's cosine c: the
    reflected share (F, or 1 - t) weighted by params[P_SPEC_WEIGHT], as Mitsuba's plastics."""
    sw = prm[8]
    r = 1.0 - _coat_transmittance(prm, table, c)
    ps = r * sw
    tot = ps + (1.0 - r) * (1.0 - sw)
    return ps / tot if tot > 0.0 else 0.0


@jit
def _coat_diffuse(prm, table, ci, co):
    """The diffuse term f(wo, wi) of the coat (both cosines positive): kd / (1 - r_in) t(ci) t(co)
    / (pi eta^2), r_in params[P_INTERNAL] (times kd per channel with NONLINEAR)."""
    eta = prm[7]
    s = _coat_transmittance(prm, table, ci) * _coat_transmittance(prm, table, co) * INV_PI / (eta * eta)
    r = prm[9]
    if int(prm[14]) & NONLINEAR:
        return (prm[0] / (1.0 - prm[0] * r) * s, prm[1] / (1.0 - prm[1] * r) * s, prm[2] / (1.0 - prm[2] * r) * s)
    k = s / (1.0 - r)
    return (prm[0] * k, prm[1] * k, prm[2] * k)


@jit
def _coated_eval_pdf(prm, table, wo, wi):
    """(f |cos wi|, density) of the coat's non-delta part: diffuse, plus the rough coat's specular
    lobe ks F D G1 G1 / (4 cos_o) sampled as METAL's."""
    if wo[2] * wi[2] <= 0.0:
        return _ZERO3, 0.0
    w = _upper(wo)
    wl = _upper(wi)
    ps = _coat_spec_prob(prm, table, w[2])
    fc = _scale3(_coat_diffuse(prm, table, w[2], wl[2]), wl[2])
    pdf = (1.0 - ps) * wl[2] * INV_PI
    if prm[6] > 0.0:
        alpha = max(prm[6], ALPHA_MIN)
        beck = int(prm[14]) & BECKMANN
        h = normalize((w[0] + wl[0], w[1] + wl[1], w[2] + wl[2]))
        d = beckmann_d(h, alpha) if beck else ggx_d(h, alpha)
        g = smith_g1(w, h, alpha, beck) * smith_g1(wl, h, alpha, beck)
        sc = fresnel_dielectric(dot(w, h), prm[7])[0] * d * g / (4.0 * w[2])
        fc = (fc[0] + prm[3] * sc, fc[1] + prm[4] * sc, fc[2] + prm[5] * sc)
        pdf += ps * _metal_pdf_h(w, h, alpha, beck)
    return fc, pdf


@jit
def _coated_sample(prm, table, wo, u0, u1, u2):
    if wo[2] == 0.0:
        return _fail()
    w = _upper(wo)
    ps = _coat_spec_prob(prm, table, w[2])
    sgn = 1.0 if wo[2] > 0.0 else -1.0
    if u2 < ps:
        if prm[6] <= 0.0:  # the smooth coat's mirror lobe
            f = fresnel_dielectric(w[2], prm[7])[0] / ps
            return (-wo[0], -wo[1], wo[2]), (prm[3] * f, prm[4] * f, prm[5] * f), ps, True
        alpha = max(prm[6], ALPHA_MIN)
        h = _sample_normal(w, alpha, int(prm[14]) & BECKMANN, u0, u1)
        wl = _reflect(w, h)
        if dot(w, h) <= 0.0 or wl[2] <= 0.0:
            return _fail()
    else:
        wl = sample_cosine_hemisphere(u0, u1)
        if wl[2] <= 0.0:
            return _fail()
    wi = (wl[0], wl[1], sgn * wl[2])
    fc, pdf = _coated_eval_pdf(prm, table, wo, wi)
    if not pdf > 0.0:
        return _fail()
    return wi, _scale3(fc, 1.0 / pdf), pdf, False


# --- Mitsuba's thin dielectric -------------------------------------------------------------------
@jit
def _thin_reflectance(prm, wo):
    """Reflectance of the slab at wo, inter-reflections included: R + T^2 R / (1 - R^2)."""
    r, _ = fresnel_dielectric(abs(wo[2]), prm[7])
    if r < 1.0:
        r = 2.0 * r / (1.0 + r)
    return r


# --- Public interface: dispatch on the material type -------------------------------------------
@jit(inline="always")
def bsdf_sample(bp, wo, u0, u1, u2, radiance, table):
    """Importance-sample wi for material m given wo (local frame).

    u0, u1 pick the direction, u2 the lobe. Returns (wi, weight, pdf, delta):
    wi 3-tuple; weight 3-tuple f |cos wi| / pdf (delta lobes: their discrete weight);
    pdf the solid-angle density of the whole BSDF's sampling at wi (delta lobes: the lobe's
    discrete probability); delta True when wi came from a delta lobe. A failed sample returns
    wi = weight = (0, 0, 0), pdf 0, delta False. A material with clear = params[P_CLEAR] > 0 (an
    opacity mask) passes straight through with probability clear (weight 1, a delta lobe) and
    scatters by its BSDF otherwise (u2 rescaled; densities times 1 - clear).
    """
    c = bp[1][16]
    if c > 0.0:
        if u2 < c:
            if wo[2] == 0.0:
                return _fail()
            return (-wo[0], -wo[1], -wo[2]), (1.0, 1.0, 1.0), c, True
        wi, wt, pdf, dlt = _sample_opaque(bp, wo, u0, u1, min((u2 - c) / (1.0 - c), 1.0 - 1e-12), radiance, table)
        return wi, wt, pdf * (1.0 - c), dlt
    return _sample_opaque(bp, wo, u0, u1, u2, radiance, table)


@jit(inline="always")
def bsdf_eval(bp, wo, wi, radiance, table):
    """f(wo, wi) |cos wi| as a 3-tuple (local frame), times the opacity; (0, 0, 0) for delta
    materials."""
    c = bp[1][16]
    if c > 0.0:
        return _scale3(_eval_opaque(bp, wo, wi, radiance, table), 1.0 - c)
    return _eval_opaque(bp, wo, wi, radiance, table)


@jit(inline="always")
def bsdf_pdf(bp, wo, wi, table):
    """Solid-angle density with which `bsdf_sample` produces wi; 0 for delta materials."""
    c = bp[1][16]
    if c > 0.0:
        return _pdf_opaque(bp, wo, wi, table) * (1.0 - c)
    return _pdf_opaque(bp, wo, wi, table)


@jit(inline="always")
def bsdf_eval_pdf(bp, wo, wi, radiance, table):
    """(bsdf_eval, bsdf_pdf) of one pair of directions, the same values bit for bit, with a
    glossy lobe's work (its microfacet terms, a coat's table lookups) done once for both."""
    f, pdf = _eval_pdf_opaque(bp, wo, wi, radiance, table)
    c = bp[1][16]
    if c > 0.0:
        return _scale3(f, 1.0 - c), pdf * (1.0 - c)
    return f, pdf


@jit
def delta_lobe(bp, wo, transmit, radiance):
    """The delta lobe of material m that reflects wo (transmit False) or refracts it (True), as
    bsdf_sample would pick it: (wi, value f |cos| in the discrete measure, probability that
    bsdf_sample picks this lobe). Probability 0 where there is no such lobe (a material that is not
    delta, total internal reflection, a grazing wo). With an opacity mask, the transmitted lobe is
    the straight pass (value and probability clear) and a reflected one is scaled by 1 - clear."""
    c = bp[1][16]
    if c > 0.0:
        if transmit:
            if wo[2] == 0.0:
                return _ZERO3, _ZERO3, 0.0
            return (-wo[0], -wo[1], -wo[2]), (c, c, c), c
        wi, val, prob = _delta_lobe_opaque(bp, wo, False, radiance)
        return wi, _scale3(val, 1.0 - c), prob * (1.0 - c)
    return _delta_lobe_opaque(bp, wo, transmit, radiance)


@jit
def _sample_opaque(bp, wo, u0, u1, u2, radiance, table):
    """bsdf_sample without the opacity mask."""
    t, prm = bp[0], bp[1]
    if prm[14] != 0.0 and int(prm[14]) & ONE_SIDED and wo[2] <= 0.0:
        return _fail()
    if t == DIFFUSE:
        return _diffuse_sample(_kd(prm), wo, u0, u1)
    if t == CONDUCTOR:
        return _conductor_sample(_ks(prm), _alpha(prm), wo, u0, u1)
    if t == MIRROR:
        return _mirror_sample(_ks(prm), wo)
    if t == DIELECTRIC:
        return _dielectric_sample(prm[7], wo, u2, radiance)
    if t == ROUGH_DIELECTRIC:
        return _rough_dielectric_sample(
            _alpha(prm), prm[7], wo, u0, u1, u2, radiance
        )
    if t == PLASTIC:
        return _plastic_sample(
            _kd(prm), _ks(prm), _alpha(prm), wo, u0, u1, u2
        )
    if t == METAL:
        return _metal_sample(prm, wo, u0, u1)
    if t == COATED:
        return _coated_sample(prm, table, wo, u0, u1, u2)
    if t == THIN_DIELECTRIC:
        if wo[2] == 0.0:
            return _fail()
        r = _thin_reflectance(prm, wo)
        if u2 < r:
            return (-wo[0], -wo[1], wo[2]), (1.0, 1.0, 1.0), r, True
        return (-wo[0], -wo[1], -wo[2]), (1.0, 1.0, 1.0), 1.0 - r, True
    return _fail()


@jit
def _eval_opaque(bp, wo, wi, radiance, table):
    """bsdf_eval without the opacity mask."""
    t, prm = bp[0], bp[1]
    if prm[14] != 0.0 and int(prm[14]) & ONE_SIDED and wo[2] <= 0.0:
        return _ZERO3
    if t == DIFFUSE:
        return _diffuse_eval(_kd(prm), wo, wi)
    if t == CONDUCTOR:
        return _conductor_eval(_ks(prm), _alpha(prm), wo, wi)
    if t == ROUGH_DIELECTRIC:
        fcos, _ = _rough_dielectric_eval_pdf(
            _alpha(prm), prm[7], wo, wi, radiance
        )
        return (fcos, fcos, fcos)
    if t == PLASTIC:
        fcos, _ = _plastic_eval_pdf(
            _kd(prm), _ks(prm), _alpha(prm), wo, wi
        )
        return fcos
    if t == METAL:
        fcos, _ = _metal_eval_pdf(prm, wo, wi)
        return fcos
    if t == COATED:
        fcos, _ = _coated_eval_pdf(prm, table, wo, wi)
        return fcos
    return _ZERO3


@jit
def _pdf_opaque(bp, wo, wi, table):
    """bsdf_pdf without the opacity mask."""
    t, prm = bp[0], bp[1]
    if prm[14] != 0.0 and int(prm[14]) & ONE_SIDED and wo[2] <= 0.0:
        return 0.0
    if t == DIFFUSE:
        return _diffuse_pdf(wo, wi)
    if t == CONDUCTOR:
        return _microfacet_reflection_pdf(_alpha(prm), wo, wi)
    if t == ROUGH_DIELECTRIC:
        _, pdf = _rough_dielectric_eval_pdf(_alpha(prm), prm[7], wo, wi, True)
        return pdf
    if t == PLASTIC:
        _, pdf = _plastic_eval_pdf(
            _kd(prm), _ks(prm), _alpha(prm), wo, wi
        )
        return pdf
    if t == METAL:
        _, pdf = _metal_eval_pdf(prm, wo, wi)
        return pdf
    if t == COATED:
        _, pdf = _coated_eval_pdf(prm, table, wo, wi)
        return pdf
    return 0.0


@jit
def _eval_pdf_opaque(bp, wo, wi, radiance, table):
    """(_eval_opaque, _pdf_opaque) in one call."""
    t, prm = bp[0], bp[1]
    if prm[14] != 0.0 and int(prm[14]) & ONE_SIDED and wo[2] <= 0.0:
        return _ZERO3, 0.0
    if t == DIFFUSE:
        return _diffuse_eval(_kd(prm), wo, wi), _diffuse_pdf(wo, wi)
    if t == CONDUCTOR:
        return _conductor_eval(_ks(prm), _alpha(prm), wo, wi), _microfacet_reflection_pdf(_alpha(prm), wo, wi)
    if t == ROUGH_DIELECTRIC:
        fcos, pdf = _rough_dielectric_eval_pdf(_alpha(prm), prm[7], wo, wi, radiance)
        return (fcos, fcos, fcos), pdf
    if t == PLASTIC:
        return _plastic_eval_pdf(_kd(prm), _ks(prm), _alpha(prm), wo, wi)
    if t == METAL:
        return _metal_eval_pdf(prm, wo, wi)
    if t == COATED:
        return _coated_eval_pdf(prm, table, wo, wi)
    return _ZERO3, 0.0


@jit
def bsdf_is_delta(bp):
    """True for materials that only scatter into discrete directions (MIRROR, DIELECTRIC,
    THIN_DIELECTRIC, METAL with alpha 0)."""
    t, prm = bp[0], bp[1]
    return t == MIRROR or t == DIELECTRIC or t == THIN_DIELECTRIC or (t == METAL and prm[6] <= 0.0)


@jit
def bsdf_has_delta(bp):
    """True for materials with a delta lobe: the delta materials, the smooth COATED (its mirror lobe
    beside the diffuse one) and every material with an opacity mask (its straight pass);
    bsdf_sample flags the samples it draws from them."""
    return bsdf_is_delta(bp) or (bp[0] == COATED and bp[1][6] <= 0.0) or bp[1][16] > 0.0


@jit
def bsdf_roughness(bp):
    """The smallest roughness of material m's lobes (the gradient-domain tracer's hybrid shift
    reconnects only between rough vertices): inf for diffuse, the GGX alpha for conductor, rough
    dielectric and plastic (its specular lobe), 0 for the delta materials."""
    t, prm = bp[0], bp[1]
    if t == DIFFUSE:
        return math.inf
    if t == CONDUCTOR or t == ROUGH_DIELECTRIC or t == PLASTIC:
        return _alpha(prm)
    if (t == METAL or t == COATED) and prm[6] > 0.0:
        return _alpha(prm)
    return 0.0


@jit
def _delta_lobe_opaque(bp, wo, transmit, radiance):
    """delta_lobe without the opacity mask."""
    t, prm = bp[0], bp[1]
    if wo[2] == 0.0:
        return _ZERO3, _ZERO3, 0.0
    if prm[14] != 0.0 and int(prm[14]) & ONE_SIDED and wo[2] < 0.0:
        return _ZERO3, _ZERO3, 0.0
    if t == MIRROR:
        if transmit:
            return _ZERO3, _ZERO3, 0.0
        return (-wo[0], -wo[1], wo[2]), _ks(prm), 1.0
    if t == METAL and prm[6] <= 0.0:
        if transmit:
            return _ZERO3, _ZERO3, 0.0
        return (-wo[0], -wo[1], wo[2]), _metal_f(prm, abs(wo[2])), 1.0
    if t == COATED and prm[6] <= 0.0:
        if transmit:
            return _ZERO3, _ZERO3, 0.0
        f = fresnel_dielectric(abs(wo[2]), prm[7])[0]
        ps = f * prm[8]
        tot = ps + (1.0 - f) * (1.0 - prm[8])  # _coat_spec_prob of the smooth coat
        return (-wo[0], -wo[1], wo[2]), (prm[3] * f, prm[4] * f, prm[5] * f), ps / tot if tot > 0.0 else 0.0
    if t == THIN_DIELECTRIC:
        r = _thin_reflectance(prm, wo)
        if transmit:
            return (-wo[0], -wo[1], -wo[2]), (1.0 - r, 1.0 - r, 1.0 - r), 1.0 - r
        return (-wo[0], -wo[1], wo[2]), (r, r, r), r
    if t != DIELECTRIC or not prm[7] > 0.0:
        return _ZERO3, _ZERO3, 0.0
    ior = prm[7]
    sgn = 1.0 if wo[2] > 0.0 else -1.0
    eta = ior if wo[2] > 0.0 else 1.0 / ior
    f, cos_t = fresnel_dielectric(abs(wo[2]), eta)
    if not transmit:
        return (-wo[0], -wo[1], wo[2]), (f, f, f), f
    if f >= 1.0:
        return _ZERO3, _ZERO3, 0.0
    s = (1.0 - f) / (eta * eta) if radiance else 1.0 - f
    return (-wo[0] / eta, -wo[1] / eta, -sgn * cos_t), (s, s, s), 1.0 - f


@jit
def bsdf_albedo(bp):
    """A cheap albedo 3-tuple for the AOV: kd (diffuse, coated); ks (metals; METAL: ks x its normal-incidence Fresnel);
    min(kd + ks, 1) (plastic); 1 (glass)."""
    t, prm = bp[0], bp[1]
    if t == DIFFUSE or t == COATED:
        return _kd(prm)
    if t == CONDUCTOR or t == MIRROR:
        return _ks(prm)
    if t == PLASTIC:
        return (
            min(prm[0] + prm[3], 1.0),
            min(prm[1] + prm[4], 1.0),
            min(prm[2] + prm[5], 1.0),
        )
    if t == METAL:
        return _metal_f(prm, 1.0)
    if t == DIELECTRIC or t == ROUGH_DIELECTRIC or t == THIN_DIELECTRIC:
        return (1.0, 1.0, 1.0)
    return _ZERO3


# --- Batch kernels (tests, experiments) ----------------------------------------------------------
def _table(mat_type, mat_param, mat_table):
    """The (type, N_PARAM columns, tables) a batch kernel reads: rows padded with zeros, COATED rows
    prepared (tracer.coating.prepare) unless mat_table is given."""
    from .coating import prepare

    p = np.zeros((len(mat_type), N_PARAM))
    p[:, : np.shape(mat_param)[1]] = mat_param
    if mat_table is None:
        p, mat_table = prepare(mat_type, p)
    return np.asarray(mat_type, dtype=np.int32), p, np.ascontiguousarray(mat_table, dtype=np.float64)


def bsdf_tables(mat_type, mat_param):
    """The COATED tables of a material table, as build_scene makes them (tests: the `table` argument)."""
    return _table(mat_type, mat_param, None)[2]


def sample_batch(mat_type, mat_param, m, wo, u, radiance, mat_table=None):
    """`bsdf_sample` over a batch, all with material m.

    wo : (n, 3) float64 local directions; u : (n, 3) float64 in [0, 1) (u0, u1 direction, u2 lobe).
    Returns wi (n, 3) float64, weight (n, 3) float64, pdf (n,) float64 (solid angle, or the lobe
    probability where delta), delta (n,) bool.
    """
    return _sample_batch(*_table(mat_type, mat_param, mat_table), m, wo, u, radiance)


def eval_batch(mat_type, mat_param, m, wo, wi, radiance, mat_table=None):
    """`bsdf_eval` over a batch: wo, wi (n, 3) float64 local -> f |cos wi| (n, 3) float64."""
    return _eval_batch(*_table(mat_type, mat_param, mat_table), m, wo, wi, radiance)


def pdf_batch(mat_type, mat_param, m, wo, wi, mat_table=None):
    """`bsdf_pdf` over a batch: wo, wi (n, 3) float64 local -> solid-angle pdf (n,) float64."""
    return _pdf_batch(*_table(mat_type, mat_param, mat_table), m, wo, wi)


def eval_pdf_batch(mat_type, mat_param, m, wo, wi, radiance, mat_table=None):
    """`bsdf_eval_pdf` over a batch: wo, wi (n, 3) float64 local -> (f |cos wi| (n, 3), pdf (n,))."""
    return _eval_pdf_batch(*_table(mat_type, mat_param, mat_table), m, wo, wi, radiance)


@kernel
def _sample_batch(mat_type, mat_param, mat_table, m, wo, u, radiance):
    n = wo.shape[0]
    wi = np.empty((n, 3))
    beta = np.empty((n, 3))
    pdf = np.empty(n)
    delta = np.empty(n, dtype=np.bool_)
    for k in prange(n):
        w, b, p, d = bsdf_sample(
            bsdf_at(mat_type, mat_param, m), (wo[k, 0], wo[k, 1], wo[k, 2]), u[k, 0], u[k, 1],
            u[k, 2], radiance, mat_table,
        )
        for c in range(3):
            wi[k, c] = w[c]
            beta[k, c] = b[c]
        pdf[k] = p
        delta[k] = d
    return wi, beta, pdf, delta


@kernel
def _eval_batch(mat_type, mat_param, mat_table, m, wo, wi, radiance):
    n = wo.shape[0]
    out = np.empty((n, 3))
    for k in prange(n):
        f = bsdf_eval(
            bsdf_at(mat_type, mat_param, m), (wo[k, 0], wo[k, 1], wo[k, 2]),
            (wi[k, 0], wi[k, 1], wi[k, 2]), radiance, mat_table,
        )
        for c in range(3):
            out[k, c] = f[c]
    return out


@kernel
def _eval_pdf_batch(mat_type, mat_param, mat_table, m, wo, wi, radiance):
    n = wo.shape[0]
    out = np.empty((n, 3))
    pdf = np.empty(n)
    for k in prange(n):
        f, pdf[k] = bsdf_eval_pdf(
            bsdf_at(mat_type, mat_param, m), (wo[k, 0], wo[k, 1], wo[k, 2]),
            (wi[k, 0], wi[k, 1], wi[k, 2]), radiance, mat_table,
        )
        for c in range(3):
            out[k, c] = f[c]
    return out, pdf


@kernel
def _pdf_batch(mat_type, mat_param, mat_table, m, wo, wi):
    n = wo.shape[0]
    out = np.empty(n)
    for k in prange(n):
        out[k] = bsdf_pdf(
            bsdf_at(mat_type, mat_param, m), (wo[k, 0], wo[k, 1], wo[k, 2]), (wi[k, 0], wi[k, 1], wi[k, 2]),
            mat_table,
        )
    return out
