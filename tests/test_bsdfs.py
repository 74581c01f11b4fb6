"""Contract tests of the BSDFs (tracer/bsdfs.py).

For every non-delta material, over several roughnesses, indices and incident directions (above,
grazing, below, normal): the sampler agrees with its pdf (chi-square), the pdf integrates to the
probability that sampling succeeds, weights equal eval / pdf, the mean weight equals the
integral of f |cos| (and is at most 1), f is reciprocal. Delta materials are checked against
Snell's law and an independent Fresnel formula. Statistical tests share one significance level
with a Sidak correction over all of them (NTESTS).
"""
import functools
import math

import numpy as np
import pytest

from tracer.testing import ChiSquareTest, sidak, sphere_grid, z_critical
from tracer import bsdfs as B

N = 500_000  # samples per case
KD = (0.7, 0.5, 0.3)
KS = (0.9, 0.6, 0.3)
PLASTIC_KD = (0.5, 0.3, 0.2)
PLASTIC_KS = (0.4, 0.4, 0.4)


def material(t, alpha=0.3, ior=1.5, kd=KD, ks=KS, eta=(0.0, 0.0, 0.0), k=(0.0, 0.0, 0.0), flags=0, clear=0.0):
    """One material as (mat_type (1,) int32, mat_param (1, N_PARAM) float64); clear = 1 - opacity."""
    mat_type = np.array([t], dtype=np.int32)
    mat_param = np.array([[*kd, *ks, alpha, ior, *eta, *k, flags, 0.0, clear]], dtype=np.float64)
    return mat_type, mat_param


def direction(z, phi=0.3):
    """Unit vector with cosine z at azimuth phi."""
    s = math.sqrt(max(0.0, 1.0 - z * z))
    return np.array([s * math.cos(phi), s * math.sin(phi), z])


# --- Cases: (name, type, material kwargs, wo.z) ------------------------------------------------
WO_TWO_SIDED = (0.8, 0.1, -0.6)  # above, grazing, below
CASES = [("diffuse", B.DIFFUSE, {}, z) for z in WO_TWO_SIDED]
CASES += [
    ("conductor", B.CONDUCTOR, dict(alpha=a), z) for a in (0.05, 0.3, 0.8) for z in WO_TWO_SIDED
]
CASES += [("conductor", B.CONDUCTOR, dict(alpha=0.3), 1.0)]  # normal incidence
CASES += [
    ("plastic", B.PLASTIC, dict(alpha=a, kd=PLASTIC_KD, ks=PLASTIC_KS), z)
    for a in (0.05, 0.3, 0.8)
    for z in WO_TWO_SIDED
]
CASES += [("plastic_spec_only", B.PLASTIC, dict(alpha=0.3, kd=(0, 0, 0), ks=PLASTIC_KS), 0.8)]
CASES += [
    ("rough_dielectric", B.ROUGH_DIELECTRIC, dict(alpha=a, ior=1.5), z)
    for a in (0.05, 0.3, 0.8)
    for z in (0.8, 0.1, -0.6, -0.1)
]
CASES += [
    ("rough_dielectric", B.ROUGH_DIELECTRIC, dict(alpha=0.3, ior=1.33), z) for z in (0.8, -0.6)
]
CASES += [("rough_dielectric", B.ROUGH_DIELECTRIC, dict(alpha=0.3, ior=1.5), 1.0)]
GOLD = dict(eta=(0.143036, 0.375307, 1.44205), k=(3.983, 2.38556, 1.60336))  # tracer.metals "Au"
CASES += [("metal", B.METAL, dict(alpha=0.3, **GOLD), z) for z in WO_TWO_SIDED]
CASES += [("metal_beckmann", B.METAL, dict(alpha=0.3, flags=B.BECKMANN, **GOLD), z) for z in (0.8, 0.1)]
COAT = dict(kd=PLASTIC_KD, ks=(1.0, 1.0, 1.0), ior=1.49)
CASES += [("coated", B.COATED, dict(alpha=0.3, **COAT), z) for z in WO_TWO_SIDED]
CASES += [("coated_beckmann", B.COATED, dict(alpha=0.2, flags=B.BECKMANN | B.NONLINEAR, **COAT), 0.5)]


def case_id(c):
    name, _, kw, z = c
    tags = [f"{k}{v}" for k, v in kw.items() if k in ("alpha", "ior")]
    return "-".join([name, *tags, f"wo{z}"])


IDS = [case_id(c) for c in CASES]
DIELECTRIC_CASES = [(ior, z) for ior in (1.5, 1.33) for z in (0.9, 0.5, 0.1, -0.9, -0.5, -0.1)]
# Statistical tests in this file: chi-square and pdf integral per case, 3 channels x 2 (mean
# against integral, mean at most 1) per case, Fresnel frequencies, the two power checks
NTESTS = len(CASES) * (2 + 6) + len(DIELECTRIC_CASES) + 2 + 3 + 3
Z = z_critical(NTESTS)


# --- Batch helpers -------------------------------------------------------------------------------
def tile(w, n):
    return np.ascontiguousarray(np.broadcast_to(np.asarray(w, dtype=np.float64), (n, 3)))


def sampler(mat, wo, radiance=False):
    """u (n, 3) -> wi (n, 3), failed samples as NaN rows (for the chi-square test)."""

    def sample(u):
        wi, _, pdf, _ = B.sample_batch(*mat, 0, tile(wo, len(u)), u, radiance)
        wi[pdf == 0.0] = np.nan
        return wi

    return sample


def pdf_fn(mat, wo):
    return lambda d: B.pdf_batch(*mat, 0, tile(wo, len(d)), d)


def eval_fn(mat, wo, radiance=False):
    return lambda d: B.eval_batch(*mat, 0, tile(wo, len(d)), d, radiance)


def breaks(t, ior, z):
    """z-values where the pdf and f jump besides the horizon: for a rough dielectric, the
    refracted directions whose generalised half vector wo + eta wi lies in the surface plane."""
    if t != B.ROUGH_DIELECTRIC:
        return ()
    eta = ior if z > 0 else 1.0 / ior
    return (-z / eta,)


@functools.lru_cache(maxsize=None)
def run_case(i):
    """Everything the per-case tests look at, computed once per case."""
    name, t, kw, z = CASES[i]
    mat = material(t, **kw)
    wo = direction(z)
    jumps = breaks(t, kw.get("ior", 1.5), z)
    # The chi-square test draws the same u from the same seed: sample once
    u = np.random.default_rng(i).random((N, 3))
    wi, beta, pdf, delta = B.sample_batch(*mat, 0, tile(wo, N), u, False)
    ok = pdf > 0.0
    wi_nan = np.where(ok[:, None], wi, np.nan)
    chi = ChiSquareTest(lambda uu: wi_nan, pdf_fn(mat, wo), n=N, seed=i, breaks=jumps)
    passed = chi.run(ntests=NTESTS)
    f_at = B.eval_batch(*mat, 0, tile(wo, N), wi, False)
    pdf_at = B.pdf_batch(*mat, 0, tile(wo, N), wi)
    # Integral of f |cos wi| over the sphere, accurate to a tenth of the weights' standard error
    mean = beta.mean(axis=0)
    se = beta.std(axis=0) / math.sqrt(N)
    tol = max(0.1 * float(se.min()), 1e-7)
    cells, err, info = sphere_grid().integrate(
        eval_fn(mat, wo), tol_total=lambda tot: tol, breaks=jumps
    )
    return dict(
        mat=mat, wo=wo, wi=wi, beta=beta, pdf=pdf, delta=delta, ok=ok, f_at=f_at, pdf_at=pdf_at,
        chi=chi, chi_passed=passed, mean=mean, se=se, f_int=cells.reshape(-1, 3).sum(axis=0),
        f_err=err.reshape(-1, 3).sum(axis=0), f_info=info,
    )


# --- Sampling against the pdf --------------------------------------------------------------------
@pytest.mark.parametrize("i", range(len(CASES)), ids=IDS)
def test_chi2_sample_matches_pdf(i):
    r = run_case(i)
    assert r["chi_passed"], r["chi"].message


@pytest.mark.parametrize("i", range(len(CASES)), ids=IDS)
def test_pdf_integrates_to_success_probability(i):
    """The pdf integrates to the probability that a sample succeeds (1 where sampling never
    fails; microfacet samples that leave on the wrong side fail)."""
    r = run_case(i)
    chi = r["chi"]
    p_ok = r["ok"].mean()
    se = math.sqrt(p_ok * (1.0 - p_ok) / N)
    sd = math.sqrt(se**2 + chi.quad_error**2 + 1e-18)
    assert chi.quad_info["converged"]
    assert abs(chi.pdf_integral - p_ok) <= Z * sd, (chi.pdf_integral, p_ok, sd)
    assert chi.pdf_integral <= 1.0 + chi.quad_error + 1e-9
    if CASES[i][1] == B.DIFFUSE:
        assert abs(chi.pdf_integral - 1.0) <= chi.quad_error + 1e-9


@pytest.mark.parametrize("i", range(len(CASES)), ids=IDS)
def test_weight_is_eval_over_pdf(i):
    r = run_case(i)
    ok, pdf, beta = r["ok"], r["pdf"], r["beta"]
    assert not r["delta"].any()
    # Failed samples carry nothing
    assert np.all(beta[~ok] == 0.0) and np.all(r["wi"][~ok] == 0.0)
    # Sampled directions are unit vectors
    np.testing.assert_allclose(np.linalg.norm(r["wi"][ok], axis=1), 1.0, rtol=1e-12)
    big = ok & (pdf > 1e-6)
    np.testing.assert_allclose(r["pdf_at"][big], pdf[big], rtol=1e-6)
    np.testing.assert_allclose(
        r["f_at"][big] / pdf[big, None], beta[big], rtol=1e-6, atol=1e-12
    )


@pytest.mark.parametrize("i", range(len(CASES)), ids=IDS)
def test_energy_mean_weight_matches_integral(i):
    """Mean sample weight (radiance=False) equals the integral of f |cos| and is at most 1."""
    r = run_case(i)
    assert r["f_info"]["converged"], r["f_info"]
    sd = np.sqrt(r["se"] ** 2 + r["f_err"] ** 2 + 1e-18)
    z = (r["mean"] - r["f_int"]) / sd
    assert np.all(np.abs(z) <= Z), (r["mean"], r["f_int"], sd)
    assert np.all(r["mean"] <= 1.0 + Z * r["se"] + 1e-12), r["mean"]
    assert np.all(r["f_int"] <= 1.0 + r["f_err"] + 1e-12), r["f_int"]


def test_energy_known_albedos():
    """Closed forms: Lambert gives kd exactly, a conductor with F0 = 1 loses only to masking."""
    i = IDS.index("diffuse-wo0.8")
    np.testing.assert_allclose(run_case(i)["f_int"], KD, rtol=1e-7)
    assert np.all(run_case(i)["beta"] == KD)
    # Conductor: F0 <= F <= 1 (Schlick), so channel c lies between F0_c times the white albedo
    # (which is at least the largest channel) and 1, ordered like F0
    j = IDS.index("conductor-alpha0.3-wo0.8")
    f = run_case(j)["f_int"]
    assert np.all(f <= 1.0) and np.all(f >= np.array(KS) * f.max()) and f[0] > f[1] > f[2]


def test_chi2_detects_wrong_pdf():
    """The chi-square test has power: a 5% roughness mismatch and a slightly wrong lobe
    probability must both be rejected."""
    wo = direction(0.7)
    m_s = material(B.CONDUCTOR, alpha=0.3)
    m_p = material(B.CONDUCTOR, alpha=0.315)
    assert not ChiSquareTest(sampler(m_s, wo), pdf_fn(m_p, wo), n=N).run(ntests=NTESTS)
    m_s = material(B.PLASTIC, alpha=0.3, kd=PLASTIC_KD, ks=PLASTIC_KS)
    m_p = material(B.PLASTIC, alpha=0.3, kd=PLASTIC_KD, ks=(0.44, 0.44, 0.44))

    def pdf_wrong(d):  # pdf of a plastic whose ks differs only in the lobe-selection probability
        return B.pdf_batch(*m_p, 0, tile(wo, len(d)), d)

    assert not ChiSquareTest(sampler(m_s, wo), pdf_wrong, n=N).run(ntests=NTESTS)


def test_smooth_coat_delta_and_diffuse_lobes():
    """The smooth COATED (Mitsuba's plastic): samples flagged delta are the mirror direction, drawn
    with the lobe's probability (binomial z-test on their frequency); the others follow the pdf
    (chi-square, the delta samples counted as failures, so the pdf must integrate to 1 - P(delta));
    the mean weight equals F(cos) ks plus the integral of the diffuse f |cos| (F from the Fresnel
    formula written here). Detects a lobe probability or weight that is off, and a diffuse pdf that
    ignores the delta lobe's share."""
    wo = direction(0.6)
    mat = material(B.COATED, alpha=0.0, **COAT)
    u = np.random.default_rng(3).random((N, 3))
    wi, beta, pdf, delta = B.sample_batch(*mat, 0, tile(wo, N), u, True)
    _, val, prob = B.delta_lobe(B.bsdf_row(*mat, 0), tuple(wo), False, True)
    f_share = delta.mean()
    assert abs(f_share - prob) <= Z * math.sqrt(prob * (1 - prob) / N), (f_share, prob)
    np.testing.assert_allclose(wi[delta], np.tile([-wo[0], -wo[1], wo[2]], (int(delta.sum()), 1)), atol=1e-12)
    np.testing.assert_allclose(pdf[delta], prob, rtol=1e-12)
    wi_nan = np.where((~delta)[:, None] & (pdf > 0)[:, None], wi, np.nan)
    chi = ChiSquareTest(lambda uu: wi_nan, pdf_fn(mat, wo), n=N, seed=3)
    assert chi.run(ntests=NTESTS), chi.message
    assert abs(chi.pdf_integral - (1.0 - prob)) <= 1e-6 + chi.quad_error
    # Fresnel of n = 1.49 at cos 0.6, written out: s- and p-polarised amplitudes
    n, ci = 1.49, 0.6
    ct = math.sqrt(1 - (1 - ci * ci) / n ** 2)
    fr = 0.5 * (((ci - n * ct) / (ci + n * ct)) ** 2 + ((n * ci - ct) / (n * ci + ct)) ** 2)
    np.testing.assert_allclose(val, (fr, fr, fr), rtol=1e-12)
    cells, err, info = sphere_grid().integrate(eval_fn(mat, wo), tol_total=lambda tot: 1e-6)
    assert info["converged"]
    expect = fr + cells.reshape(-1, 3).sum(axis=0)
    se = beta.std(axis=0) / math.sqrt(N)
    assert np.all(np.abs(beta.mean(axis=0) - expect) <= Z * np.sqrt(se ** 2 + err.reshape(-1, 3).sum(0) ** 2)), \
        (beta.mean(axis=0), expect)


@pytest.mark.parametrize("t,kw", [(B.DIFFUSE, dict(clear=0.35)), (B.CONDUCTOR, dict(alpha=0.2, clear=0.6))],
                         ids=["diffuse", "conductor"])
def test_opacity_mask_passes_straight_through(t, kw):
    """An opacity mask (params[P_CLEAR] = 1 - opacity): samples flagged delta go straight through
    (wi = -wo) with frequency `clear` (binomial z-test), weight 1; the others follow the pdf
    (chi-square: the pdf integrates to (1 - clear) P(success)); eval is (1 - clear) times the
    unmasked BSDF's (written here from the same material without the mask); the mean weight is
    clear plus the integral of f |cos|. Detects a pass drawn too often or too rarely, or a BSDF
    part not scaled by the opacity."""
    wo = direction(0.7)
    mat = material(t, **kw)
    bare = material(t, **dict(kw, clear=0.0))
    c = kw["clear"]
    u = np.random.default_rng(4).random((N, 3))
    wi, beta, pdf, delta = B.sample_batch(*mat, 0, tile(wo, N), u, True)
    assert abs(delta.mean() - c) <= Z * math.sqrt(c * (1 - c) / N), delta.mean()
    np.testing.assert_allclose(wi[delta], np.tile(-wo, (int(delta.sum()), 1)), atol=1e-15)
    assert np.all(beta[delta] == 1.0) and np.all(pdf[delta] == c)
    wi_nan = np.where((~delta & (pdf > 0))[:, None], wi, np.nan)
    chi = ChiSquareTest(lambda uu: wi_nan, pdf_fn(mat, wo), n=N, seed=4)
    assert chi.run(ntests=NTESTS), chi.message
    d = random_dirs(np.random.default_rng(5), 1000)
    np.testing.assert_allclose(B.eval_batch(*mat, 0, tile(wo, 1000), d, True),
                               (1 - c) * B.eval_batch(*bare, 0, tile(wo, 1000), d, True), rtol=1e-12)
    _, val, prob = B.delta_lobe(B.bsdf_row(*mat, 0), tuple(wo), True, True)
    assert prob == c and val == (c, c, c)
    cells, err, info = sphere_grid().integrate(eval_fn(mat, wo), tol_total=lambda tot: 1e-6)
    expect = c + cells.reshape(-1, 3).sum(axis=0)
    se = beta.std(axis=0) / math.sqrt(N)
    assert np.all(np.abs(beta.mean(axis=0) - expect) <= Z * np.sqrt(se ** 2 + err.reshape(-1, 3).sum(0) ** 2))


# --- Reciprocity ---------------------------------------------------------------------------------
def random_dirs(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize(
    "t, kw",
    [
        (B.DIFFUSE, {}),
        (B.CONDUCTOR, dict(alpha=0.05)),
        (B.CONDUCTOR, dict(alpha=0.4)),
        (B.PLASTIC, dict(alpha=0.2, kd=PLASTIC_KD, ks=PLASTIC_KS)),
    ],
    ids=["diffuse", "conductor-0.05", "conductor-0.4", "plastic"],
)
def test_reciprocity(t, kw):
    rng = np.random.default_rng(7)
    mat = material(t, **kw)
    wo, wi = random_dirs(rng, 20000), random_dirs(rng, 20000)
    wi[:, 2] = np.abs(wi[:, 2]) * np.sign(wo[:, 2])  # same side: reflection
    f_oi = B.eval_batch(*mat, 0, wo, wi, True) / np.abs(wi[:, 2:3])
    f_io = B.eval_batch(*mat, 0, wi, wo, True) / np.abs(wo[:, 2:3])
    assert np.all(f_oi > 0.0)
    np.testing.assert_allclose(f_oi, f_io, rtol=1e-9)


@pytest.mark.parametrize("alpha, ior", [(0.1, 1.5), (0.5, 1.33)])
def test_rough_dielectric_adjoint(alpha, ior):
    """f in radiance mode at (wo, wi) equals f in importance mode at (wi, wo), for reflection and
    refraction; the two modes differ by (n_i / n_o)^2 across the interface only."""
    rng = np.random.default_rng(8)
    mat = material(B.ROUGH_DIELECTRIC, alpha=alpha, ior=ior)
    wo, wi = random_dirs(rng, 20000), random_dirs(rng, 20000)
    f_rad = B.eval_batch(*mat, 0, wo, wi, True)[:, 0] / np.abs(wi[:, 2])
    f_imp = B.eval_batch(*mat, 0, wi, wo, False)[:, 0] / np.abs(wo[:, 2])
    np.testing.assert_allclose(f_rad, f_imp, rtol=1e-6, atol=1e-300)
    trans = wo[:, 2] * wi[:, 2] < 0.0
    assert np.sum(f_rad[trans] > 0) > 1000 and np.sum(f_rad[~trans] > 0) > 1000
    # Mode ratio: eta^2 = (n_i / n_o)^2 for refraction, 1 for reflection
    f_imp_same = B.eval_batch(*mat, 0, wo, wi, False)[:, 0] / np.abs(wi[:, 2])
    eta = np.where(wo[:, 2] > 0, ior, 1.0 / ior)
    ratio = np.where(trans, eta**2, 1.0)
    np.testing.assert_allclose(f_imp_same, f_rad * ratio, rtol=1e-12, atol=1e-300)


def test_rough_dielectric_radiance_weight_scale():
    """Sampled refractions in radiance mode weigh (n_o / n_i)^2 times the importance weight."""
    rng = np.random.default_rng(9)
    mat = material(B.ROUGH_DIELECTRIC, alpha=0.3, ior=1.5)
    wo = random_dirs(rng, 50000)
    u = rng.random((50000, 3))
    wi_r, b_r, p_r, _ = B.sample_batch(*mat, 0, wo, u, True)
    wi_i, b_i, p_i, _ = B.sample_batch(*mat, 0, wo, u, False)
    np.testing.assert_array_equal(wi_r, wi_i)
    np.testing.assert_array_equal(p_r, p_i)
    eta = np.where(wo[:, 2] > 0, 1.5, 1.0 / 1.5)
    trans = wo[:, 2] * wi_r[:, 2] < 0.0
    scale = np.where(trans, 1.0 / eta**2, 1.0)
    np.testing.assert_allclose(b_r, b_i * scale[:, None], rtol=1e-12)


# --- Delta materials -----------------------------------------------------------------------------
def test_mirror():
    rng = np.random.default_rng(3)
    mat = material(B.MIRROR, ks=KS)
    wo = random_dirs(rng, 1000)
    wo[:3] = [[0, 0, 1], [0, 0, -1], [0.6, 0, -0.8]]
    wi, beta, pdf, delta = B.sample_batch(*mat, 0, wo, rng.random((1000, 3)), True)
    np.testing.assert_array_equal(wi, wo * [-1, -1, 1])
    np.testing.assert_array_equal(beta, np.tile(KS, (1000, 1)))
    assert np.all(pdf == 1.0) and np.all(delta)
    assert np.all(B.eval_batch(*mat, 0, wo, wi, True) == 0.0)
    assert np.all(B.pdf_batch(*mat, 0, wo, wi) == 0.0)
    assert B.bsdf_is_delta(B.bsdf_row(*mat, 0))
    # Grazing wo (in the surface plane) gives no sample
    flat = np.array([[1.0, 0, 0]])
    wi, beta, pdf, delta = B.sample_batch(*mat, 0, flat, np.full((1, 3), 0.5), True)
    assert pdf[0] == 0.0 and np.all(beta == 0.0) and not delta[0]


def fresnel_reference(cos_o, n_o, n_i):
    """Unpolarised Fresnel reflectance from the s and p amplitude coefficients (slow twin)."""
    sin_o = np.sqrt(1.0 - cos_o**2)
    sin_t = n_o / n_i * sin_o
    if sin_t >= 1.0:
        return 1.0
    cos_t = np.sqrt(1.0 - sin_t**2)
    rs = (n_o * cos_o - n_i * cos_t) / (n_o * cos_o + n_i * cos_t)
    rp = (n_i * cos_o - n_o * cos_t) / (n_i * cos_o + n_o * cos_t)
    return 0.5 * (rs**2 + rp**2)


def test_fresnel_dielectric_against_reference():
    for ior in (1.5, 1.33, 2.4):
        normal = ((ior - 1) / (ior + 1)) ** 2
        assert B.fresnel_dielectric(1.0, ior)[0] == pytest.approx(normal, rel=1e-12)
        for c in np.linspace(0.0, 1.0, 101):
            for n_o, n_i in ((1.0, ior), (ior, 1.0)):
                f, cos_t = B.fresnel_dielectric(c, n_i / n_o)
                assert f == pytest.approx(fresnel_reference(c, n_o, n_i), rel=1e-10, abs=1e-14)
                assert 0.0 <= f <= 1.0


@pytest.mark.parametrize(
    "ior, z", DIELECTRIC_CASES, ids=[f"ior{a}-wo{b}" for a, b in DIELECTRIC_CASES]
)
def test_smooth_dielectric(ior, z):
    n = 200_000
    mat = material(B.DIELECTRIC, ior=ior)
    wo = direction(z, phi=1.1)
    n_o, n_i = (1.0, ior) if z > 0 else (ior, 1.0)
    F = fresnel_reference(abs(z), n_o, n_i)
    rng = np.random.default_rng(int(ior * 100) + int(z * 10) + 50)
    u = rng.random((n, 3))
    wi, beta, pdf, delta = B.sample_batch(*mat, 0, tile(wo, n), u, False)
    assert np.all(delta)
    refl = wi[:, 2] * z > 0
    # Reflections: mirror direction, probability F, weight 1
    np.testing.assert_allclose(wi[refl], tile(wo * [-1, -1, 1], refl.sum()), atol=1e-15)
    np.testing.assert_allclose(pdf[refl], F, rtol=1e-10)
    # Lobe frequencies follow the exact Fresnel reflectance (binomial z-test)
    k = refl.sum()
    if 0.0 < F < 1.0:
        zstat = (k - n * F) / math.sqrt(n * F * (1 - F))
        assert abs(zstat) <= Z, (k / n, F)
    else:
        assert k == (n if F == 1.0 else 0)
    # Lossless interface: every importance weight is 1, so their mean is 1
    np.testing.assert_array_equal(beta, 1.0)
    tr = ~refl
    if F == 1.0:
        assert abs(z) < math.sqrt(1 - (n_i / n_o) ** 2) + 1e-12  # total internal reflection
        return
    # Refractions: Snell's law, plane of incidence, opposite side, unit length, pdf 1 - F
    w = wi[tr]
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, rtol=1e-12)
    sin_o = math.sqrt(1 - z * z)
    np.testing.assert_allclose(n_i * np.linalg.norm(w[:, :2], axis=1), n_o * sin_o, rtol=1e-12)
    assert np.all(w[:, 2] * z < 0)
    phi_o = math.atan2(wo[1], wo[0])
    np.testing.assert_allclose(np.cos(np.arctan2(w[:, 1], w[:, 0]) - phi_o), -1.0, atol=1e-12)
    np.testing.assert_allclose(pdf[tr], 1.0 - F, rtol=1e-10)
    # Radiance mode scales refraction by (n_o / n_i)^2
    _, beta_r, _, _ = B.sample_batch(*mat, 0, tile(wo, n), u, True)
    np.testing.assert_allclose(beta_r[tr], (n_o / n_i) ** 2, rtol=1e-12)
    np.testing.assert_array_equal(beta_r[refl], 1.0)
    assert np.all(B.eval_batch(*mat, 0, tile(wo, 100), wi[:100], True) == 0.0)
    assert np.all(B.pdf_batch(*mat, 0, tile(wo, 100), wi[:100]) == 0.0)


def test_total_internal_reflection_grazing_inside():
    mat = material(B.DIELECTRIC, ior=1.5)
    wo = direction(-0.1)
    u = np.random.default_rng(4).random((1000, 3))
    wi, beta, pdf, delta = B.sample_batch(*mat, 0, tile(wo, 1000), u, True)
    np.testing.assert_array_equal(wi, tile(wo * [-1, -1, 1], 1000))
    assert np.all(pdf == 1.0) and np.all(beta == 1.0) and np.all(delta)
    # The rough dielectric reflects (almost) everything too; what refracts has a tilted facet
    mat = material(B.ROUGH_DIELECTRIC, alpha=0.05, ior=1.5)
    wi, beta, pdf, delta = B.sample_batch(*mat, 0, tile(wo, 1000), u, True)
    assert np.mean(wi[:, 2] < 0) > 0.9


# --- Robustness ----------------------------------------------------------------------------------
EDGE_PARAMS = [
    (B.DIFFUSE, dict(kd=(0, 0, 0))),
    (B.CONDUCTOR, dict(alpha=0.0)),
    (B.CONDUCTOR, dict(alpha=1e-4)),
    (B.CONDUCTOR, dict(alpha=3.0, ks=(1, 1, 1))),
    (B.MIRROR, {}),
    (B.DIELECTRIC, dict(ior=1.0)),
    (B.DIELECTRIC, dict(ior=2.4)),
    (B.ROUGH_DIELECTRIC, dict(alpha=0.0, ior=1.5)),
    (B.ROUGH_DIELECTRIC, dict(alpha=1e-4, ior=1.0)),
    (B.ROUGH_DIELECTRIC, dict(alpha=3.0, ior=1.33)),
    (B.PLASTIC, dict(alpha=0.0, kd=(0, 0, 0), ks=(0, 0, 0))),
    (B.PLASTIC, dict(alpha=1e-4)),
    (B.COATED, dict(alpha=0.0, kd=(0, 0, 0), ks=(0, 0, 0))),
    (B.COATED, dict(alpha=1e-4, kd=(1, 1, 1), flags=B.NONLINEAR)),
    (B.COATED, dict(alpha=3.0, ior=1.0, flags=B.BECKMANN)),
    (B.DIFFUSE, dict(clear=1.0)),
    (B.COATED, dict(alpha=0.0, clear=0.5)),
]


def edge_directions(rng, n):
    """Random unit vectors plus the degenerate ones: poles, horizon, tiny and subnormal z."""
    d = [random_dirs(rng, n)]
    special = []
    for z in (0.0, 1e-300, -1e-300, 1e-160, 1e-9, -1e-9, 1e-4, 0.999999999, 1.0, -1.0):
        for phi in (0.0, 0.7, math.pi / 2):
            v = direction(z, phi)
            v[2] = z
            special.append(v)
            special.append(v * [1, 1, -1])
    special.append([0.0, 0.0, 1.0])
    special.append([0.0, 0.0, -1.0])
    d.append(np.array(special))
    return np.concatenate(d)


@pytest.mark.parametrize(
    "t, kw", EDGE_PARAMS, ids=[f"{B.TYPE_NAMES[t]}-{kw}" for t, kw in EDGE_PARAMS]
)
def test_finite_outputs(t, kw):
    rng = np.random.default_rng(11)
    mat = material(t, **kw)
    dirs = edge_directions(rng, 2000)
    n = len(dirs)
    # Every wo against every special wi, and random pairs
    wo = np.repeat(dirs[-62:], 62, axis=0)
    wi = np.tile(dirs[-62:], (62, 1))
    wo = np.concatenate([wo, dirs, dirs[::-1]])
    wi = np.concatenate([wi, dirs[::-1], dirs])
    u_edge = np.array([0.0, 1e-300, 0.5, 1.0 - 2.0**-53])
    u = rng.random((len(wo), 3))
    u[: len(u) // 2] = u_edge[rng.integers(0, 4, size=(len(u) // 2, 3))]
    for radiance in (True, False):
        s_wi, beta, pdf, delta = B.sample_batch(*mat, 0, wo, u, radiance)
        f = B.eval_batch(*mat, 0, wo, wi, radiance)
        p = B.pdf_batch(*mat, 0, wo, wi)
        outputs = (("wi", s_wi), ("weight", beta), ("pdf", pdf), ("eval", f), ("pdf_batch", p))
        for name, a in outputs:
            bad = ~np.isfinite(a)
            assert not bad.any(), (name, wo[bad.reshape(len(wo), -1).any(1)][:3])
        assert np.all(beta >= 0.0) and np.all(pdf >= 0.0) and np.all(f >= 0.0) and np.all(p >= 0.0)
        # Zero weight wherever the pdf is zero; unit directions wherever it is not
        assert np.all(beta[pdf == 0.0] == 0.0)
        np.testing.assert_allclose(np.linalg.norm(s_wi[pdf > 0], axis=1), 1.0, rtol=1e-9)
        # Directions in the surface plane never carry energy from a non-delta material
        assert np.all(f[wo[:, 2] == 0.0] == 0.0) and np.all(f[wi[:, 2] == 0.0] == 0.0)
        assert np.all(pdf[wo[:, 2] == 0.0] == 0.0)
    assert n > 2000


# --- Small helpers -------------------------------------------------------------------------------
def test_is_delta_and_albedo():
    kinds = [B.DIFFUSE, B.CONDUCTOR, B.MIRROR, B.DIELECTRIC, B.ROUGH_DIELECTRIC, B.PLASTIC, B.METAL, B.METAL,
             B.THIN_DIELECTRIC, B.COATED, B.COATED]
    assert [B.TYPE_NAMES[k] for k in kinds[:7]] + [B.TYPE_NAMES[k] for k in kinds[8:10]] == list(B.TYPE_NAMES)
    mat_type = np.array(kinds, dtype=np.int32)
    mat_param = np.tile([*KD, *KS, 1e-5, 1.5, *GOLD["eta"], *GOLD["k"], 0, 0], (11, 1))
    mat_param[7, 6] = 0.0  # a smooth METAL
    mat_param[9, 6] = 0.0  # a smooth COATED: a delta lobe beside a diffuse one
    assert [B.bsdf_is_delta(B.bsdf_row(mat_type, mat_param, m)) for m in range(11)] == [
        False, False, True, True, False, False, False, True, True, False, False,
    ]
    assert [B.bsdf_has_delta(B.bsdf_row(mat_type, mat_param, m)) for m in range(11)] == [
        False, False, True, True, False, False, False, True, True, True, False,
    ]
    albedo = [B.bsdf_albedo(B.bsdf_row(mat_type, mat_param, m)) for m in range(11)]
    assert albedo[9] == KD and albedo[10] == KD
    assert albedo[0] == KD and albedo[1] == KS and albedo[2] == KS
    assert albedo[3] == (1.0, 1.0, 1.0) and albedo[4] == (1.0, 1.0, 1.0) and albedo[8] == (1.0, 1.0, 1.0)
    np.testing.assert_allclose(albedo[5], np.minimum(np.add(KD, KS), 1.0))
    # METAL: ks times the normal-incidence reflectance of eta + i k, |(n - 1 + ik) / (n + 1 + ik)|^2
    n, k = np.array(GOLD["eta"]), np.array(GOLD["k"])
    np.testing.assert_allclose(albedo[6], np.array(KS) * ((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2), rtol=1e-12)


def test_lum_and_ns_to_alpha():
    assert B.lum((1.0, 1.0, 1.0)) == pytest.approx(1.0)
    assert B.lum((0.0, 1.0, 0.0)) == pytest.approx(0.7152)
    assert B.ns_to_alpha(0.0) == pytest.approx(1.0)
    assert B.ns_to_alpha(98.0) == pytest.approx(math.sqrt(0.02))
    np.testing.assert_allclose(B.ns_to_alpha(np.array([0.0, 2.0])), [1.0, math.sqrt(0.5)])


def test_sidak_level():
    # Guard against a silently lax suite: the corrected level is well below 1%
    assert sidak(NTESTS) < 0.01 / NTESTS * 1.01


@pytest.mark.parametrize("cos_i", [1.0, 0.7, 0.2, 0.0])
def test_conductor_none_reflects_everything_at_every_angle(cos_i):
    """Mitsuba's conductor material "none" (eta = k = 0) is a perfect mirror: Fresnel 1 at every
    incidence. At exactly normal incidence the exact formula's p term is 0/0: the AOV's albedo
    (bsdf_albedo, which evaluates at cos 1) came out NaN on Mitsuba's bathroom mirror, and the
    images denoised or reconstructed by GradNet with it. Detects that NaN and any other value."""
    from tracer.bsdfs import METAL, bsdf_albedo, fresnel_conductor

    assert fresnel_conductor(cos_i, 0.0, 0.0) == 1.0
    prm = np.zeros(17)
    prm[3:6] = (0.9, 0.8, 0.7)  # ks; eta and k (8:14) zero
    assert bsdf_albedo((np.int32(METAL), tuple(prm))) == pytest.approx((0.9, 0.8, 0.7), abs=1e-15)


# --- eval and pdf in one call --------------------------------------------------------------------
@pytest.mark.parametrize("masked", [False, True], ids=["opaque", "clear0.3"])
@pytest.mark.parametrize("radiance", [True, False], ids=["radiance", "importance"])
def test_eval_pdf_is_eval_and_pdf_bit_for_bit(radiance, masked):
    """bsdf_eval_pdf, which evaluates a lobe once for both, gives bsdf_eval's f and bsdf_pdf's
    density exactly, for every case above (every non-delta material), a mirror and a smooth
    dielectric (zero), a one-sided conductor seen from below, with and without an opacity mask, for
    radiance and importance: detects a lobe whose f or density the combined call takes from a
    different formula or argument."""
    rng = np.random.default_rng(11)
    kinds = [(t, kw, z) for _, t, kw, z in CASES]
    kinds += [(B.MIRROR, {}, 0.6), (B.DIELECTRIC, {}, 0.6), (B.CONDUCTOR, dict(flags=B.ONE_SIDED), -0.5)]
    for t, kw, z in kinds:
        mat = material(t, **dict(kw, clear=0.3 if masked else 0.0))
        wo = tile(direction(z), 500)
        wi = random_dirs(rng, 500)
        f, pdf = B.eval_pdf_batch(*mat, 0, wo, wi, radiance)
        assert np.array_equal(f, B.eval_batch(*mat, 0, wo, wi, radiance)), (t, kw, z)
        assert np.array_equal(pdf, B.pdf_batch(*mat, 0, wo, wi)), (t, kw, z)
        if t not in (B.MIRROR, B.DIELECTRIC) and not kw.get("flags", 0) & B.ONE_SIDED:
            assert (pdf > 0).any() and (f > 0).any(), (t, kw, z)  # not a comparison of zeros only
