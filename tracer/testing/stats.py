"""z-tests with Sidak-corrected levels, and the checks every render test makes."""
import numpy as np
from scipy import stats

ALPHA = 0.01  # family-wise false-failure rate of one test function (or one benchmark's check)


def sidak(n_tests, alpha=ALPHA):
    """Per-test level so that n_tests independent tests together fail with probability alpha."""
    return 1.0 - (1.0 - alpha) ** (1.0 / max(int(n_tests), 1))


def z_critical(n_tests=1, alpha=ALPHA):
    """Two-sided |z| threshold at the Sidak-corrected level for n_tests z-tests of family-wise level alpha."""
    return float(stats.norm.isf(sidak(n_tests, alpha) / 2.0))


def assert_z(estimate, variance, expected, n_tests=1, alpha=ALPHA, what="estimate"):
    """Two-sided z-test of estimate(s) against expected with the given variance(s) of the estimate."""
    est = np.atleast_1d(np.asarray(estimate, dtype=np.float64))
    var = np.atleast_1d(np.asarray(variance, dtype=np.float64))
    exp = np.broadcast_to(np.asarray(expected, dtype=np.float64), est.shape)
    assert np.all(var > 0), f"{what}: variance must be positive to test, got {var}"
    z = (est - exp) / np.sqrt(var)
    zc = z_critical(max(n_tests, est.size), alpha)
    worst = int(np.argmax(np.abs(z)))
    assert np.all(np.abs(z) < zc), (
        f"{what}: |z| = {abs(z[worst]):.2f} >= {zc:.2f} at {worst}: got {est[worst]:.6g}, "
        f"expected {exp[worst]:.6g} +- {np.sqrt(var[worst]):.3g}"
    )
    return z


def image_mean(result, mask=None):
    """Mean over pixels (per channel) and the variance of that mean, from a RenderResult."""
    img = result.image.astype(np.float64)
    var = result.variance.astype(np.float64)
    if mask is not None:
        img, var = img[mask], var[mask]
    else:
        img, var = img.reshape(-1, 3), var.reshape(-1, 3)
    n = img.shape[0]
    return img.mean(axis=0), var.sum(axis=0) / (n * n)


def assert_clean(result, what="render"):
    """The render met no non-finite sample and wrote only finite pixels.

    The integrator zeroes a non-finite sample before the film sees it (and counts it in
    stats["nonfinite_samples"]), so `np.isfinite(image)` alone cannot fail: the count can."""
    n = result.stats["nonfinite_samples"]
    assert n == 0, f"{what}: {n} non-finite sample(s) were zeroed"
    assert np.isfinite(result.image).all() and np.isfinite(result.variance).all(), f"{what}: non-finite pixels"


def clean_seed_images(scene, spp, seeds, first_seed, what="render", **kw):
    """(seeds, H, W, 3) float64 images of `scene` rendered with seeds first_seed, first_seed + 1, ...
    (box filter unless kw says otherwise), each checked by assert_clean."""
    import tracer

    kw.setdefault("pixel_filter", "box")
    out = []
    for k in range(seeds):
        r = tracer.render(scene, spp=spp, seed=first_seed + k, **kw)
        assert_clean(r, what)
        out.append(r.image)
    return np.stack(out).astype(np.float64)
