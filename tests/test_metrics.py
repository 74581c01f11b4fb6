"""Error metrics on inputs with known answers."""
import numpy as np
import pytest

from tracer import metrics


def test_relmse_and_mse_known_values():
    ref = np.full((4, 5, 3), 0.1)
    img = ref + 0.1
    assert metrics.mse(img, ref) == pytest.approx(0.01)
    assert metrics.relmse(img, ref) == pytest.approx(0.01 / (0.01 + 0.01))
    assert metrics.relmse(ref, ref) == 0.0 and metrics.mse(ref, ref) == 0.0


def test_trimmed_mrse_drops_the_worst_pixels():
    ref = np.ones((100, 100, 3))
    img = ref.copy()
    img[0, 0] = 1000.0  # one firefly: 1 pixel of 10,000 is the 0.01% that is trimmed
    assert metrics.mrse_trimmed(img, ref) == 0.0
    assert metrics.relmse(img, ref) > 1.0
    img[0, 1] = 2.0  # a second bad pixel stays: error (1)^2 / 1.01 over 9,999 pixels
    assert metrics.mrse_trimmed(img, ref) == pytest.approx(1 / 1.01 / 9999)


def test_ssim_is_zero_for_identical_and_grows_with_noise():
    g = np.random.default_rng(0)
    ref = g.random((32, 32, 3))
    assert metrics.one_minus_ssim(ref, ref) == pytest.approx(0.0, abs=1e-12)
    a = metrics.one_minus_ssim(ref + g.normal(0, 0.05, ref.shape), ref)
    b = metrics.one_minus_ssim(ref + g.normal(0, 0.2, ref.shape), ref)
    assert 0 < a < b <= 2


def test_mismatched_sizes_are_an_error():
    with pytest.raises(Exception, match="reference"):
        metrics.relmse(np.zeros((4, 4, 3)), np.zeros((5, 4, 3)))


def test_all_metrics_names():
    x = np.ones((8, 8, 3))
    assert set(metrics.all_metrics(x, x)) == {"relMSE", "MSE", "MrSE", "1-SSIM"}
