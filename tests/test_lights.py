"""Light sampling: the density NEE reports is the one it samples from, for the environment map
(both conventions: the tracer's texels and Mitsuba 3's bilinear envmap) and for triangles chosen by
power, one-sided. Light densities jump at every pixel and triangle edge, so they are checked by
unbiasedness: E[f / p] equals the exact integral of f (z-tests on the sample variance); Mitsuba's
map also by chi-square of its samples against its pdf (tracer.testing.chi2)."""
import numpy as np
from numba import njit

import tracer
from tracer.lights import ENV_BILINEAR, build_lights, env_pdf, env_radiance, sample_light, triangle_light_pdf
from tests import scenes
from tracer.testing.stats import assert_z

N_TESTS = 4  # z-test groups in this file (Sidak)


@njit(cache=True)
def _sample_batch(lt, tri, x, u):
    n = u.shape[0]
    out = np.full((n, 3), np.nan)
    pdfs = np.zeros(n)
    for i in range(n):
        wi, dist, le, pdf, _ = sample_light(lt, tri, (x[0], x[1], x[2]), u[i, 0], u[i, 1], u[i, 2])
        if pdf > 0.0:
            out[i, 0], out[i, 1], out[i, 2] = wi
            pdfs[i] = pdf
    return out, pdfs


@njit(cache=True)
def _env_pdf_batch(lt, d):
    out = np.zeros(d.shape[0])
    for i in range(d.shape[0]):
        out[i] = env_pdf(lt, (d[i, 0], d[i, 1], d[i, 2]))
    return out


@njit(cache=True)
def _env_radiance_batch(lt, d):
    out = np.zeros((d.shape[0], 3))
    for i in range(d.shape[0]):
        out[i] = env_radiance(lt, (d[i, 0], d[i, 1], d[i, 2]))
    return out


@njit(cache=True)
def _tri_pdf_batch(lt, tri, normal, x, d):
    """Density of NEE at x toward each direction d: the nearest light triangle it meets."""
    out = np.zeros(d.shape[0])
    for i in range(d.shape[0]):
        best = np.inf
        hit = -1
        for t in range(tri.shape[0]):
            e1 = tri[t, 1] - tri[t, 0]
            e2 = tri[t, 2] - tri[t, 0]
            p = np.cross(d[i], e2)
            det = np.dot(e1, p)
            if abs(det) < 1e-14:
                continue
            s = x - tri[t, 0]
            b1 = np.dot(s, p) / det
            q = np.cross(s, e1)
            b2 = np.dot(d[i], q) / det
            tt = np.dot(e2, q) / det
            if b1 >= 0 and b2 >= 0 and b1 + b2 <= 1 and 0 < tt < best:
                best, hit = tt, t
        if hit >= 0:
            cos_l = -np.dot(d[i], normal[hit])
            out[i] = triangle_light_pdf(lt, hit, best * best, cos_l)
    return out


def _solid_angle(tri, x):
    """Solid angle of each triangle (T,3,3) seen from x (Van Oosterom and Strackee 1983)."""
    a, b, c = tri[:, 0] - x, tri[:, 1] - x, tri[:, 2] - x
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    num = np.abs(np.einsum("ij,ij->i", a, np.cross(b, c)))
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb \
        + np.einsum("ij,ij->i", b, c) * la
    return 2.0 * np.arctan2(num, den)


def test_environment_map_sampling_is_unbiased(tmp_path):
    """E[L(w) / p(w)] = integral of L over the sphere = sum over pixels of L x pixel solid angle.
    This checks the map's 2D sampling together with the (u, v) <-> direction map and its
    Jacobian 1 / (2 pi^2 sin theta); the 2D tables themselves are chi-square tested in
    test_sampling.py."""
    g = np.random.default_rng(1)
    h, w = 8, 16
    img = (g.random((h, w, 3)) ** 4 * 10 + 0.01).astype(np.float32)
    img[2, 5] = 200.0  # a sun
    tracer.write_image(tmp_path / "env.exr", img)
    scene = tracer.load_scene(scenes.sphere_under_sky(tmp_path, 0.5, 1.0, env={"map": "env.exr"}))
    lt = build_lights(scene)
    assert lt.p_env == 1.0
    x = np.zeros(3)
    n = 400_000
    d, p = _sample_batch(lt, scene.tri, x, g.random((n, 3)))
    assert np.all(p > 0)
    # the pdf NEE returns is env_pdf at the sampled direction
    np.testing.assert_allclose(p, _env_pdf_batch(lt, d), rtol=1e-6)  # sin(theta) recomputed from d
    # radiance of each sample, looked up through the map convention of tracer.scene.Environment
    u = (0.5 + np.arctan2(d[:, 0], -d[:, 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(d[:, 1], -1, 1)) / np.pi
    L = img[np.minimum((v * h).astype(int), h - 1), np.minimum((u * w).astype(int), w - 1)].astype(float)
    rows = np.cos(np.pi * np.arange(h + 1) / h)
    pixel_sa = (2 * np.pi / w) * (rows[:-1] - rows[1:])
    exact = (img.astype(float) * pixel_sa[:, None, None]).sum(axis=(0, 1))
    est = L / p[:, None]
    assert_z(est.mean(axis=0), est.var(axis=0, ddof=1) / n, exact, n_tests=N_TESTS * 3, what="E[L/p]")
    inv = 1.0 / p
    assert_z(inv.mean(), inv.var(ddof=1) / n, 4 * np.pi, n_tests=N_TESTS, what="E[1/p]")


MITSUBA_ENV = """<scene version="3.0.0">
    <sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>
        </transform><film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
    </sensor>
    <shape type="rectangle"/>
    <emitter type="envmap"><string name="filename" value="env.exr"/>
        <transform name="to_world"><rotate x="0.6" y="0.8" angle="40"/></transform></emitter>
</scene>
"""


def _mitsuba_env(tmp_path):
    """(lights, image) of a Mitsuba envmap (9 x 12, a sun of two texels) under a rotation."""
    g = np.random.default_rng(4)
    img = (g.random((9, 12, 3)) ** 4 * 10 + 0.01).astype(np.float32)
    img[3, 4:6] = 200.0
    tracer.write_image(tmp_path / "env.exr", img)
    (tmp_path / "scene.xml").write_text(MITSUBA_ENV)
    lt = build_lights(tracer.load_scene(str(tmp_path / "scene.xml")))
    assert lt.env_type == ENV_BILINEAR and lt.p_env == 1.0
    return lt, img.astype(np.float64)


def test_mitsuba_envmap_sampling_matches_its_pdf(tmp_path):
    """Chi-square of 400k NEE samples of a rotated Mitsuba envmap against env_pdf, and the pdf NEE
    reports equals env_pdf at its direction. Detects a sampler whose (u, v) <-> direction map, half
    texel shift, rotation or Jacobian disagrees with the density that MIS weights use."""
    from tracer.testing.chi2 import ChiSquareTest

    lt, img = _mitsuba_env(tmp_path)
    x = np.zeros(3)
    # histogrammed in the map's frame, its pole on the grid's +z: (-z, x, y) of the map's frame,
    # so that the density's jumps between rows are the grid's circles of constant z (breaks)
    q = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) @ lt.env_rot

    def sample(u):
        d, p = _sample_batch(lt, np.zeros((1, 3, 3)), x, np.column_stack([np.zeros(len(u)), u]))
        return d @ q.T

    rows = np.cos(np.pi * np.arange(1, img.shape[0] - 1) / (img.shape[0] - 1))
    t = ChiSquareTest(sample, lambda d: _env_pdf_batch(lt, d @ q), sample_dim=2, n=400_000, res=(31, 61), seed=3,
                      breaks=rows)
    assert t.run(), t.message
    assert abs(t.pdf_integral - 1.0) < max(5 * t.quad_error, 2e-3), t.message
    d, p = _sample_batch(lt, np.zeros((1, 3, 3)), x, np.random.default_rng(5).random((10_000, 3)))
    np.testing.assert_allclose(p, _env_pdf_batch(lt, d), rtol=1e-6)


def test_mitsuba_envmap_sampling_is_unbiased(tmp_path):
    """E[L(w) / p(w)] over NEE samples = the integral of Mitsuba's bilinear radiance over the
    sphere (exact: linear in u within a cell, 16-point Gauss-Legendre in v against sin theta).
    Detects a sampler that misses part of the sphere or weighs a cell by the wrong density, and
    radiance looked up with a different interpolation than the integral's."""
    lt, img = _mitsuba_env(tmp_path)
    h, w = img.shape[:2]
    n = 400_000
    d, p = _sample_batch(lt, np.zeros((1, 3, 3)), np.zeros(3), np.random.default_rng(6).random((n, 3)))
    assert np.all(p > 0)
    L = _env_radiance_batch(lt, d)
    # the integral: over u a cell's mean is the mean of its two columns (all columns: the row mean)
    row = img.mean(axis=1)  # (h, 3)
    gx, gw = np.polynomial.legendre.leggauss(16)
    t, wt = 0.5 * (gx + 1.0), 0.5 * gw
    exact = np.zeros(3)
    for y in range(h - 1):
        v = (y + t) / (h - 1)
        f = (1 - t)[:, None] * row[y] + t[:, None] * row[y + 1]
        exact += (wt[:, None] * f * np.sin(np.pi * v)[:, None]).sum(axis=0) / (h - 1)
    exact *= 2 * np.pi * np.pi  # d omega = 2 pi^2 sin(theta) du dv
    est = L / p[:, None]
    assert_z(est.mean(axis=0), est.var(axis=0, ddof=1) / n, exact, n_tests=N_TESTS * 3, what="E[L/p]")


def _lamp_scene(tmp_path):
    # Two lamps of different power facing a receiver at the origin, and one facing away.
    big = np.array([[-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]], float)
    small = np.array([[2, 0.5, -0.3], [2, 0.5, 0.3], [2, -0.1, 0.0]], float)
    away = np.array([[-2, -1, -1], [-2, 1, -1], [-2, 1, 1]], float)
    groups = [("big", big, [[0, 1, 2], [0, 2, 3]]),  # normal -y: faces the origin
              ("small", small, [[0, 2, 1]]),  # normal -x: faces the origin
              ("away", away, [[0, 2, 1]])]  # normal -x: faces away
    mats = {"big": "Kd 0 0 0\nKe 1 1 1", "small": "Kd 0 0 0\nKe 5 3 1", "away": "Kd 0 0 0\nKe 2 2 2"}
    return tracer.load_scene(scenes.write_scene(tmp_path, "lamps", groups, mats, None))


def test_triangle_light_sampling_is_unbiased(tmp_path):
    """E[Le / p] over NEE samples = sum over front-facing triangles of Le x solid angle, and the
    pdf NEE reports is the one triangle_light_pdf gives where its direction meets the light."""
    scene = _lamp_scene(tmp_path)
    lt = build_lights(scene)
    tri = scene.tri[lt.tri]
    x = np.zeros(3)
    front = np.einsum("ij,ij->i", x - tri[:, 0], lt.normal) > 0
    assert front.sum() == 3  # one lamp faces away: chosen by power, its samples carry nothing
    n = 400_000
    g = np.random.default_rng(2)
    d, p = _sample_batch(lt, scene.tri, x, g.random((n, 3)))
    ok = p > 0
    assert 0 < ok.mean() < 1
    np.testing.assert_allclose(p[ok], _tri_pdf_batch(lt, tri, lt.normal, x, d[ok]), rtol=1e-9)
    # Le of each successful sample: the triangle its direction meets
    le = np.zeros((n, 3))
    pdf_by_tri = np.stack([_tri_pdf_batch(lt, tri[t:t + 1], lt.normal[t:t + 1], x, d[ok]) for t in range(len(tri))])
    # (_tri_pdf_batch with one triangle is nonzero only where the direction meets that triangle)
    owner = np.argmax(pdf_by_tri > 0, axis=0)
    le[ok] = lt.radiance[owner]
    est = np.where(ok[:, None], le / np.where(ok, p, 1.0)[:, None], 0.0)
    exact = (lt.radiance[front] * _solid_angle(tri[front], x)[:, None]).sum(axis=0)
    assert_z(est.mean(axis=0), est.var(axis=0, ddof=1) / n, exact, n_tests=N_TESTS * 3, what="E[Le/p]")


def test_lights_are_chosen_by_power(tmp_path):
    scene = _lamp_scene(tmp_path)
    lt = build_lights(scene)
    from tracer.lights import luminance

    power = luminance(lt.radiance) * lt.area * np.pi
    np.testing.assert_allclose(np.diff(lt.cdf), power / power.sum(), rtol=1e-12)
