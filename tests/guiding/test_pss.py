"""`--guide pss`: the Real NVP warp's contract, and renders that stay unbiased.

The flow (tracer.guiding.pss.flow) is tested for every configuration the guide builds (image:
4 or 6 dims; pixel: 2 or 4 dims with the pixel context) with weights moved off the identity:
- forward then inverse returns the input, both ways (detects a wrong inverse coupling);
- log q from `warp` equals minus the log-determinant of the autograd Jacobian of the whole map,
  written out here in float64 (detects a missing or wrong term of the log-density);
- the density integrates to 1 over the unit cube: a z-test of the mean of q at uniform points
  (detects a density off by a constant factor of more than about 0.1%, e.g. a coupling's
  log-determinant counted twice);
- save and load give the same outputs.
A flow trained on a 2D toy target passes a chi-square test of its samples against its density
(detects a sampler whose samples do not follow the density it reports). The candidate set's
primary samples, replayed through the sample seam, give the candidate pass's own samples, in a
crop, with either pixel filter and several waves (detects a wrong dimension, pixel or sample-index
mapping). Renders: the mean of the warped passes alone equals `bsdf`'s (z-test, Sidak-corrected)
on cornell and ajar for both conditioning modes; a scene without light falls back to uniform
sampling; `auto` keeps the candidate model of least validation NLL.
"""
import copy
import os

import numpy as np
import pytest
import torch
from scipy import stats

import tracer
from tests import scenes
from tracer.testing.stats import assert_clean, assert_z, image_mean
from tracer.errors import SettingsError
from tracer.guiding import make_guide
from tracer.guiding.pss import flow as pf
from tracer.guiding.pss.warp import _CountingFilm
from tracer.render import make_context
from tracer.rng import pss_dims
from tracer.session import trace_source
from tracer.sources import CameraSource, PrimarySampleSource
from tracer.wave import WaveBuffers

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIGS = [(4, False), (6, False), (2, True), (4, True)]  # (dims, pixel context)


def _perturbed(dims, context, scale=0.05, seed=0):
    torch.manual_seed(seed)
    f = pf.PSSFlow(dims, layers=4, width=16, blocks=1, context=context)
    with torch.no_grad():
        for p in f.parameters():
            p.add_(scale * torch.randn_like(p))
    return f.eval()


def _inputs(dims, context, n, seed=1):
    rng = np.random.default_rng(seed)
    z = rng.random((n, dims))
    c = pf.context_features(rng.random((n, 2))) if context else None
    return z, c


@pytest.mark.parametrize("dims,context", CONFIGS)
def test_flow_inverts_both_ways(dims, context):
    f = _perturbed(dims, context)
    z, c = _inputs(dims, context, 20000)
    y, logq = pf.warp(f, z, c)
    z2, logq2 = pf.unwarp(f, y, c)
    np.testing.assert_allclose(z2, z, atol=2e-4)
    np.testing.assert_allclose(logq2, logq, atol=2e-3)
    z3, _ = pf.unwarp(f, z, c)  # the other way: y given, back and forth
    y3, _ = pf.warp(f, z3, c)
    np.testing.assert_allclose(y3, z, atol=2e-4)
    assert f.f_forward(torch.zeros(1, dims), None if c is None else torch.from_numpy(c[:1]))[0].shape == (1, dims)


def _warp_torch(flow64, z, ctx):
    """The whole warp in float64 torch, independently of pss_flow.warp: squeeze, logit, F, sigmoid."""
    zs = pf.EPS + (1.0 - 2.0 * pf.EPS) * z
    a = torch.log(zs) - torch.log1p(-zs)
    b = a
    for cpl in flow64.couplings:
        b, _ = cpl(b, ctx)
    return torch.sigmoid(b)


@pytest.mark.parametrize("dims,context", CONFIGS)
def test_log_density_is_minus_log_det_of_the_jacobian(dims, context):
    f = _perturbed(dims, context)
    f64 = copy.deepcopy(f).double()
    z, c = _inputs(dims, context, 12, seed=2)
    _, logq = pf.warp(f, z, c)
    for i in range(z.shape[0]):
        ci = None if c is None else torch.from_numpy(c[i:i + 1].astype(np.float64))
        jac = torch.autograd.functional.jacobian(
            lambda zz: _warp_torch(f64, zz[None], ci)[0], torch.from_numpy(z[i]))
        sign, logabs = torch.linalg.slogdet(jac)
        assert sign != 0
        assert abs(-float(logabs) - logq[i]) < 1e-3, (i, -float(logabs), logq[i])


@pytest.mark.parametrize("dims,context", CONFIGS)
def test_density_integrates_to_one(dims, context):
    f = _perturbed(dims, context)
    u, c = _inputs(dims, context, 200_000, seed=3)
    q = np.exp(pf.log_density(f, u, c))
    assert q.std() > 0.05, "the flow is too close to the identity for this test to see anything"
    assert_z(q.mean(), q.var() / q.shape[0], 1.0, n_tests=len(CONFIGS), what="integral of q over the cube")


@pytest.mark.parametrize("dims,context", CONFIGS)
def test_save_and_load(tmp_path, dims, context):
    f = _perturbed(dims, context)
    path = tmp_path / "flow.pt"
    pf.save(f, path, extra={"m": 1})
    g, extra = pf.load(path)
    assert extra == {"m": 1} and g.config == f.config
    z, c = _inputs(dims, context, 1000)
    np.testing.assert_array_equal(pf.warp(g, z, c)[0], pf.warp(f, z, c)[0])
    assert pf.parameter_count(g) == pf.parameter_count(f)


def test_trained_toy_flow_samples_follow_its_density():
    # Two anisotropic Gaussian blobs in the unit square; a short maximum-likelihood fit.
    rng = np.random.default_rng(0)
    n = 30000
    blob = rng.random(n) < 0.6
    y = np.where(blob[:, None], rng.normal([0.3, 0.7], [0.05, 0.08], (n, 2)),
                 rng.normal([0.7, 0.3], [0.1, 0.04], (n, 2)))
    y = y[((y > 0) & (y < 1)).all(axis=1)]
    torch.manual_seed(0)
    f = pf.PSSFlow(2, layers=4, width=16)
    b, _ = pf.prepare_targets(y)
    opt = torch.optim.Adam(f.parameters(), lr=3e-3)
    for _ in range(6):
        perm = torch.randperm(b.shape[0])
        for i in range(0, b.shape[0], 512):
            loss = f.nll_terms(b[perm[i:i + 512]]).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
    f.eval()
    # samples of the warp, binned on a 16 x 16 grid
    N, R, Q = 300_000, 16, 12
    ys, _ = pf.warp(f, np.random.default_rng(5).random((N, 2)))
    obs = np.histogram2d(ys[:, 0], ys[:, 1], bins=R, range=[[0, 1], [0, 1]])[0]
    # expected: the density integrated over each cell (Q x Q Gauss-Legendre points per cell)
    x, w = np.polynomial.legendre.leggauss(Q)
    pts = ((np.arange(R)[:, None] + (x[None, :] + 1) / 2) / R).ravel()
    wts = np.tile(w / 2 / R, R)
    gx, gy = np.meshgrid(pts, pts, indexing="ij")
    q = np.exp(pf.log_density(f, np.stack([gx.ravel(), gy.ravel()], axis=1))).reshape(gx.shape)
    mass = (q * wts[:, None] * wts[None, :]).reshape(R, Q, R, Q).sum(axis=(1, 3))
    assert abs(mass.sum() - 1.0) < 1e-3
    assert mass.max() > 8.0 / (R * R), "the flow learned nothing: the test would compare two uniforms"
    exp = N * mass
    pool = exp < 5.0
    o = np.append(obs[~pool], obs[pool].sum())
    e = np.append(exp[~pool], exp[pool].sum())
    chi2 = float(((o - e) ** 2 / e).sum())
    p = stats.chi2.sf(chi2, o.size - 1)
    assert p > 0.01, f"chi-square {chi2:.1f} on {o.size - 1} dof: p = {p:.2g}"


def _scene(name, w, h):
    return scenes.builtin(ROOT, name, w, h)


@pytest.mark.parametrize("pixel_filter", ["box", "point"])
def test_candidate_primary_samples_replay_the_candidate_pass(pixel_filter):
    scene = _scene("ajar", 40, 30)
    crop = (7, 5, 24, 18)
    ctx = make_context(scene, seed=4, pixel_filter=pixel_filter, crop=crop)
    film = _CountingFilm(24, 18, keep=True)
    trace_source(ctx, CameraSource(), film, spp=2, sample0=3, buf=WaveBuffers(100))
    g = make_guide("pss", target="luminance")
    y, _, f = g.examples(ctx, film, sample0=3)
    assert np.count_nonzero(f) > 20
    # the same paths again, with the recomputed primary samples supplied through the seam
    again = _CountingFilm(24, 18, keep=True)
    trace_source(ctx, PrimarySampleSource(y, pss_dims(2), whole_image=True), again, spp=2, sample0=3,
                 buf=WaveBuffers(77))
    f2 = again.luminance()  # weight (1) x value, per sample
    same = np.isclose(f2, f, rtol=1e-5, atol=1e-12)
    assert same.mean() > 0.99, f"only {same.mean():.3f} of the samples replay"
    assert (same & (f > 0)).sum() > 0.95 * np.count_nonzero(f)


CASES = [("cornell", 32, 32, 96), ("ajar", 48, 36, 96), ("ajar-textured", 48, 36, 96)]  # (tests/scenes.textured)
MODES = ["image", "pixel"]
FAST = dict(m=1, layers=2, width=16, epochs=6, candidates=16)


@pytest.fixture(scope="module")
def bsdf_renders():
    return {name: tracer.render(_scene(name, w, h), spp=spp, seed=101) for name, w, h, spp in CASES}


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_pss_mean_equals_bsdf_mean(case, mode, bsdf_renders):
    name, w, h, spp = case
    g = make_guide("pss", condition=mode, **FAST)
    finals = []

    def keep_final(i, film, st):
        if st["passes"][i]["kind"] == "final" and not any(f is film for f in finals):
            finals.append(film)

    r = tracer.render(_scene(name, w, h), spp=spp, guide=g, seed=202, callback=keep_final)
    assert_clean(r, f"pss {mode} on {name}")
    per_pixel = (spp - FAST["candidates"]) * (w * h if mode == "image" else 1)  # image: every sample counts
    assert len(finals) == 1 and finals[0].count.min() == per_pixel
    st = g.stats()
    assert st["fallback"] is None and g.flow is not None, st.get("fallback")
    d = g.flow.dims
    u, c = _inputs(d, mode == "pixel", 4000, seed=9)
    q = np.exp(pf.log_density(g.flow, u, c))
    assert q.std() > 0.02, "the warp is the identity: this test would not test warping"
    assert r.stats["spp"] == spp and [p["kind"] for p in r.stats["passes"]][:2] == ["train", "final"]
    # the warped passes alone (the candidate pass is plain bsdf sampling and would dilute a bias);
    # in image mode pixels are slightly negatively correlated, so the summed variance is an upper bound
    img, var = finals[0].mean().reshape(-1, 3), finals[0].variance().reshape(-1, 3)
    m_g, v_g = img.mean(axis=0), var.sum(axis=0) / img.shape[0] ** 2
    m_b, v_b = image_mean(bsdf_renders[name])
    assert_z(m_g, v_g + v_b, m_b, n_tests=len(CASES) * len(MODES) * 3, what=f"pss {mode} on {name} vs bsdf")


def _dark_box(folder):
    """The camera inside a closed box; the only light outside it, where no path can reach."""
    v, f = scenes.box_faces((-1, -1, -1), (1, 1, 1), inward=True)
    lamp = np.array([[-1, 3, -1], [-1, 3, 1], [1, 3, 1], [1, 3, -1]], float)
    return scenes.write_scene(
        folder, "dark", [("wall", v, f), ("lamp", lamp, np.array([[0, 2, 1], [0, 3, 2]]))],
        {"wall": "Kd 0.5 0.5 0.5", "lamp": "Kd 0 0 0\nKe 5 5 5"},
        {"camera": {"origin": [0, 0, 0.5], "target": [0, 0, -1], "up": [0, 1, 0], "fov": 90},
         "film": {"width": 12, "height": 12}, "render": {"spp": 8, "max_depth": -1}})


def test_scene_without_light_falls_back_to_uniform(tmp_path):
    scene = tracer.load_scene(_dark_box(tmp_path))
    g = make_guide("pss", **FAST)
    r = tracer.render(scene, spp=24, guide=g, seed=1)
    assert_clean(r)
    st = g.stats()
    assert g.flow is None and "lit candidate samples" in st["fallback"]
    assert r.stats["spp"] == 24 and float(r.image.max()) == 0.0
    assert st["zero_share_uniform"] == 1.0 and st["zero_share_final"] == 1.0


@pytest.mark.parametrize("bad", [{"condition": "both"}, {"m": 3}, {"defensive": 0.0}, {"target": "x"},
                                 {"layers": 0}, {"candidates": 0}])
def test_settings_are_checked(bad):
    with pytest.raises(SettingsError):
        make_guide("pss", **bad)



def test_auto_keeps_the_model_of_least_validation_nll():
    g = make_guide("pss", epochs=1, candidates=8)
    tracer.render(_scene("cornell", 20, 20), spp=12, guide=g, seed=5)
    st = g.stats()
    tried = st["tried"]
    assert len(tried) == 6 and {t["m"] for t in tried} == {1, 2}
    best = min(tried, key=lambda t: t["val_nll"])
    assert (st["m"], st["layers"], st["width"]) == (best["m"], best["layers"], best["width"])
    assert best["epochs"] == 2 and all(t["epochs"] == 1 for t in tried if t is not best)
    assert st["val_nll"] == best["val_nll"] and g.flow.dims == 2 + 2 * st["m"] - 2  # pixel: directions only


def test_a_short_time_budget_falls_back_to_uniform():
    # share x time = 0.06 s, below the 1 s the learning needs whatever the machine's speed
    g = make_guide("pss")
    r = tracer.render(_scene("cornell", 16, 16), time=0.2, guide=g, seed=3)
    assert_clean(r)
    assert g.flow is None and g.stats()["fallback"].startswith("too little time left to learn")
    assert 1 <= sum(p["spp"] for p in r.stats["passes"] if p["kind"] == "train") <= g.candidates
