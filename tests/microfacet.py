"""Slow twins of the microfacet BSDFs and of the environment map's convention, in plain NumPy.

Written from the textbook formulas, not from tracer/bsdfs.py, so that a test can compare the two:

- GGX (Trowbridge-Reitz) in terms of the polar angle theta of the microfacet normal:
  D = 1 / (pi a^2 cos^4 (1 + tan^2 / a^2)^2); Smith Lambda = (-1 + sqrt(1 + a^2 tan^2)) / 2,
  G1 = 1 / (1 + Lambda), height-correlated G2 = 1 / (1 + Lambda(wo) + Lambda(wi)); the density of
  visible normals D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z (Heitz 2014/2018).
- Fresnel from the s and p amplitude coefficients; the rough dielectric of Walter et al. 2007
  (eqs. 20 and 21) with the macro normal fixed at +z, microfacet normals on the +z side.
- Quadratures over directions: composite Gauss-Legendre rules whose panel edges sit where the
  integrand jumps or kinks and whose panels are finest at its lobes (`sphere_rule`), so that they
  converge like rules for smooth functions; an error estimate comes from a lower-order rule.
- The equirectangular map of the README: u = 0.5 + atan2(x, -z) / 2pi, v = acos(y) / pi, +y up,
  row 0 at the top, inverted here as w(theta, phi) = (sin theta sin phi, cos theta,
  -sin theta cos phi) with theta = pi v, phi = 2 pi (u - 0.5).

Directions are (..., 3) float64 arrays in the local frame (+z the macro normal), unit length;
densities are per unit solid angle.
"""
import math

import numpy as np


# --- GGX -----------------------------------------------------------------------------------------
def tan2_of(w):
    """tan^2 of the polar angle of unit directions w (..., 3); inf in the plane z = 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return (w[..., 0] ** 2 + w[..., 1] ** 2) / w[..., 2] ** 2


def ggx_d(cos_h, tan2_h, alpha):
    """D(h) = 1 / (pi a^2 cos^4 (1 + tan^2 / a^2)^2) for cos_h > 0, else 0."""
    a2 = alpha * alpha
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        d = 1.0 / (math.pi * a2 * cos_h**4 * (1.0 + tan2_h / a2) ** 2)
    return np.where(cos_h > 0.0, d, 0.0)


def ggx_lambda(tan2, alpha):
    """Lambda = (-1 + sqrt(1 + a^2 tan^2)) / 2, evaluated as expm1(log1p(a^2 tan^2) / 2) / 2 so that
    it keeps its digits near the normal."""
    return 0.5 * np.expm1(0.5 * np.log1p(alpha * alpha * tan2))


def ggx_g1(tan2, alpha):
    return 1.0 / (1.0 + ggx_lambda(tan2, alpha))


def ggx_g2(tan2_o, tan2_i, alpha):
    """Height-correlated Smith masking-shadowing."""
    return 1.0 / (1.0 + ggx_lambda(tan2_o, alpha) + ggx_lambda(tan2_i, alpha))


def d_of(h, alpha):
    """D at unit normals h (..., 3)."""
    return ggx_d(h[..., 2], tan2_of(h), alpha)


def vndf_pdf(wo, h, alpha):
    """D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z; wo (3,) with wo.z > 0, h (..., 3)."""
    cos_oh = np.maximum(np.sum(h * wo, axis=-1), 0.0)
    return ggx_g1(tan2_of(wo), alpha) * cos_oh * d_of(h, alpha) / wo[2]


def half_vector(wo, wi):
    h = wo + wi
    with np.errstate(invalid="ignore"):
        return h / np.linalg.norm(h, axis=-1, keepdims=True)


def conductor_fcos(wo, wi, alpha):
    """f |cos wi| of a rough conductor with F = 1: D(h) G2 / (4 wo.z) where wo.z, wi.z > 0."""
    wo = np.broadcast_to(wo, wi.shape)
    h = half_vector(wo, wi)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = d_of(h, alpha) * ggx_g2(tan2_of(wo), tan2_of(wi), alpha) / (4.0 * wo[..., 2])
    return np.where((wo[..., 2] > 0.0) & (wi[..., 2] > 0.0), v, 0.0)


# --- Dielectric ----------------------------------------------------------------------------------
def fresnel(cos_o, n_o, n_t):
    """Unpolarised Fresnel reflectance for light in medium n_o meeting n_t at cosine cos_o (>= 0);
    1 under total internal reflection."""
    cos_o = np.clip(cos_o, 0.0, 1.0)
    sin_t = n_o / n_t * np.sqrt(1.0 - cos_o**2)
    cos_t = np.sqrt(np.maximum(1.0 - sin_t**2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (n_o * cos_o - n_t * cos_t) / (n_o * cos_o + n_t * cos_t)
        rp = (n_t * cos_o - n_o * cos_t) / (n_t * cos_o + n_o * cos_t)
    return np.where(sin_t >= 1.0, 1.0, 0.5 * (rs**2 + rp**2))


def dielectric_fcos(wo, wi, alpha, ior):
    """Walter et al. 2007 with importance transport (so that a lossless interface integrates to 1):
    (reflection, transmission) f |cos wi|, each (...,). Outside (z > 0) index 1, inside `ior`.

    Reflection: F D G2 / (4 |wo.z|) with h = sign(wo.z) (wo + wi) normalised.
    Transmission: |wi.h| |wo.h| (1 - F) D G2 eta^2 / (|wo.z| (wo.h + eta wi.h)^2) with
    h = -(n_o wo + n_i wi) normalised and turned to +z, eta = n_i / n_o.
    Both require the microfacet to face each direction from its own side: (v.h) (v.z) > 0.
    """
    wo = np.broadcast_to(wo, wi.shape)
    zo, zi = wo[..., 2], wi[..., 2]
    n_o = np.where(zo > 0.0, 1.0, ior)
    n_i = np.where(zi > 0.0, 1.0, ior)
    refl = zo * zi > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.where(refl[..., None], (wo + wi) * np.sign(zo)[..., None],
                     -(n_o[..., None] * wo + n_i[..., None] * wi))
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        h = h * np.where(h[..., 2] < 0.0, -1.0, 1.0)[..., None]
        oh = np.sum(wo * h, axis=-1)
        ih = np.sum(wi * h, axis=-1)
        ok = (oh * zo > 0.0) & (ih * zi > 0.0) & (h[..., 2] > 0.0)
        F = fresnel(np.abs(oh), n_o, np.where(zo > 0.0, ior, 1.0))
        DG = d_of(h, alpha) * ggx_g2(tan2_of(wo), tan2_of(wi), alpha)
        eta = n_i / n_o
        r = F * DG / (4.0 * np.abs(zo))
        t = np.abs(ih) * np.abs(oh) * (1.0 - F) * DG * eta**2 / (np.abs(zo) * (oh + eta * ih) ** 2)
    r = np.where(ok & refl, r, 0.0)
    t = np.where(ok & ~refl, t, 0.0)
    return np.nan_to_num(r, nan=0.0, posinf=0.0), np.nan_to_num(t, nan=0.0, posinf=0.0)


# --- Quadrature ----------------------------------------------------------------------------------
def gauss_legendre(edges, order):
    """Composite rule: nodes and weights (both (len(edges) - 1) * order,) on the panels `edges`."""
    x, w = np.polynomial.legendre.leggauss(order)
    a, b = edges[:-1, None], edges[1:, None]
    return (0.5 * (a + b) + 0.5 * (b - a) * x).ravel(), (0.5 * (b - a) * w).ravel()


def smoothed_panels(edges, order):
    """Composite Gauss-Legendre rule on the panels between sorted `edges` (..., k), each panel
    mapped through s -> 3 s^2 - 2 s^3: the map's zero slope at both ends turns an integrand that
    behaves like a half-integer power of the distance to a panel edge (a sqrt where a cone of
    total internal reflection or a circle's tangent meets the edge) into a smooth one.
    Returns nodes and weights (..., (k - 1) * order)."""
    x, w = np.polynomial.legendre.leggauss(order)
    s, w = 0.5 * (x + 1.0), 0.5 * w
    m, mw = 3.0 * s * s - 2.0 * s**3, 6.0 * s * (1.0 - s) * w
    a, b = edges[..., :-1, None], edges[..., 1:, None]
    shape = edges.shape[:-1] + (-1,)
    return (a + (b - a) * m).reshape(shape), ((b - a) * mw).reshape(shape)


def edges_around(lo, hi, centers, coarse=0.2, ratio=0.4, fixed=()):
    """Panel edges on [lo, hi]: `fixed` ones, and around each (center, width) of `centers` panels
    `width` wide that grow with the distance d from it (ratio x d) up to `coarse`."""
    pts = [lo, hi, *fixed]
    for c, width in centers:
        for sgn in (1.0, -1.0):
            d, step = 0.0, width
            while d < hi - lo:
                d += step
                pts.append(c + sgn * d)
                step = min(coarse, max(width, ratio * d))
    pts = np.unique(np.clip(pts, lo, hi))
    out = [pts[:1]]
    for a, b in zip(pts[:-1], pts[1:]):
        out.append(np.linspace(a, b, max(1, math.ceil((b - a) / coarse)) + 1)[1:])
    return np.concatenate(out)


def sphere_rule(wo, peaks, theta_fixed=(), cones=(), theta_max=math.pi, fine=0.25, order=12):
    """Nodes (m, 3) and weights (m,) over the directions with polar angle up to theta_max and
    phi in [0, pi], weights doubled: for integrands symmetric about the xz-plane, wo in that plane
    with wo.x >= 0. Every panel is smooth for the integrand when:

    peaks       : (theta, width) of features at phi = pi (lobes around the mirror and refracted
                  directions, the horizon, -wo); panels there are fine x width, in theta and in
                  phi (at phi = pi, with the narrowest width), and grow away from them.
    theta_fixed : polar angles where the integrand jumps (horizon, the transmission's break).
    cones       : values s of wo.wi along which it is not smooth (a kink or a sqrt): in each row
                  of constant theta they are panel edges in phi, and the thetas where a cone
                  touches a row are panel edges in theta.
    """
    so, co = math.hypot(wo[0], wo[1]), wo[2]
    theta_o = math.atan2(so, co)
    tangent = []
    for s in cones:
        g = math.acos(s)
        for t in (abs(theta_o - g), theta_o + g):
            t = 2.0 * math.pi - t if t > math.pi else t
            if 0.0 < t < theta_max:
                tangent.append(t)
    narrow = fine * min(w for _, w in peaks)
    t, wt = smoothed_panels(edges_around(
        0.0, theta_max, [(p, fine * w) for p, w in peaks],
        fixed=[x for x in theta_fixed if x < theta_max] + tangent), order)
    pe = edges_around(0.0, math.pi, [(math.pi, narrow)])
    st, ct = np.sin(t), np.cos(t)
    breaks = [np.full_like(t, math.pi)]
    with np.errstate(divide="ignore", invalid="ignore"):
        for s in cones:
            c = (s - co * ct) / (so * st)
            breaks.append(np.where(np.abs(c) < 1.0, np.arccos(np.clip(c, -1.0, 1.0)), math.pi))
    e = np.sort(np.concatenate([np.broadcast_to(pe, (t.size, pe.size)), np.stack(breaks, 1)], 1), 1)
    p, wp = smoothed_panels(e, order)
    sp = st[:, None]
    dirs = np.stack([sp * np.cos(p), sp * np.sin(p), np.broadcast_to(ct[:, None], p.shape)], -1)
    return dirs.reshape(-1, 3), (2.0 * sp * wt[:, None] * wp).ravel()


def conductor_rule(alpha, mu, fine=0.25, order=12):
    """`sphere_rule` over the upper hemisphere for the conductor seen from
    wo = (sqrt(1 - mu^2), 0, mu): the lobe at the mirror direction, the horizon (where G2's
    sqrt(cos^2 + a^2 sin^2) changes on the scale alpha) and -wo, near which the half vector turns
    fast (distance mu). Returns (wo, dirs, weights)."""
    wo = np.array([math.sqrt(1.0 - mu * mu), 0.0, mu])
    theta_o = math.acos(mu)
    peaks = [(theta_o, alpha), (0.5 * math.pi, alpha), (math.pi - theta_o, max(mu, 1e-3))]
    return (wo, *sphere_rule(wo, peaks, theta_max=0.5 * math.pi, fine=fine, order=order))


def conductor_albedo(alpha, mu):
    """Directional albedo E(mu) = integral of D G2 / (4 mu) over wi of the conductor with F = 1,
    and a conservative estimate of its quadrature error (the change from an 8-point rule)."""
    wo, d, w = conductor_rule(alpha, mu)
    e = float(np.sum(conductor_fcos(wo, d, alpha) * w))
    wo, d, w = conductor_rule(alpha, mu, order=8)
    return e, abs(e - float(np.sum(conductor_fcos(wo, d, alpha) * w)))


def dielectric_rule(alpha, z, ior, fine=0.25, order=12):
    """`sphere_rule` for the rough dielectric seen from wo = (sqrt(1 - z^2), 0, z). Returns
    (wo, dirs, weights).

    Panel edges sit where the integrand is not smooth: the horizon, the circle
    wi.z = -wo.z / eta where the transmission's half vector reaches the surface plane (a jump),
    the cones wo.wi = -n_o / n_i and -n_i / n_o where wo.h or wi.h changes sign (kinks; grazing
    refraction), and from the denser side the cone of total internal reflection
    (wo.h = cos theta_c, a sqrt in F). Panels are finest at the reflected lobe (width alpha), the
    refracted one (alpha |1 - n_o / n_i|), the horizon and -wo."""
    wo = np.array([math.sqrt(1.0 - z * z), 0.0, z])
    theta_o = math.acos(z)
    n_o, n_i = (1.0, ior) if z > 0.0 else (ior, 1.0)
    eta = n_i / n_o
    fixed = [0.5 * math.pi] + ([math.acos(-z / eta)] if abs(z / eta) < 1.0 else [])
    cones = [s for s in (-n_o / n_i, -n_i / n_o) if -1.0 < s < 1.0]
    if n_i < n_o:
        cos_c = math.sqrt(1.0 - (n_i / n_o) ** 2)
        cones.append(2.0 * cos_c * cos_c - 1.0)  # wo.h = sqrt((1 + wo.wi) / 2) for reflection
    peaks = [(theta_o, alpha), (0.5 * math.pi, alpha), (math.pi - theta_o, abs(z))]
    sin_t = math.sin(theta_o) / eta
    if sin_t < 1.0:
        t = math.asin(sin_t)
        peaks.append((math.pi - t if z > 0.0 else t, alpha * abs(1.0 - n_o / n_i)))
    return (wo, *sphere_rule(wo, peaks, fixed, cones, fine=fine, order=order))


def dielectric_albedo(alpha, z, ior, order=12):
    """(R, T): integrals over wi of `dielectric_fcos` from wo = (sqrt(1 - z^2), 0, z)."""
    wo, d, w = dielectric_rule(alpha, z, ior, order=order)
    r, t = dielectric_fcos(wo, d, alpha, ior)
    return float(np.sum(r * w)), float(np.sum(t * w))


# --- Environment map -----------------------------------------------------------------------------
def env_direction(theta, phi):
    """World direction (+y up) of polar angle theta from +y and map azimuth phi = 2 pi (u - 0.5)."""
    st = np.sin(theta)
    return np.stack([st * np.sin(phi), np.cos(theta), -st * np.cos(phi)], axis=-1)


def env_lookup(img, d):
    """Radiance of the map img (H, W, 3) along world directions d (..., 3), nearest pixel."""
    h, w = img.shape[:2]
    u = (0.5 + np.arctan2(d[..., 0], -d[..., 2]) / (2.0 * math.pi)) % 1.0
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / math.pi
    return img[np.minimum((v * h).astype(int), h - 1), np.minimum((u * w).astype(int), w - 1)]


def env_irradiance(img, n, sub=16, order=4):
    """Irradiance integral of L(w) max(0, n.w) over the sphere from the map img (H, W, 3),
    pixel by pixel (each a (theta, phi) rectangle) with sub x sub Gauss-Legendre panels of
    order x order points; n (3,) unit. Returns (3,)."""
    h, w = img.shape[:2]
    lit = np.argwhere(np.any(img > 0.0, axis=2))
    total = np.zeros(3)
    for y, x in lit:
        t, wt = gauss_legendre(np.linspace(math.pi * y / h, math.pi * (y + 1) / h, sub + 1), order)
        phi0, phi1 = 2.0 * math.pi * (x / w - 0.5), 2.0 * math.pi * ((x + 1) / w - 0.5)
        p, wp = gauss_legendre(np.linspace(phi0, phi1, sub + 1), order)
        T, P = np.meshgrid(t, p, indexing="ij")
        cos_n = np.maximum(env_direction(T, P) @ n, 0.0)
        total += img[y, x] * np.sum(cos_n * np.sin(T) * wt[:, None] * wp[None, :])
    return total
