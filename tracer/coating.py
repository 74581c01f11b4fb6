"""The tables of Mitsuba's coated diffuse BSDFs (`plastic`, `roughplastic`: bsdfs.COATED), in NumPy.

A COATED material is a dielectric interface (relative index eta = params[P_IOR]) over a diffuse
base kd. Light enters through the interface, scatters in the base and leaves through it again; what
the interface reflects back inside is added as a geometric series (Mitsuba 3's model):

    f_diffuse(wo, wi) = kd / (1 - r_in) * t(wo) t(wi) / (pi eta^2),   r_in: the internal reflectance
                                                                       (kd r_in with `nonlinear`)

with t the interface's transmittance: 1 - F(cos) for the smooth coat, and for the rough one the
integral over the microfacets visible from w of (1 - F(w.m)) times the masking of the refracted
direction, tabulated at TABLE_RES cosines in [0, 1] (lerped; index 0 at cos 1e-6). r_in is
Mitsuba's fit of the diffuse Fresnel reflectance at 1 / eta (smooth) or twice the cosine-weighted
mean of the rough interface's reflectance from inside (rough). Both integrals use Mitsuba's
quadrature: Gauss-Legendre nodes (32 x 32 from outside, 128 x 128 from inside) mapped through the
visible-normal sampler of the distribution, so the table is the one Mitsuba computes.

`prepare` fills the derived columns of the material table (the specular sampling weight, r_in,
the table's row) and returns the (M, TABLE_RES) table the BSDF functions take as `table`.
"""
import functools

import numpy as np
from scipy.special import erf, erfinv

from . import bsdfs

TABLE_RES = 64  # cosines of the transmittance table (Mitsuba's MI_ROUGH_TRANSMITTANCE_RES)


def fresnel_diffuse_reflectance(eta):
    """Hemispherical-cosine mean of the dielectric Fresnel reflectance at relative index eta, by
    the fits Mitsuba 3 uses: Egan and Hilgeman (1973) for eta < 1, d'Eon and Irving (2011) above."""
    if eta < 1.0:
        return -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 / eta
    x = 1.0 / eta
    return 0.919317 + x * (-3.4793 + x * (6.75335 + x * (-7.80989 + x * (4.98554 + x * -1.36881))))


def _fresnel(cos_i, eta):
    """Unpolarised dielectric Fresnel reflectance and the refracted cosine (positive), for cos_i
    of either sign (negative: from inside, eta inverted), as arrays."""
    inside = cos_i < 0.0
    e = np.where(inside, 1.0 / eta, eta)
    c = np.abs(cos_i)
    s2t = (1.0 - c * c) / (e * e)
    tir = s2t >= 1.0
    ct = np.sqrt(np.maximum(1.0 - s2t, 0.0))
    rpar = (e * c - ct) / (e * c + ct)
    rperp = (c - e * ct) / (c + e * ct)
    f = np.where(tir, 1.0, 0.5 * (rpar * rpar + rperp * rperp))
    return f, np.where(tir, 0.0, ct), e


def _g1(w, m, alpha, beckmann):
    """Smith G1 of directions w (n, 3) for normals m (n, 3), as bsdfs.smith_g1."""
    xy2 = alpha * alpha * (w[:, 0] ** 2 + w[:, 1] ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t2 = xy2 / (w[:, 2] ** 2)
        if beckmann:
            a = 1.0 / np.sqrt(t2)
            g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))
        else:
            g = 2.0 / (1.0 + np.sqrt(1.0 + t2))
    g = np.where(xy2 == 0.0, 1.0, g)
    return np.where(np.einsum("ij,ij->i", w, m) * w[:, 2] <= 0.0, 0.0, g)


def _concentric_disk(u0, u1):
    a, b = 2.0 * u0 - 1.0, 2.0 * u1 - 1.0
    first = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(first, a, b)
        phi = np.where(first, np.pi / 4 * b / a, np.pi / 2 - np.pi / 4 * a / b)
    phi = np.where((a == 0.0) & (b == 0.0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def _visible_slopes(cos_i, u0, u1, beckmann):
    """Slopes of the visible normals of the unit-roughness distribution seen at cos_i (>0), for
    sample points (u0, u1): Mitsuba 3's sample_visible_11 (GGX: Heitz's projected-disk construction;
    Beckmann: Jakob's inversion by three Newton steps in the erf domain)."""
    if beckmann:
        tan_i = np.sqrt(np.maximum(1.0 - cos_i * cos_i, 0.0)) / cos_i
        with np.errstate(divide="ignore"):
            cot_i = 1.0 / tan_i
        maxval = erf(cot_i)
        u0 = np.clip(u0, 1e-6, 1.0 - 1e-6)
        u1 = np.clip(u1, 1e-6, 1.0 - 1e-6)
        x = maxval - (maxval + 1.0) * erf(np.sqrt(-np.log(u0)))
        u0 = u0 * (1.0 + maxval + tan_i * np.exp(-cot_i * cot_i) / np.sqrt(np.pi))
        for _ in range(3):
            slope = erfinv(x)
            value = 1.0 + x + tan_i * np.exp(-slope * slope) / np.sqrt(np.pi) - u0
            x = x - value / (1.0 - slope * tan_i)
        return erfinv(x), erfinv(2.0 * u1 - 1.0)
    px, py = _concentric_disk(u0, u1)
    s = 0.5 * (1.0 + cos_i)
    py = (1.0 - s) * np.sqrt(np.maximum(1.0 - px * px, 0.0)) + s * py
    x, y = px, py
    z = np.sqrt(np.maximum(1.0 - x * x - y * y, 0.0))
    sin_i = np.sqrt(np.maximum(1.0 - cos_i * cos_i, 0.0))
    norm = 1.0 / (sin_i * y + cos_i * z)
    return (cos_i * y - sin_i * z) * norm, x * norm


def _sample_visible(wi, alpha, u0, u1, beckmann):
    """Visible microfacet normals (n, 3) from directions wi (n, 3) (wi.y = 0, wi.z > 0), as
    Mitsuba's MicrofacetDistribution.sample with sample_visible."""
    wp = np.stack([alpha * wi[:, 0], alpha * wi[:, 1], wi[:, 2]], 1)
    wp /= np.linalg.norm(wp, axis=1, keepdims=True)
    sin_t = np.sqrt(np.maximum(1.0 - wp[:, 2] ** 2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_p = np.where(sin_t > 0.0, np.clip(wp[:, 0] / sin_t, -1.0, 1.0), 1.0)
        sin_p = np.where(sin_t > 0.0, np.clip(wp[:, 1] / sin_t, -1.0, 1.0), 0.0)
    sx, sy = _visible_slopes(wp[:, 2], u0, u1, beckmann)
    sx, sy = (cos_p * sx - sin_p * sy) * alpha, (sin_p * sx + cos_p * sy) * alpha
    m = np.stack([-sx, -sy, np.ones_like(sx)], 1)
    return m / np.linalg.norm(m, axis=1, keepdims=True)


def _quadrature(cos_i, alpha, eta, beckmann, transmit):
    """Mitsuba's eval_transmittance (transmit) / eval_reflectance at the cosines cos_i (n,)."""
    res = 32 if eta > 1.0 else 128
    nodes, weights = np.polynomial.legendre.leggauss(res)
    ux, uy = np.meshgrid(0.5 * nodes + 0.5, 0.5 * nodes + 0.5)
    wx, wy = np.meshgrid(weights, weights)
    ux, uy, wq = ux.ravel(), uy.ravel(), (wx * wy).ravel() * 0.25
    out = np.zeros(cos_i.size)
    for j, c in enumerate(cos_i):
        wi = np.tile([np.sqrt(max(1.0 - c * c, 0.0)), 0.0, c], (ux.size, 1))
        m = _sample_visible(wi, alpha, ux, uy, beckmann)
        cm = np.einsum("ij,ij->i", wi, m)
        f, ct, e = _fresnel(cm, eta)
        if transmit:
            # refract wi about m (Mitsuba's refract(wi, m, cos_theta_t, eta_ti)); ct signed opposite wi
            ct_s = np.where(cm >= 0.0, -ct, ct)
            eti = 1.0 / e
            wo = -wi * eti[:, None] + m * (cm * eti + ct_s)[:, None]
            g = _g1(wo, m, alpha, beckmann) * (1.0 - f)
            g = np.where(wo[:, 2] * wi[:, 2] >= 0.0, 0.0, g)
        else:
            wo = 2.0 * cm[:, None] * m - wi
            g = _g1(wo, m, alpha, beckmann) * f
            g = np.where((wo[:, 2] <= 0.0) | (wi[:, 2] <= 0.0), 0.0, g)
        out[j] = np.sum(g * wq)
    return out


def table_cosines():
    """The cosines of the table's entries (Mitsuba's: linspace(0, 1), the first raised to 1e-6)."""
    return np.maximum(np.linspace(0.0, 1.0, TABLE_RES), 1e-6)


def rough_coat(alpha, eta, beckmann):
    """(transmittance table (TABLE_RES,), internal reflectance) of a rough coat of GGX (or
    Beckmann) roughness alpha and relative index eta (computed once per process per triple)."""
    t, r = _rough_coat(float(alpha), float(eta), bool(beckmann))
    return t.copy(), r


@functools.lru_cache(maxsize=256)
def _rough_coat(alpha, eta, beckmann):
    mu = table_cosines()
    t = _quadrature(mu, alpha, eta, beckmann, True)
    r = _quadrature(mu, alpha, 1.0 / eta, beckmann, False)
    return t, 2.0 * float(np.mean(r * mu))


def prepare(mat_type, mat_param, kd_mean=None, ks_mean=None):
    """(param, table): a copy of the material table with the COATED rows' derived columns filled
    (P_SPEC_WEIGHT: Mitsuba's mean(ks) / (mean(kd) + mean(ks)); P_INTERNAL: r_in) and the (M,
    TABLE_RES) transmittance tables (zeros for other rows and for smooth coats). kd_mean, ks_mean:
    (M,) means of textured reflectances where they differ from the row's constants (None: the
    rows')."""
    param = np.array(mat_param, dtype=np.float64)
    table = np.zeros((len(mat_type), TABLE_RES))
    for m, t in enumerate(mat_type):
        if t != bsdfs.COATED:
            continue
        p = param[m]
        kd = float(np.mean(p[bsdfs.P_KD:bsdfs.P_KD + 3])) if kd_mean is None else float(kd_mean[m])
        ks = float(np.mean(p[bsdfs.P_KS:bsdfs.P_KS + 3])) if ks_mean is None else float(ks_mean[m])
        p[bsdfs.P_SPEC_WEIGHT] = ks / (kd + ks) if kd + ks > 0.0 else 0.5
        alpha, eta = float(p[bsdfs.P_ALPHA]), float(p[bsdfs.P_IOR])
        if alpha <= 0.0:
            p[bsdfs.P_INTERNAL] = fresnel_diffuse_reflectance(1.0 / eta)
            continue
        beck = bool(int(p[bsdfs.P_FLAGS]) & bsdfs.BECKMANN)
        table[m], p[bsdfs.P_INTERNAL] = rough_coat(alpha, eta, beck)
        p[bsdfs.P_TABLE_ROW] = m
    return param, table
