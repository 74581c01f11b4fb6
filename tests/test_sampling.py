"""Tests of the warps and tables in tracer/sampling.py.

Each warp is run over a batch by a small jitted loop, then checked against its density with a
chi-square test (tracer/testing/chi2.py) and at its edges (u = 0, u -> 1). Statistical tests share one
significance level with a Sidak correction over the NTESTS tests of this file.
"""
import math

import numpy as np
import pytest

from tracer.testing import ChiSquareTest, histogram_test, z_critical
from tracer import sampling as S
from tracer._jit import jit

N = 500_000
NTESTS = 8  # chi-square tests below: 2 direction warps, disk, triangle, 2 x 1D table, 2 x 2D table
U_EDGE = np.array([0.0, 1e-300, 0.25, 0.5, 0.75, 1.0 - 2.0**-53])


# --- Batch wrappers around the scalar warps ------------------------------------------------------
@jit
def cosine_batch(u):
    out = np.empty((u.shape[0], 3))
    for k in range(u.shape[0]):
        w = S.sample_cosine_hemisphere(u[k, 0], u[k, 1])
        out[k, 0], out[k, 1], out[k, 2] = w[0], w[1], w[2]
    return out


@jit
def cosine_pdf_batch(d):
    out = np.empty(d.shape[0])
    for k in range(d.shape[0]):
        out[k] = S.cosine_hemisphere_pdf((d[k, 0], d[k, 1], d[k, 2]))
    return out


@jit
def sphere_batch(u):
    out = np.empty((u.shape[0], 3))
    for k in range(u.shape[0]):
        w = S.sample_uniform_sphere(u[k, 0], u[k, 1])
        out[k, 0], out[k, 1], out[k, 2] = w[0], w[1], w[2]
    return out


@jit
def sphere_pdf_batch(d):
    out = np.empty(d.shape[0])
    for k in range(d.shape[0]):
        out[k] = S.uniform_sphere_pdf((d[k, 0], d[k, 1], d[k, 2]))
    return out


@jit
def disk_batch(u):
    out = np.empty((u.shape[0], 2))
    for k in range(u.shape[0]):
        out[k, 0], out[k, 1] = S.sample_concentric_disk(u[k, 0], u[k, 1])
    return out


@jit
def triangle_batch(u):
    out = np.empty((u.shape[0], 2))
    for k in range(u.shape[0]):
        out[k, 0], out[k, 1] = S.sample_uniform_triangle(u[k, 0], u[k, 1])
    return out


@jit
def dist1d_batch(func, cdf, u):
    n = u.shape[0]
    x, pdf, idx, pdf_again = np.empty(n), np.empty(n), np.empty(n, np.int64), np.empty(n)
    for k in range(n):
        x[k], pdf[k], idx[k] = S.sample_distribution_1d(func, cdf, u[k])
        pdf_again[k] = S.distribution_1d_pdf(func, cdf, x[k])
    return x, pdf, idx, pdf_again


@jit
def dist2d_batch(cf, cc, mf, mc, u):
    n = u.shape[0]
    x, y, pdf, pdf_again = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        x[k], y[k], pdf[k] = S.sample_distribution_2d(cf, cc, mf, mc, u[k, 0], u[k, 1])
        pdf_again[k] = S.distribution_2d_pdf(cf, cc, mf, mc, x[k], y[k])
    return x, y, pdf, pdf_again


@jit
def power_batch(a, b):
    out = np.empty(a.shape[0])
    for k in range(a.shape[0]):
        out[k] = S.power_heuristic(a[k], b[k])
    return out


@jit
def frame_batch(n):
    out = np.empty((n.shape[0], 4, 3))
    for k in range(n.shape[0]):
        nk = (n[k, 0], n[k, 1], n[k, 2])
        s, t = S.frame(nk)
        c = S.cross(s, t)
        v = (0.3, -0.5, 0.81)
        w = S.to_local(S.to_world(v, s, t, nk), s, t, nk)
        for i in range(3):
            out[k, 0, i], out[k, 1, i], out[k, 2, i], out[k, 3, i] = s[i], t[i], c[i], w[i]
    return out


def edge_u():
    """All pairs of edge values of u."""
    a, b = np.meshgrid(U_EDGE, U_EDGE)
    return np.stack([a.ravel(), b.ravel()], axis=1)


# --- Directions ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "sample, pdf",
    [(cosine_batch, cosine_pdf_batch), (sphere_batch, sphere_pdf_batch)],
    ids=["cosine_hemisphere", "uniform_sphere"],
)
def test_direction_warp_chi2(sample, pdf):
    chi = ChiSquareTest(sample, pdf, sample_dim=2, n=N, seed=1)
    assert chi.run(ntests=NTESTS), chi.message
    # The density integrates to 1 and the warp never fails
    assert abs(chi.pdf_integral - 1.0) <= chi.quad_error + 1e-9
    assert chi.observed[-1] == 0
    d = sample(np.concatenate([edge_u(), np.random.default_rng(2).random((1000, 2))]))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-12)
    assert np.all(pdf(d) > 0.0) or sample is cosine_batch
    if sample is cosine_batch:
        assert np.all(d[:, 2] >= 0.0)
        assert np.all(cosine_pdf_batch(-np.abs(d)) == 0.0)


def test_concentric_disk():
    u = np.concatenate([edge_u(), np.random.default_rng(3).random((N, 2))])
    p = disk_batch(u)
    r2 = np.sum(p * p, axis=1)
    assert np.all(np.isfinite(p)) and np.all(r2 <= 1.0 + 1e-15)
    np.testing.assert_array_equal(disk_batch(np.array([[0.5, 0.5]])), [[0.0, 0.0]])
    # Area preserving: (r^2, angle) is uniform on [0, 1] x [-pi, pi]
    k_r, k_a = 21, 31
    ir = np.minimum((r2 * k_r).astype(int), k_r - 1)
    angle = (np.arctan2(p[:, 1], p[:, 0]) + math.pi) / (2 * math.pi)
    ia = np.minimum((angle * k_a).astype(int), k_a - 1)
    obs = np.bincount(ir * k_a + ia, minlength=k_r * k_a)
    passed, msg = histogram_test(obs, np.full(k_r * k_a, len(p) / (k_r * k_a)), NTESTS)
    assert passed, msg


def test_uniform_triangle():
    u = np.random.default_rng(4).random((N, 2))
    b = triangle_batch(u)
    assert np.all(b >= 0.0) and np.all(b.sum(axis=1) <= 1.0)
    e = triangle_batch(edge_u())
    assert np.all(e >= 0.0) and np.all(e.sum(axis=1) <= 1.0)
    # Uniform density 2 on the triangle {b1, b2 >= 0, b1 + b2 <= 1}: cells of a k x k grid below
    # the diagonal hold 1 / k^2 of the area times 2, cells on it half of that
    k = 21
    i = np.minimum((b[:, 0] * k).astype(int), k - 1)
    j = np.minimum((b[:, 1] * k).astype(int), k - 1)
    obs = np.bincount(i * k + j, minlength=k * k)
    ii, jj = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    area = np.where(ii + jj < k - 1, 1.0, np.where(ii + jj == k - 1, 0.5, 0.0)) / k**2
    passed, msg = histogram_test(obs, (N * 2.0 * area).ravel(), NTESTS)
    assert passed, msg


# --- Piecewise-constant tables -------------------------------------------------------------------
def table_1d():
    f = np.random.default_rng(5).random(37) * 3.0
    f[[0, 1, 10, 11, 12, 36]] = 0.0  # leading, inner and trailing empty bins
    return f


@pytest.mark.parametrize("zero", [False, True], ids=["random", "zero_function"])
def test_distribution_1d(zero):
    f = np.zeros(23) if zero else table_1d()
    func, cdf = S.build_distribution_1d(f)
    n = func.size
    target = np.ones(n) if zero else f
    u = np.concatenate([U_EDGE, np.random.default_rng(6).random(N)])
    x, pdf, idx, pdf_again = dist1d_batch(func, cdf, u)
    assert np.all((x >= 0.0) & (x < 1.0))
    np.testing.assert_array_equal(idx, np.minimum((x * n).astype(int), n - 1))
    # The returned pdf is the table's density in the sampled bin, and the pdf function agrees
    np.testing.assert_allclose(pdf, target[idx] / target.mean(), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(pdf_again, pdf, rtol=1e-12)
    assert np.all(target[idx] > 0.0)
    # Histogram on 3 sub-bins per bin: uniform within each bin
    sub = 3
    fine = np.minimum((x[len(U_EDGE) :] * n * sub).astype(int), n * sub - 1)
    obs = np.bincount(fine, minlength=n * sub)
    expected = np.repeat(target / target.sum(), sub) / sub * N
    passed, msg = histogram_test(obs, expected, NTESTS)
    assert passed, msg


@pytest.mark.parametrize("zero", [False, True], ids=["random", "zero_function"])
def test_distribution_2d(zero):
    rows, cols = 13, 17
    if zero:
        f = np.zeros((rows, cols))
    else:
        f = np.random.default_rng(7).random((rows, cols)) ** 2
        f[3] = 0.0  # an empty row
        f[:, 5] = 0.0  # an empty column
        f[7, 9] = 0.0
    tables = S.build_distribution_2d(f)
    target = np.ones((rows, cols)) if zero else f
    u = np.concatenate([edge_u(), np.random.default_rng(8).random((N, 2))])
    x, y, pdf, pdf_again = dist2d_batch(*tables, u)
    assert np.all((x >= 0) & (x < 1) & (y >= 0) & (y < 1))
    c = np.minimum((x * cols).astype(int), cols - 1)
    r = np.minimum((y * rows).astype(int), rows - 1)
    np.testing.assert_allclose(pdf, target[r, c] / target.mean(), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(pdf_again, pdf, rtol=1e-12)
    assert np.all(target[r, c] > 0.0)
    # Histogram on 2 x 2 sub-cells per cell
    m = len(edge_u())
    cs = np.minimum((x[m:] * cols * 2).astype(int), 2 * cols - 1)
    rs = np.minimum((y[m:] * rows * 2).astype(int), 2 * rows - 1)
    obs = np.bincount(rs * 2 * cols + cs, minlength=4 * rows * cols)
    expected = np.repeat(np.repeat(target / target.sum(), 2, axis=0), 2, axis=1) / 4 * N
    passed, msg = histogram_test(obs, expected.ravel(), NTESTS)
    assert passed, msg


def test_distribution_rejects_bad_input():
    for bad in (np.array([]), np.array([1.0, -1.0]), np.array([1.0, np.nan]), np.ones((2, 2))):
        with pytest.raises(ValueError):
            S.build_distribution_1d(bad)


# --- MIS and frames ------------------------------------------------------------------------------
def test_power_heuristic():
    rng = np.random.default_rng(9)
    a = 10.0 ** rng.uniform(-30, 30, 100_000)
    b = 10.0 ** rng.uniform(-30, 30, 100_000)
    b[:1000] = 0.0
    w_ab, w_ba = power_batch(a, b), power_batch(b, a)
    np.testing.assert_allclose(w_ab + w_ba, 1.0, rtol=1e-12)
    assert np.all((w_ab >= 0) & (w_ab <= 1))
    np.testing.assert_array_equal(w_ab[:1000], 1.0)
    np.testing.assert_allclose(power_batch(a, a), 0.5)
    np.testing.assert_allclose(power_batch(np.array([1.0]), np.array([2.0])), [0.2])
    assert S.power_heuristic(0.0, 0.0) == 0.0
    assert S.power_heuristic(math.inf, 1.0) == 1.0 and S.power_heuristic(1.0, math.inf) == 0.0


def test_frame():
    rng = np.random.default_rng(10)
    n = rng.normal(size=(10_000, 3))
    n = np.concatenate([n / np.linalg.norm(n, axis=1, keepdims=True), np.eye(3), -np.eye(3)])
    out = frame_batch(n)
    s, t, c, back = out[:, 0], out[:, 1], out[:, 2], out[:, 3]
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.sum(s * t, axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(s * n, axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(c, n, atol=1e-12)  # s x t = n
    np.testing.assert_allclose(back, np.tile([0.3, -0.5, 0.81], (len(n), 1)), atol=1e-12)


def test_sidak_threshold_is_strict():
    # With NTESTS tests the two-sided threshold exceeds the single-test 2.576
    assert z_critical(NTESTS) > 2.576
