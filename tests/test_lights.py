"""Light sampling: the density NEE reports is the one it samples from, for the environment map
and for triangles chosen by power, one-sided. Light densities jump at every pixel and triangle
edge, which sphere quadrature cannot integrate well, so they are checked by unbiasedness:
E[f / p] equals the exact integral of f (z-tests on the sample variance)."""
import numpy as np
from numba import njit

import tracer
from tracer.lights import build_lights, env_pdf, sample_light, triangle_light_pdf
from tests import scenes
from tracer.testing.stats import assert_z

N_TESTS = 3  # z-test groups in this file (Sidak)


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
