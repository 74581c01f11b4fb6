"""Screened Poisson solvers against a sparse direct solve and images with known answers."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from tracer.errors import SettingsError
from tracer.gradient import poisson


def _diff_matrix(n):
    """(n, n) forward differences with the last row zero: an independent twin of grad_x/grad_y."""
    d = sp.lil_matrix((n, n))
    for i in range(n - 1):
        d[i, i] = -1.0
        d[i, i + 1] = 1.0
    return d.tocsr()


def _smooth_image(h, w, seed=0):
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    rng = np.random.default_rng(seed)
    c = rng.uniform(0.5, 2.0, size=3)
    img = np.stack([np.sin(3 * x * c[k] + 2 * y) + 0.5 * (x > 0.5) + 1.5 for k in range(3)], axis=2)
    return img


def test_dct_solve_equals_a_sparse_direct_solve():
    """The exact L2 solve by the DCT equals spsolve of the normal equations built from sparse
    difference matrices, to 1e-8 (detects a wrong eigenvalue, boundary or adjoint)."""
    h, w = 7, 11
    rng = np.random.default_rng(1)
    base, gx, gy = rng.normal(size=(3, h, w))
    alpha = 0.3
    dx = sp.kron(sp.identity(h), _diff_matrix(w))  # row-major (y, x)
    dy = sp.kron(_diff_matrix(h), sp.identity(w))
    a = alpha ** 2 * sp.identity(h * w) + dx.T @ dx + dy.T @ dy
    gxm = gx.copy()
    gxm[:, -1] = 0.0
    gym = gy.copy()
    gym[-1] = 0.0
    rhs = alpha ** 2 * base.ravel() + dx.T @ gxm.ravel() + dy.T @ gym.ravel()
    ref = spsolve(a.tocsc(), rhs).reshape(h, w)
    np.testing.assert_allclose(poisson.solve_l2(base, gx, gy, alpha), ref, atol=1e-8, rtol=0)


def test_gradient_operators_and_their_adjoints():
    """<D u, g> = <u, D' g> for both axes (the adjoints the normal equations use)."""
    rng = np.random.default_rng(2)
    u, g = rng.normal(size=(2, 6, 9, 3))
    g[:, -1] = 0.0
    assert np.isclose(np.vdot(poisson.grad_x(u), g), np.vdot(u, poisson.grad_x_t(g)))
    g = rng.normal(size=(6, 9, 3))
    g[-1] = 0.0
    assert np.isclose(np.vdot(poisson.grad_y(u), g), np.vdot(u, poisson.grad_y_t(g)))


@pytest.mark.parametrize("solver", [poisson.solve_l2, poisson.solve_l1])
def test_exact_gradients_and_a_noisy_base_give_the_image_back(solver):
    """With the true gradients, the reconstruction from a base with noise sigma 0.3 is at least 20x
    closer (MSE) to the truth than the base (the screening keeps only the noise's mean)."""
    truth = _smooth_image(48, 64)
    base = truth + np.random.default_rng(3).normal(scale=0.3, size=truth.shape)
    out = solver(base, poisson.grad_x(truth), poisson.grad_y(truth), alpha=0.2)
    mse_base = np.mean((base - truth) ** 2)
    mse_out = np.mean((out - truth) ** 2)
    assert mse_out < mse_base / 20.0, (mse_out, mse_base)


def test_l1_ignores_gradient_outliers_that_l2_smears():
    """A few gradients off by 50 (fireflies in the gradient images): L1's error stays below a
    quarter of L2's."""
    truth = _smooth_image(40, 40, seed=4)
    gx, gy = poisson.grad_x(truth), poisson.grad_y(truth)
    rng = np.random.default_rng(5)
    idx = rng.integers(0, 39, size=(12, 2))
    gx[idx[:, 0], idx[:, 1]] += 50.0
    base = truth + rng.normal(scale=0.1, size=truth.shape)
    e2 = np.mean((poisson.solve_l2(base, gx, gy) - truth) ** 2)
    e1 = np.mean((poisson.solve_l1(base, gx, gy) - truth) ** 2)
    assert e1 < e2 / 4.0, (e1, e2)


@pytest.mark.parametrize("method", ["l1", "l2"])
def test_a_large_alpha_returns_the_base(method):
    rng = np.random.default_rng(6)
    base, gx, gy = rng.normal(size=(3, 10, 12))
    out = poisson.reconstruct(method, base, gx, gy, alpha=1e4)
    np.testing.assert_allclose(out, base, atol=1e-5)


def test_bad_input_is_one_clear_error():
    with pytest.raises(SettingsError, match="shape"):
        poisson.solve_l2(np.zeros((4, 4)), np.zeros((4, 5)), np.zeros((4, 4)))
    with pytest.raises(SettingsError, match="alpha"):
        poisson.solve_l1(np.zeros((4, 4)), np.zeros((4, 4)), np.zeros((4, 4)), alpha=0.0)
    with pytest.raises(SettingsError, match="reconstruction"):
        poisson.reconstruct("l3", np.zeros((4, 4)), np.zeros((4, 4)), np.zeros((4, 4)))


def test_l1_stops_reweighting_at_its_deadline():
    """With a deadline already past, the L1 solve runs its first reweighting only (the result of
    reweights=1, bit for bit), and with one far off it runs them all: a budgeted render's solve
    ends by the budget. Detects a deadline that is ignored, or one that skips the first
    reweighting (the L2 start returned as the L1 image)."""
    import time

    rng = np.random.default_rng(5)
    img = rng.random((24, 20))
    gx, gy = poisson.grad_x(img) + rng.normal(scale=0.1, size=img.shape), poisson.grad_y(img)
    past = poisson.solve_l1(img, gx, gy, deadline=time.perf_counter() - 1.0)
    np.testing.assert_array_equal(past, poisson.solve_l1(img, gx, gy, reweights=1))
    assert not np.array_equal(past, poisson.solve_l2(img, gx, gy))
    far = poisson.solve_l1(img, gx, gy, deadline=time.perf_counter() + 1e6)
    np.testing.assert_array_equal(far, poisson.solve_l1(img, gx, gy))


def test_l1_fills_the_time_to_its_deadline():
    """With fill, a deadline far off buys more reweightings at the last eps (FILL_MAX x
    `reweights` in all, no more), and they bring the image no farther from the smoothed L1 minimum: its
    L1 objective is no larger than after the scheduled ones. With a deadline soon, the fill stops
    by it. Detects a fill that is skipped (a budgeted render that ends early when its solve was
    estimated long), one that runs past its deadline or without end, or one that makes the image
    worse (eps halved past the schedule's last, or weights from the wrong image)."""
    import time

    rng = np.random.default_rng(7)
    img = rng.random((40, 36))
    gx = poisson.grad_x(img) + rng.standard_cauchy(size=img.shape) * 0.02
    gy = poisson.grad_y(img) + rng.standard_cauchy(size=img.shape) * 0.02
    info = {}
    base = poisson.solve_l1(img, gx, gy, reweights=6, info=info)
    assert info["reweights"] == 6
    filled = poisson.solve_l1(img, gx, gy, reweights=6, deadline=time.perf_counter() + 1e6, fill=True, info=info)
    assert info["reweights"] == poisson.FILL_MAX * 6
    assert poisson.l1_objective(filled, img, gx, gy) <= poisson.l1_objective(base, img, gx, gy) * (1 + 1e-6)
    t0 = time.perf_counter()
    poisson.solve_l1(img, gx, gy, reweights=10 ** 6, deadline=t0 + 0.2, fill=True, info=info)
    assert time.perf_counter() - t0 < 0.2 + 0.1 and info["reweights"] < poisson.FILL_MAX * 10 ** 6
