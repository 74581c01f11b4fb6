"""The BSDFs against Mitsuba 3 (the `scalar_rgb` variant: float32, no LLVM), where Mitsuba defines
the same BSDF: `diffuse`; `roughconductor` and `conductor` with `material: none` (F = 1 times the
specular reflectance, our CONDUCTOR and MIRROR with ks = 1 where Schlick's F is exactly 1);
`roughdielectric` (GGX, visible-normal sampling) and `dielectric`, from outside and inside.

For each, over a grid of direction pairs in both hemispheres: f |cos wi| (Mitsuba's `eval`) and the
sampling density (`pdf`) to 1e-4 relative (Mitsuba computes in float32), and for Mitsuba's own
samples, its sample weight against ours at the direction it drew (f |cos| / pdf, ours evaluated).

One difference is deliberate: our microfacet BSDFs mask with the height-correlated Smith term
1 / (1 + L(wo) + L(wi)) (Heitz 2014), Mitsuba 3 with the separable G1(wo) G1(wi) = 1 / ((1 + L(wo))
(1 + L(wi))); they differ by the factor (1 + L(wo) + L(wi)) / ((1 + L(wo)) (1 + L(wi))), which this
test computes from the GGX Lambda written out below and applies to our f before comparing (on this
grid the factor reaches 0.08% at alpha 0.05, 18% at 0.3 and 92% at 0.8, at the most grazing
pairs). The densities (visible normals: G1 only) need no such factor.
Detects a wrong microfacet distribution, masking term, Fresnel, refraction scaling (the
radiance-mode (n_o / n_i)^2), lobe-selection probability or Jacobian: each changes these values by
far more than float32 rounding. Skipped without Mitsuba (pip install -e ".[mitsuba]")."""
import numpy as np
import pytest

from tracer import bsdfs as B
from tracer.coating import TABLE_RES
from tracer.metals import metal_ior

mi = pytest.importorskip("mitsuba")
mi.set_variant("scalar_rgb")

RTOL = 1e-4


def _dirs(n, seed, lower=False):
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.1, 0.99, n)  # no grazing directions (float32 loses them)
    phi = rng.uniform(0, 2 * np.pi, n)
    r = np.sqrt(1 - z * z)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), -z if lower else z], axis=1)
    return d


def _si(wo):
    si = mi.SurfaceInteraction3f()
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    si.wi = mi.Vector3f(*wo)
    return si


def _mitsuba_eval_pdf(bsdf, wo, wi):
    ctx = mi.BSDFContext()
    f = np.empty((len(wo), 3))
    p = np.empty(len(wo))
    for k in range(len(wo)):
        si = _si(wo[k])
        v = mi.Vector3f(*wi[k])
        f[k] = np.array(bsdf.eval(ctx, si, v))
        p[k] = bsdf.pdf(ctx, si, v)
    return f, p


CASES = [
    ("diffuse", B.DIFFUSE, [0.3, 0.5, 0.7, 0, 0, 0, 0, 1.5],
     {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.3, 0.5, 0.7]}}),
    *[(f"roughconductor-{a}", B.CONDUCTOR, [0, 0, 0, 1, 1, 1, a, 1.5],
       {"type": "roughconductor", "material": "none", "distribution": "ggx", "alpha": a}) for a in (0.05, 0.3, 0.8)],
    *[(f"roughdielectric-{a}-{n}", B.ROUGH_DIELECTRIC, [0, 0, 0, 0, 0, 0, a, n],
       {"type": "roughdielectric", "distribution": "ggx", "alpha": a, "int_ior": n, "ext_ior": 1.0})
      for a, n in ((0.05, 1.5), (0.3, 1.5), (0.7, 1.33))],
]


def _lambda(w, alpha):
    """GGX Smith Lambda of local directions w (n, 3): (-1 + sqrt(1 + alpha^2 tan^2)) / 2."""
    c2 = w[:, 2] ** 2
    return (-1.0 + np.sqrt(1.0 + alpha * alpha * (1.0 - c2) / c2)) / 2.0


def _separable(mtype, param, wo, wi):
    """The factor from our height-correlated masking to Mitsuba's separable one (1 for diffuse)."""
    if mtype == B.DIFFUSE:
        return np.ones(len(wo))
    lo, li = _lambda(wo, param[6]), _lambda(wi, param[6])
    return (1.0 + lo + li) / ((1.0 + lo) * (1.0 + li))


def _bp(mtype, param):
    """A bp for the jitted BSDF functions (an untextured row)."""
    param = list(param) + [0.0] * (B.N_PARAM - len(param))
    return mtype, tuple(float(x) for x in param)


def _ours(mtype, param):
    return np.array([mtype], np.int32), np.array([param], np.float64)


@pytest.mark.parametrize("name,mtype,param,spec", CASES, ids=[c[0] for c in CASES])
def test_eval_and_pdf_match_mitsuba(name, mtype, param, spec):
    bsdf = mi.load_dict(spec)
    mt, mp = _ours(mtype, param)
    sides = [(False, False), (False, True)]
    if mtype == B.ROUGH_DIELECTRIC:
        sides += [(True, True), (True, False)]  # from inside the medium as well
    for k, (wo_low, wi_low) in enumerate(sides):
        wo = _dirs(200, 10 + k, wo_low)
        wi = _dirs(200, 20 + k, wi_low)
        f_mi, p_mi = _mitsuba_eval_pdf(bsdf, wo, wi)
        f = B.eval_batch(mt, mp, 0, wo, wi, True) * _separable(mtype, param, wo, wi)[:, None]
        p = B.pdf_batch(mt, mp, 0, wo, wi)
        np.testing.assert_allclose(f, f_mi, rtol=RTOL, atol=1e-6 * max(f_mi.max(), 1e-3), err_msg=f"{name} f {k}")
        np.testing.assert_allclose(p, p_mi, rtol=RTOL, atol=1e-6 * max(p_mi.max(), 1e-3), err_msg=f"{name} pdf {k}")


@pytest.mark.parametrize("name,mtype,param,spec", CASES, ids=[c[0] for c in CASES])
def test_sample_weights_match_mitsuba(name, mtype, param, spec):
    """Mitsuba's sample (direction, weight, pdf) against our eval / pdf at that direction."""
    bsdf = mi.load_dict(spec)
    mt, mp = _ours(mtype, param)
    rng = np.random.default_rng(5)
    ctx = mi.BSDFContext()
    n = 0
    for wo in np.concatenate([_dirs(100, 3), _dirs(100, 4, True) if mtype == B.ROUGH_DIELECTRIC else _dirs(0, 4)]):
        bs, w = bsdf.sample(ctx, _si(wo), float(rng.random()), mi.Point2f(*rng.random(2)))
        if not (bs.pdf > 0 and max(np.array(w)) > 0):
            continue  # a failed sample (Mitsuba keeps its pdf but zeroes its weight)
        wi = np.array(bs.wo, dtype=np.float64)[None]
        if abs(wi[0, 2]) < 0.05:
            continue  # grazing: float32 direction too coarse for 1e-4
        f = B.eval_batch(mt, mp, 0, wo[None], wi, True)[0] * _separable(mtype, param, wo[None], wi)[0]
        p = B.pdf_batch(mt, mp, 0, wo[None], wi)[0]
        np.testing.assert_allclose(p, bs.pdf, rtol=10 * RTOL, err_msg=name)
        np.testing.assert_allclose(f / p, np.array(w), rtol=10 * RTOL, atol=1e-6, err_msg=name)
        n += 1
    assert n > 50


def test_smooth_dielectric_and_mirror_lobes_match_mitsuba():
    """Delta lobes: Mitsuba's `dielectric` reflection (sample1 = 0) and refraction (sample1 -> 1),
    and `conductor` material none, against our delta_lobe's direction, value and probability."""
    ctx = mi.BSDFContext()
    for n in (1.5, 1.33):
        bsdf = mi.load_dict({"type": "dielectric", "int_ior": n, "ext_ior": 1.0})
        bp = _bp(B.DIELECTRIC, (0.0,) * 7 + (n,) + (0.0,) * 8)
        for wo in np.concatenate([_dirs(50, 7), _dirs(50, 8, True)]):
            for transmit, u in ((False, 0.0), (True, 0.99999)):
                bs, w = bsdf.sample(ctx, _si(wo), u, mi.Point2f(0.5, 0.5))
                wi, val, prob = B.delta_lobe(bp, tuple(wo), transmit, True)
                if prob == 0.0:  # total internal reflection: Mitsuba reflects whatever the sample
                    assert transmit and np.array(bs.wo)[2] * wo[2] > 0
                    continue
                np.testing.assert_allclose(wi, np.array(bs.wo), atol=1e-5)
                np.testing.assert_allclose(prob, bs.pdf, rtol=RTOL)
                np.testing.assert_allclose(np.array(val) / prob, np.array(w), rtol=RTOL)
    mirror = mi.load_dict({"type": "conductor", "material": "none"})
    bp = _bp(B.MIRROR, (0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 1.5) + (0.0,) * 8)
    for wo in _dirs(50, 9):
        bs, w = mirror.sample(ctx, _si(wo), 0.5, mi.Point2f(0.5, 0.5))
        wi, val, prob = B.delta_lobe(bp, tuple(wo), False, True)
        np.testing.assert_allclose(wi, np.array(bs.wo), atol=1e-5)
        np.testing.assert_allclose(np.array(val) / prob, np.array(w), rtol=RTOL)


def _metal(ks, alpha, eta, k, flags=0):
    return [0, 0, 0, *ks, alpha, 1.5, *eta, *k, flags, 0]


METAL_CASES = [
    (f"metal-{m}-{a}-{d}", B.METAL, _metal([1, 1, 1], a, *metal_ior(m), B.BECKMANN if d == "beckmann" else 0),
     {"type": "roughconductor", "material": m, "distribution": d, "alpha": a, "sample_visible": d == "ggx"})
    for m, a, d in (("Au", 0.1, "ggx"), ("Cu", 0.4, "ggx"), ("Al", 0.3, "beckmann"), ("Cr", 0.05, "beckmann"))
] + [
    ("metal-eta-k-ks", B.METAL, _metal([0.9, 0.6, 0.3], 0.2, (1.1, 0.9, 0.5), (3.0, 2.5, 2.0)),
     {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2,
      "eta": {"type": "rgb", "value": [1.1, 0.9, 0.5]}, "k": {"type": "rgb", "value": [3.0, 2.5, 2.0]},
      "specular_reflectance": {"type": "rgb", "value": [0.9, 0.6, 0.3]}}),
]
ONE_SIDED_CASES = [
    ("diffuse-one-sided", B.DIFFUSE, [0.3, 0.5, 0.7, 0, 0, 0, 0, 1.5, 0, 0, 0, 0, 0, 0, B.ONE_SIDED, 0],
     {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.3, 0.5, 0.7]}}),
    ("metal-one-sided", B.METAL, _metal([1, 1, 1], 0.3, *metal_ior("Ag"), B.ONE_SIDED),
     {"type": "roughconductor", "material": "Ag", "distribution": "ggx", "alpha": 0.3}),
]


def _metal_eval_pdf_against(name, mtype, param, spec, sides):
    bsdf = mi.load_dict(spec)
    mt, mp = _ours(mtype, param)
    worst = 0.0
    for k, (wo_low, wi_low) in enumerate(sides):
        wo, wi = _dirs(200, 40 + k, wo_low), _dirs(200, 50 + k, wi_low)
        f_mi, p_mi = _mitsuba_eval_pdf(bsdf, wo, wi)
        f = B.eval_batch(mt, mp, 0, wo, wi, True)
        p = B.pdf_batch(mt, mp, 0, wo, wi)
        np.testing.assert_allclose(f, f_mi, rtol=RTOL, atol=1e-6 * max(f_mi.max(), 1e-3), err_msg=f"{name} f {k}")
        np.testing.assert_allclose(p, p_mi, rtol=RTOL, atol=1e-6 * max(p_mi.max(), 1e-3), err_msg=f"{name} pdf {k}")
        big = f_mi > 1e-6 * max(f_mi.max(), 1e-30)
        if big.any():
            worst = max(worst, float(np.max(np.abs(f[big] - f_mi[big]) / f_mi[big])))
    return worst


@pytest.mark.parametrize("name,mtype,param,spec", METAL_CASES, ids=[c[0] for c in METAL_CASES])
def test_metal_matches_mitsubas_roughconductor(name, mtype, param, spec):
    """METAL (complex Fresnel with named or given eta and k, specular_reflectance, GGX with visible
    normals or Beckmann with D cos sampling, separable masking) against Mitsuba's roughconductor:
    eval and pdf on the grid, the weights of Mitsuba's samples (two-sided: Mitsuba's
    roughconductor is one-sided, so only wo above)."""
    _metal_eval_pdf_against(name, mtype, param, spec, [(False, False), (False, True)])
    bsdf = mi.load_dict(spec)
    mt, mp = _ours(mtype, param)
    rng = np.random.default_rng(6)
    ctx = mi.BSDFContext()
    n = 0
    for wo in _dirs(100, 61):
        bs, w = bsdf.sample(ctx, _si(wo), float(rng.random()), mi.Point2f(*rng.random(2)))
        wi = np.array(bs.wo, dtype=np.float64)[None]
        if not (bs.pdf > 0 and max(np.array(w)) > 0) or wi[0, 2] < 0.05:
            continue
        f = B.eval_batch(mt, mp, 0, wo[None], wi, True)[0]
        p = B.pdf_batch(mt, mp, 0, wo[None], wi)[0]
        np.testing.assert_allclose(p, bs.pdf, rtol=10 * RTOL, err_msg=name)
        np.testing.assert_allclose(f / p, np.array(w), rtol=10 * RTOL, atol=1e-6, err_msg=name)
        n += 1
    assert n > 50


@pytest.mark.parametrize("name,mtype,param,spec", ONE_SIDED_CASES, ids=[c[0] for c in ONE_SIDED_CASES])
def test_one_sided_bsdfs_are_black_from_behind_as_mitsubas(name, mtype, param, spec):
    """The ONE_SIDED flag: Mitsuba's BSDFs without `twosided` are black when wo is below the
    surface; ours agree on all four hemisphere pairs (detects a flag ignored, or applied to wi)."""
    _metal_eval_pdf_against(name, mtype, param, spec, [(False, False), (False, True), (True, True), (True, False)])
    mt, mp = _ours(mtype, param)
    wo = _dirs(50, 70, True)
    wi, wt, pdf, _ = B.sample_batch(mt, mp, 0, wo, np.random.default_rng(1).random((50, 3)), True)
    assert np.all(pdf == 0) and np.all(wt == 0)


def test_smooth_metal_and_thin_dielectric_match_mitsuba():
    """METAL at alpha 0 (Mitsuba's conductor) and THIN_DIELECTRIC (thindielectric): the delta lobes'
    directions, values and probabilities."""
    ctx = mi.BSDFContext()
    eta, k = metal_ior("Cu")
    bsdf = mi.load_dict({"type": "conductor", "material": "Cu"})
    bp = _bp(B.METAL, _metal([1, 1, 1], 0.0, eta, k))
    assert B.bsdf_is_delta(bp)
    for wo in _dirs(50, 80):
        bs, w = bsdf.sample(ctx, _si(wo), 0.5, mi.Point2f(0.5, 0.5))
        wi, wt, pdf, delta = B.bsdf_sample(bp, tuple(wo), 0.5, 0.5, 0.5, True, np.zeros((1, TABLE_RES)))
        assert delta and pdf == 1.0
        np.testing.assert_allclose(wi, np.array(bs.wo), atol=1e-5)
        np.testing.assert_allclose(wt, np.array(w), rtol=RTOL)
    for n in (1.5, 1.33):
        bsdf = mi.load_dict({"type": "thindielectric", "int_ior": n, "ext_ior": 1.0})
        bp = _bp(B.THIN_DIELECTRIC, (0.0,) * 7 + (n,) + (0.0,) * 8)
        for wo in np.concatenate([_dirs(50, 81), _dirs(50, 82, True)]):
            for transmit, u in ((False, 0.0), (True, 0.99999)):
                bs, w = bsdf.sample(ctx, _si(wo), u, mi.Point2f(0.5, 0.5))
                wi, val, prob = B.delta_lobe(bp, tuple(wo), transmit, True)
                np.testing.assert_allclose(wi, np.array(bs.wo), atol=1e-5)
                np.testing.assert_allclose(prob, bs.pdf, rtol=RTOL)
                np.testing.assert_allclose(np.array(val) / prob, np.array(w), rtol=RTOL)


@pytest.mark.parametrize("name", ["Au", "Cu", "Al", "Ag", "Cr", "W", "TiN"])
def test_named_metals_are_mitsubas(name):
    """tracer.metals holds what Mitsuba's scalar_rgb variant uses for its named conductors."""
    p = mi.traverse(mi.load_dict({"type": "conductor", "material": name}))
    eta, k = metal_ior(name)
    np.testing.assert_allclose(eta, np.array(p["eta.value"]), rtol=1e-5)
    np.testing.assert_allclose(k, np.array(p["k.value"]), rtol=1e-5)


def _coat(kd, ks, alpha, eta, flags=0):
    return [*kd, *ks, alpha, eta, 0, 0, 0, 0, 0, 0, flags, 0]


def _coat_spec(kind, kd, ks, alpha, eta, dist="ggx", nonlinear=False):
    spec = {"type": kind, "int_ior": eta, "ext_ior": 1.0, "nonlinear": nonlinear,
            "diffuse_reflectance": {"type": "rgb", "value": kd}, "specular_reflectance": {"type": "rgb", "value": ks}}
    if kind == "roughplastic":
        spec.update(alpha=alpha, distribution=dist)
    return spec


COATED_CASES = [
    ("plastic", B.COATED, _coat([0.3, 0.5, 0.7], [1, 1, 1], 0.0, 1.49), _coat_spec("plastic", [0.3, 0.5, 0.7], [1, 1, 1], 0, 1.49)),
    ("plastic-nonlinear-ks", B.COATED, _coat([0.8, 0.2, 0.1], [0.5, 0.6, 0.7], 0.0, 1.6, B.NONLINEAR),
     _coat_spec("plastic", [0.8, 0.2, 0.1], [0.5, 0.6, 0.7], 0, 1.6, nonlinear=True)),
    ("roughplastic-ggx-0.1", B.COATED, _coat([0.3, 0.5, 0.7], [1, 1, 1], 0.1, 1.49),
     _coat_spec("roughplastic", [0.3, 0.5, 0.7], [1, 1, 1], 0.1, 1.49)),
    ("roughplastic-ggx-0.4-nonlinear", B.COATED, _coat([0.9, 0.5, 0.2], [0.8, 0.8, 0.9], 0.4, 1.33, B.NONLINEAR),
     _coat_spec("roughplastic", [0.9, 0.5, 0.2], [0.8, 0.8, 0.9], 0.4, 1.33, nonlinear=True)),
    ("roughplastic-beckmann-0.2", B.COATED, _coat([0.5, 0.4, 0.3], [1, 1, 1], 0.2, 1.5, B.BECKMANN),
     _coat_spec("roughplastic", [0.5, 0.4, 0.3], [1, 1, 1], 0.2, 1.5, dist="beckmann")),
]


@pytest.mark.parametrize("name,mtype,param,spec", COATED_CASES, ids=[c[0] for c in COATED_CASES])
def test_coated_matches_mitsubas_plastics(name, mtype, param, spec):
    """COATED against Mitsuba's plastic / roughplastic (the diffuse base under the coat with its
    internal reflections, `nonlinear`, specular_reflectance; the rough coat's tabulated
    transmittance): eval and pdf of the non-delta part on the grid (wo above: Mitsuba's plastics
    are one-sided), the weights of Mitsuba's samples, and the smooth coat's delta lobe (direction,
    value, probability). Beckmann: Mitsuba samples its visible normals, we sample D cos, so the
    pdfs and sample weights differ by design; eval is compared. Detects a wrong Fresnel, internal
    reflectance, transmittance table, lobe probability or eta^2 factor (each moves values far past
    1e-4)."""
    beck = "beckmann" in name
    bsdf = mi.load_dict(spec)
    mt, mp = _ours(mtype, param)
    for k, wi_low in enumerate((False, True)):
        wo, wi = _dirs(200, 90 + k), _dirs(200, 95 + k, wi_low)
        f_mi, p_mi = _mitsuba_eval_pdf(bsdf, wo, wi)
        f = B.eval_batch(mt, mp, 0, wo, wi, True)
        np.testing.assert_allclose(f, f_mi, rtol=RTOL, atol=1e-6 * max(f_mi.max(), 1e-3), err_msg=f"{name} f {k}")
        if not beck:
            p = B.pdf_batch(mt, mp, 0, wo, wi)
            np.testing.assert_allclose(p, p_mi, rtol=RTOL, atol=1e-6 * max(p_mi.max(), 1e-3), err_msg=f"{name} pdf")
    if beck:
        return
    rng = np.random.default_rng(7)
    ctx = mi.BSDFContext()
    bp = B.bsdf_row(mt, mp, 0)
    n = 0
    for wo in _dirs(150, 98):
        bs, w = bsdf.sample(ctx, _si(wo), float(rng.random()), mi.Point2f(*rng.random(2)))
        wi = np.array(bs.wo, dtype=np.float64)
        if not (bs.pdf > 0 and max(np.array(w)) > 0) or wi[2] < 0.05:
            continue
        if mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta):
            wd, val, prob = B.delta_lobe(bp, tuple(wo), False, True)
            np.testing.assert_allclose(wd, wi, atol=1e-5)
            np.testing.assert_allclose(prob, bs.pdf, rtol=RTOL, err_msg=name)
            np.testing.assert_allclose(np.array(val) / prob, np.array(w), rtol=RTOL, err_msg=name)
        else:
            f = B.eval_batch(mt, mp, 0, wo[None], wi[None], True)[0]
            p = B.pdf_batch(mt, mp, 0, wo[None], wi[None])[0]
            np.testing.assert_allclose(p, bs.pdf, rtol=10 * RTOL, err_msg=name)
            np.testing.assert_allclose(f / p, np.array(w), rtol=10 * RTOL, atol=1e-6, err_msg=name)
        n += 1
    assert n > 100


def test_mask_matches_mitsubas():
    """Mitsuba's `mask` (opacity 0.3) around a two-sided diffuse and a roughconductor, as our
    params[P_CLEAR] = 0.7: eval and pdf of the scattering part (opacity times the nested BSDF's),
    and the null pass (sample1 at or above the opacity: -wo, weight 1, probability 1 - opacity)
    against our delta_lobe's transmitted lobe. Detects a mask applied to the wrong share."""
    ctx = mi.BSDFContext()
    for name, mtype, param, nested in (
            ("diffuse", B.DIFFUSE, [0.3, 0.5, 0.7] + [0] * 13 + [0.7],
             {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.3, 0.5, 0.7]}}}),
            ("metal", B.METAL, _metal([1, 1, 1], 0.3, *metal_ior("Ag")) + [0.7],
             {"type": "roughconductor", "material": "Ag", "distribution": "ggx", "alpha": 0.3})):
        bsdf = mi.load_dict({"type": "mask", "opacity": 0.3, "bsdf": nested})
        mt, mp = _ours(mtype, param)
        wo, wi = _dirs(200, 110), _dirs(200, 111)
        f_mi, p_mi = _mitsuba_eval_pdf(bsdf, wo, wi)
        np.testing.assert_allclose(B.eval_batch(mt, mp, 0, wo, wi, True), f_mi, rtol=RTOL, atol=1e-7, err_msg=name)
        np.testing.assert_allclose(B.pdf_batch(mt, mp, 0, wo, wi), p_mi, rtol=RTOL, atol=1e-7, err_msg=name)
        bp = B.bsdf_row(mt, mp, 0)
        for w in wo[:20]:
            bs, wt = bsdf.sample(ctx, _si(w), 0.65, mi.Point2f(0.5, 0.5))
            d, val, prob = B.delta_lobe(bp, tuple(w), True, True)
            np.testing.assert_allclose(d, np.array(bs.wo), atol=1e-6)
            np.testing.assert_allclose(prob, bs.pdf, rtol=RTOL)
            np.testing.assert_allclose(np.array(val) / prob, np.array(wt), rtol=RTOL)
