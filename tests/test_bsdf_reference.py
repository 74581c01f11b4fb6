"""The microfacet BSDFs (tracer/bsdfs.py) against formulas the tracer did not compute itself.

test_bsdfs.py checks that sample, pdf and eval agree with each other; a D or G that is wrong
but used consistently passes there. Here the reference is tests/microfacet.py, written from the
textbook formulas in NumPy:

- GGX D, Lambda, G1, G2 and the visible-normal density against their closed forms, pointwise;
  the closed forms' normalisation by quadrature; the visible-normal sampler against the
  independent density (chi-square).
- White furnaces: the directional albedo of a conductor with F = 1 and of the rough dielectric
  (reflection and transmission separately), by quadrature of the independent formulas, against
  the mean sample weight (z-test) and the quadrature of `eval_batch`; the plastic's albedo is
  kd + ks times the conductor's.

Statistical tests share one family-wise level with a Sidak correction over NTESTS. Sensitivities
quoted in the docstrings come from perturbing the reference formula and re-running the comparison
with the same samples: that is the error of a tracer whose f, pdf and sampler all carry it
(which test_bsdfs.py cannot see). Mutating the tracer itself (in a copy) gave the same verdicts:
the separable G1 G1 for G2 passes test_bsdfs.py and fails 13 tests here.
"""
import functools
import math

import numpy as np
import pytest
from numba import njit

from tests import microfacet as M
from tracer.testing import ChiSquareTest, z_critical
from tracer.testing.stats import assert_z
from tracer import bsdfs as B


# --- Batch wrappers of the scalar GGX functions --------------------------------------------------
@njit(cache=True)
def _ggx_batch(w, h, alpha):
    """(n, 5) float64: D(h), Lambda(w), G1(w), G2(w, h), ggx_vndf_pdf(w, h) for the rows of
    w, h (n, 3) and alpha (n,)."""
    n = w.shape[0]
    out = np.empty((n, 5))
    for k in range(n):
        a = (w[k, 0], w[k, 1], w[k, 2])
        b = (h[k, 0], h[k, 1], h[k, 2])
        out[k, 0] = B.ggx_d(b, alpha[k])
        out[k, 1] = B.ggx_lambda(a, alpha[k])
        out[k, 2] = B.ggx_g1(a, alpha[k])
        out[k, 3] = B.ggx_g2(a, b, alpha[k])
        out[k, 4] = B.ggx_vndf_pdf(a, b, alpha[k])
    return out


@njit(cache=True)
def _vndf_sample_batch(wo, alpha, u):
    """sample_ggx_vndf from wo (3,) for each row of u (n, 2+) -> h (n, 3)."""
    n = u.shape[0]
    out = np.empty((n, 3))
    for k in range(n):
        h = B.sample_ggx_vndf((wo[0], wo[1], wo[2]), alpha, u[k, 0], u[k, 1])
        out[k, 0], out[k, 1], out[k, 2] = h[0], h[1], h[2]
    return out


def material(t, alpha, ior=1.5, kd=(0.0, 0.0, 0.0), ks=(1.0, 1.0, 1.0)):
    """One material as (mat_type (1,) int32, mat_param (1, 8) float64)."""
    return np.array([t], dtype=np.int32), np.array([[*kd, *ks, alpha, ior]], dtype=np.float64)


def direction(z, phi=0.0):
    s = math.sqrt(max(0.0, 1.0 - z * z))
    return np.array([s * math.cos(phi), s * math.sin(phi), z])


def tile(w, n):
    return np.ascontiguousarray(np.broadcast_to(np.asarray(w, dtype=np.float64), (n, 3)))


def sample_weights(mat, wo, n, seed, radiance=False):
    """(wi (n, 3), weight (n, 3)) of n `sample_batch` samples from wo."""
    u = np.random.default_rng(seed).random((n, 3))
    wi, beta, _, _ = B.sample_batch(*mat, 0, tile(wo, n), u, radiance)
    return wi, beta


# --- Cases and the family-wise level -------------------------------------------------------------
VNDF_CASES = [(0.1, 0.95), (0.2, 0.05), (0.3, 0.5), (0.3, 1.0), (0.6, 0.15), (1.0, 0.02)]
ALPHAS = (0.1, 0.3, 0.6, 1.0)
MUS = (1.0, 0.8, 0.5, 0.25, 0.1, 0.03)
DIELECTRIC_CASES = [(a, z) for a in (0.1, 0.5) for z in (0.8, 0.2, -0.8, -0.3)]
DIELECTRIC_CASES += [(1.0, 0.5), (1.0, -0.5)]
PLASTIC_KD = (0.5, 0.3, 0.1)
PLASTIC_KS = (0.5, 0.6, 0.9)  # kd + ks <= 1 in every channel
PLASTIC_MUS = (1.0, 0.6, 0.3, 0.1, 0.03)
N_SAMPLES = 250_000
# chi-square per VNDF case; a z-test per (alpha, mu) of the conductor; reflection, transmission,
# their sum and "sum <= 1" per dielectric case; 3 channels per plastic angle
NTESTS = (len(VNDF_CASES) + len(ALPHAS) * len(MUS) + 4 * len(DIELECTRIC_CASES)
          + 3 * len(PLASTIC_MUS))
Z = z_critical(NTESTS)


# --- 1. GGX against its closed forms -------------------------------------------------------------
THETAS = np.array([0.0, 1e-7, 1e-4, 1e-2, 0.1, 0.3, 0.6, 0.9, 1.2, 1.4, 1.5, 1.55,
                   0.5 * math.pi - 1e-3, 0.5 * math.pi - 1e-6])
GRID_ALPHAS = np.array([0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0])


def polar(theta, phi):
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


def test_ggx_matches_closed_forms():
    """D, Lambda, G1, G2 and the VNDF density agree with the textbook formulas, written in theta
    (tan^2 from np.tan of the angle, not from the vector the tracer gets), to 1e-10 relative over
    alpha 0.05-1 and theta from the normal (0, 1e-7) to 1e-6 from grazing, with h below the surface
    and wo.h < 0 giving 0. Any change of a formula beyond rounding fails here: a Lambda off by
    1e-9 relative, a D with a^2 for a, the separable G1 G1 for the height-correlated G2."""
    rng = np.random.default_rng(5)
    a, t_o, t_h = (g.ravel() for g in np.meshgrid(GRID_ALPHAS, THETAS, THETAS, indexing="ij"))
    phi_o = rng.uniform(-math.pi, math.pi, a.size)
    phi_h = rng.uniform(-math.pi, math.pi, a.size)
    wo, h = polar(t_o, phi_o), polar(t_h, phi_h)
    got = _ggx_batch(wo, h, a)
    tan2_o, tan2_h = np.tan(t_o) ** 2, np.tan(t_h) ** 2
    d = M.ggx_d(np.cos(t_h), tan2_h, a)
    lam = M.ggx_lambda(tan2_o, a)
    g1 = M.ggx_g1(tan2_o, a)
    g2 = M.ggx_g2(tan2_o, tan2_h, a)
    cos_oh = np.sin(t_o) * np.sin(t_h) * np.cos(phi_o - phi_h) + np.cos(t_o) * np.cos(t_h)
    vndf = g1 * np.maximum(cos_oh, 0.0) * d / np.cos(t_o)
    for k, (name, ref) in enumerate([("D", d), ("Lambda", lam), ("G1", g1), ("G2", g2)]):
        np.testing.assert_allclose(got[:, k], ref, rtol=1e-10, atol=0.0, err_msg=name)
    # The VNDF density's cosine cancels near wo.h = 0: absolute slack of 1e-15 of its scale there
    scale = g1 * d / np.cos(t_o)
    assert np.all(np.abs(got[:, 4] - vndf) <= 1e-10 * vndf + 1e-15 * scale), "ggx_vndf_pdf"
    assert np.any((cos_oh < 0) & (scale > 0)) and np.all(got[cos_oh < -1e-12, 4] == 0.0)
    # Below the surface D is 0, and so is the density of a normal that faces away
    below = h * [1, 1, -1]
    got_below = _ggx_batch(wo, below, a)
    keep = np.cos(t_h) > 1e-12
    assert np.all(got_below[keep, 0] == 0.0) and np.all(got_below[keep, 4] == 0.0)


def test_ggx_closed_forms_are_normalised():
    """The reference itself: the integral of D(h) cos theta_h over the hemisphere is 1, and the
    visible-normal density integrates to 1 for every wo (quadrature of the NumPy formulas, to
    1e-9; the tracer agrees with them pointwise by the test above). A D missing its 1/pi, or a
    VNDF with G2 for G1, would integrate to 1/pi or < 1."""
    for alpha in GRID_ALPHAS:
        # theta_h = atan(alpha tan(pi x / 2)) puts the panels where D lives; Jacobian d theta / dx
        x, w = M.gauss_legendre(np.linspace(0.0, 1.0, 65), 12)
        s = np.tan(0.5 * math.pi * x)
        theta = np.arctan(alpha * s)
        jac = alpha * 0.5 * math.pi * (1.0 + s * s) / (1.0 + (alpha * s) ** 2)
        d = M.ggx_d(np.cos(theta), np.tan(theta) ** 2, alpha)
        total = np.sum(2.0 * math.pi * d * np.cos(theta) * np.sin(theta) * jac * w)
        assert abs(total - 1.0) < 1e-9, (alpha, total)
    for alpha, z in [(0.1, 0.9), (0.3, 0.3), (0.6, 1.0), (1.0, 0.05), (0.2, 0.01)]:
        wo = direction(z)
        # kink where wo.h = 0 (a cone about wo), jump at the horizon (D = 0 below)
        dirs, w = M.sphere_rule(wo, [(0.0, alpha), (0.5 * math.pi, alpha)], [0.5 * math.pi], [0.0])
        total = np.sum(M.vndf_pdf(wo, dirs, alpha) * w)
        assert abs(total - 1.0) < 1e-9, (alpha, z, total)


@pytest.mark.parametrize("alpha, z", VNDF_CASES, ids=[f"alpha{a}-wo{z}" for a, z in VNDF_CASES])
def test_vndf_sampling_matches_independent_pdf(alpha, z):
    """Chi-square of `sample_ggx_vndf` against the NumPy D_wo(h) (500k samples, 31 x 61 cells).
    The normals are turned so that the macro normal lies on the grid's equator, where its cells
    are finest. A sampler whose alpha is 2% too large is rejected (tried at alpha 0.1, 0.3 and 1;
    p-values 1e-5 to 1e-14); 1% is not (p 0.003 to 0.7)."""
    wo = direction(z, 0.7)

    def turn(h):  # macro normal +z -> grid +x (a rotation: densities are unchanged)
        return h[:, [2, 0, 1]]

    def pdf(d):
        return M.vndf_pdf(wo, d[:, [1, 2, 0]], alpha)

    chi = ChiSquareTest(lambda u: turn(_vndf_sample_batch(wo, alpha, u)), pdf, sample_dim=2,
                        n=500_000, seed=int(1000 * alpha + 100 * z))
    assert chi.run(ntests=NTESTS), chi.message


def test_vndf_chi2_has_power():
    """The chi-square test above rejects a sampler with alpha 2% too large."""
    alpha, wo = 0.3, direction(0.5, 0.7)
    chi = ChiSquareTest(lambda u: _vndf_sample_batch(wo, 1.02 * alpha, u)[:, [2, 0, 1]],
                        lambda d: M.vndf_pdf(wo, d[:, [1, 2, 0]], alpha), sample_dim=2, n=500_000,
                        seed=3)
    assert not chi.run(ntests=NTESTS)


# --- 2a. White furnace: conductor with F = 1 -----------------------------------------------------
@functools.lru_cache(maxsize=None)
def conductor_reference(alpha, mu):
    """(E, quadrature error estimate) of the independent formula."""
    return M.conductor_albedo(alpha, mu)


def test_conductor_reference_anchors():
    """The reference's own sanity: its quadrature error estimate is under 1e-5 (a tenth of the
    smallest standard error below; the 12-point rule itself agrees with a 16-point rule on panels
    half as wide to 1e-8), E <= 1, E -> 1 as alpha -> 0 (E(0.1, 1) > 0.98), E at normal
    incidence falls with alpha, and for alpha = 1 at normal incidence, where D = 1/pi and
    G2 = 2 cos_i / (1 + cos_i), E = integral over cos_i of cos_i / (1 + cos_i) = 1 - ln 2."""
    e1 = [conductor_reference(a, 1.0)[0] for a in ALPHAS]
    assert e1[0] > 0.98 and all(x > y for x, y in zip(e1, e1[1:]))
    assert abs(e1[-1] - (1.0 - math.log(2.0))) < 1e-12
    for a in ALPHAS:
        for mu in MUS:
            e, err = conductor_reference(a, mu)
            assert err < 1e-5 and 0.0 < e <= 1.0  # err: change from an 8-point rule, conservative


@pytest.mark.parametrize("alpha", ALPHAS)
def test_conductor_white_furnace(alpha):
    """Directional albedo of a rough conductor with Ks = 1 (Schlick F = 1) for mu in MUS: the
    mean `sample_batch` weight (250k samples, z-test) and the quadrature of `eval_batch` both
    equal the quadrature of D G2 / (4 mu) (tests/microfacet.py; eval_batch on the reference's own
    nodes, to 1e-9 relative, so any pointwise change of f beyond rounding fails).

    Standard errors are 2e-4 to 8e-4. Sensitivity (limit |z| 3.85): Lambda 1% too large fails 9
    of the 24 cases, worst z 31 at alpha 0.3, mu 0.03 (at mu 0.5 only 1.7-2.8 standard errors:
    Lambda matters at grazing angles); D with alpha 1% too large fails 15 of 24 (worst z 33); the
    separable G1(wo) G1(wi) for the height-correlated G2 fails 16 of 24 (E(0.6, 0.25) moves by
    0.053, 79 standard errors; at mu = 1 the two agree). The eval_batch check fails for any of
    them, and for a pointwise change of f above 1e-9.
    """
    mat = material(B.CONDUCTOR, alpha)
    for k, mu in enumerate(MUS):
        e, err = conductor_reference(alpha, mu)
        wo = direction(mu)
        _, beta = sample_weights(mat, wo, N_SAMPLES, seed=int(100 * alpha) * 100 + k)
        assert np.all(beta == beta[:, :1])  # F = 1 in every channel
        b = beta[:, 0]
        assert_z(b.mean(), b.var(ddof=1) / b.size + err**2, e, n_tests=NTESTS,
                 what=f"conductor alpha {alpha} mu {mu}: mean weight against E")
        # eval_batch integrated with the reference's rule equals the reference's integral
        wo, dirs, w = M.conductor_rule(alpha, mu, order=8)
        f = B.eval_batch(*mat, 0, tile(wo, len(dirs)), dirs, False)
        q, q_ref = np.sum(f[:, 0] * w), np.sum(M.conductor_fcos(wo, dirs, alpha) * w)
        assert abs(q - q_ref) <= 1e-9 * q_ref and abs(q - e) <= 2.0 * err + 1e-9, (alpha, mu, q, e)


# --- 2b. White furnace: rough dielectric ---------------------------------------------------------
@functools.lru_cache(maxsize=None)
def dielectric_reference(alpha, z, ior=1.5):
    """(R, T, quadrature error estimate) of Walter et al.'s formula for wo = direction(z),
    importance transport; R + T is the directional albedo of the interface."""
    r, t = M.dielectric_albedo(alpha, z, ior)
    r8, t8 = M.dielectric_albedo(alpha, z, ior, order=8)
    return r, t, abs(r - r8) + abs(t - t8)


@pytest.mark.parametrize("alpha, z", DIELECTRIC_CASES,
                         ids=[f"alpha{a}-wo{z}" for a, z in DIELECTRIC_CASES])
def test_rough_dielectric_white_furnace(alpha, z):
    """A lossless interface (radiance=False, ior 1.5) from outside (wo.z > 0) and inside: the mean
    sample weight of reflections, of transmissions and of both equal the quadratures of Walter et
    al.'s reflection and transmission terms (own exact Fresnel), and the sum is at most 1 (it is
    1 minus the single-scattering loss). eval_batch integrated on the reference's nodes gives
    its R and T to 1e-9 relative, so any pointwise change of f fails too.

    Standard errors are 1e-4 to 8e-4, the quadrature error estimate under 3e-8. Sensitivity
    (limit |z| 3.85): the Fresnel reflectance evaluated from the wrong side (n_o and n_t swapped)
    fails 29 of the 30 z-tests (R at alpha 0.1, wo.z 0.8 moves by 0.22, 540 standard errors);
    F 3% too large moves R by up to 8.8 standard errors, 5% by 15 (1% by 1.1: not detected);
    Lambda 1% too large fails 5 of 30 (worst z 14 at alpha 0.5, wo.z 0.2).
    """
    r_ref, t_ref, err = dielectric_reference(alpha, z)
    assert r_ref + t_ref <= 1.0 + 2.0 * err, (r_ref, t_ref)
    mat = material(B.ROUGH_DIELECTRIC, alpha, ior=1.5)
    wi, beta = sample_weights(mat, direction(z, 0.3), N_SAMPLES, seed=int(1000 * alpha - 100 * z))
    b = beta[:, 0]
    refl = wi[:, 2] * z > 0.0
    n = b.size
    for name, x, ref in [("reflection", b * refl, r_ref), ("transmission", b * ~refl, t_ref),
                         ("both", b, r_ref + t_ref)]:
        assert_z(x.mean(), x.var(ddof=1) / n + (2.0 * err) ** 2, ref, n_tests=NTESTS,
                 what=f"{name}: mean weight against the reference")
    se = b.std(ddof=1) / math.sqrt(n)
    assert b.mean() <= 1.0 + Z * se
    # eval_batch integrated with the reference's rule equals the reference's integrals
    wo, dirs, w = M.dielectric_rule(alpha, z, 1.5, order=8)
    f = B.eval_batch(*mat, 0, tile(wo, len(dirs)), dirs, False)[:, 0]
    r, t = M.dielectric_fcos(wo, dirs, alpha, 1.5)
    side = dirs[:, 2] * z > 0.0
    np.testing.assert_allclose([np.sum((f * w)[side]), np.sum((f * w)[~side])],
                               [np.sum(r * w), np.sum(t * w)], rtol=1e-9)


# --- 3. Plastic ----------------------------------------------------------------------------------
@pytest.mark.parametrize("alpha", (0.1, 0.6))
def test_plastic_albedo(alpha):
    """The plastic's f = kd / pi + ks D G2 / (4 cos_i cos_o) has no Fresnel coupling between its
    lobes, so its directional albedo is exactly kd + ks E(mu), E the F = 1 conductor's albedo
    (reference quadrature): checked per channel with the mean sample weight (z-test) and the
    quadrature of eval_batch (on the reference's nodes, to 1e-9), for mu from 1 to 0.03. Since
    E <= 1 the albedo is at most 1 when kd + ks <= 1 (asserted); with kd + ks > 1 it exceeds 1
    near normal incidence (the loader warns), so that is no property of the BSDF to test.

    What it detects: a wrong diffuse normalisation, a specular lobe with the wrong D or G2 (as the
    conductor), lobes scaled by the wrong channel. A kd 1% too large in channel R (0.5) is 6 to
    14 standard errors, in G (0.3) 4.6 to 19; a ks 1% too large 3.7 to 38 (limit 3.85)."""
    mat = material(B.PLASTIC, alpha, kd=PLASTIC_KD, ks=PLASTIC_KS)
    kd, ks = np.array(PLASTIC_KD), np.array(PLASTIC_KS)
    for k, mu in enumerate(PLASTIC_MUS):
        e, err = conductor_reference(alpha, mu)
        albedo = kd + ks * e
        assert np.all(albedo <= 1.0 + err)
        wo = direction(mu, 1.1)
        _, beta = sample_weights(mat, wo, N_SAMPLES, seed=700 + k)
        assert_z(beta.mean(axis=0), beta.var(axis=0, ddof=1) / len(beta) + (ks * err) ** 2,
                 albedo, n_tests=NTESTS, what=f"plastic mu {mu}: mean weight against kd + ks E")
        wo, dirs, w = M.conductor_rule(alpha, mu, order=8)
        f = B.eval_batch(*mat, 0, tile(wo, len(dirs)), dirs, False)
        q = np.sum(f * w[:, None], axis=0)
        q_ref = kd + ks * np.sum(M.conductor_fcos(wo, dirs, alpha) * w)
        np.testing.assert_allclose(q, q_ref, rtol=1e-9)
        np.testing.assert_allclose(q, albedo, rtol=0.0, atol=2.0 * err + 1e-9)


def test_plastic_without_specular_is_lambertian():
    """With Ks = 0 every sample weighs exactly Kd and f |cos| integrates to Kd, at normal incidence
    and at every angle."""
    kd = np.array([0.7, 0.4, 0.2])
    mat = material(B.PLASTIC, 0.3, kd=tuple(kd), ks=(0.0, 0.0, 0.0))
    for mu in (1.0, 0.7, 0.2, 0.01, -0.5):
        wo = direction(mu, 0.2)
        wi, beta = sample_weights(mat, wo, 20_000, seed=9)
        ok = np.all(beta != 0.0, axis=1)
        assert ok.mean() > 0.999  # only directions in the surface plane fail
        np.testing.assert_allclose(beta[ok], np.broadcast_to(kd, beta[ok].shape), rtol=1e-12)
        _, dirs, w = M.conductor_rule(0.3, 1.0, order=8)
        dirs = np.ascontiguousarray(dirs * [1, 1, np.sign(mu)])
        f = B.eval_batch(*mat, 0, tile(wo, len(dirs)), dirs, False)
        np.testing.assert_allclose(np.sum(f * w[:, None], axis=0), kd, rtol=1e-12)
