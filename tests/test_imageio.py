"""Image files: the tonemapped preview and writes that a failure cannot leave half done."""
import os

import numpy as np
import pytest

import tracer
from tracer.imageio import auto_exposure, filmic, temp_path, tonemap


def test_tonemap_range_and_monotone():
    x = np.concatenate([[0.0], np.geomspace(1e-6, 1e6, 2000)])
    y = tonemap(x[None, :, None].repeat(3, axis=2), auto=False)[0, :, 0]
    assert y[0] == 0.0 and np.all(np.diff(y) >= 0.0) and y.max() <= 1.0 and y[-1] == 1.0
    assert np.all(np.diff(y[x < 7.0]) > 0.0)  # strictly increasing below the shoulder (x = 7.24)
    assert filmic(0.13) == pytest.approx(0.18, abs=1e-3)  # where auto exposure puts the log-average


def test_tonemap_non_finite_input():
    img = np.array([[[np.nan, np.inf, -np.inf], [-1.0, 0.5, 2.0]]])
    y = tonemap(img)
    assert np.isfinite(y).all() and y.min() >= 0.0 and y.max() <= 1.0
    np.testing.assert_array_equal(y[0, 0], [0.0, 1.0, 0.0])
    assert y[0, 1, 0] == 0.0  # negative radiance shows as black
    # the exposure comes from the finite, lit pixels only
    assert auto_exposure(img) == auto_exposure(img[:, 1:])


def test_exposure_stops_scale_the_linear_input():
    rng = np.random.default_rng(3)
    img = rng.gamma(0.5, 1.0, (8, 8, 3))
    np.testing.assert_allclose(tonemap(img, exposure=1.0, auto=False), filmic(2.0 * img), rtol=1e-12)
    np.testing.assert_allclose(tonemap(img, exposure=1.0, auto=False), tonemap(2.0 * img, auto=False), rtol=1e-12)
    np.testing.assert_allclose(tonemap(img, exposure=-2.0), filmic(0.25 * auto_exposure(img) * img), rtol=1e-12)
    # automatic exposure makes the preview independent of the radiance's scale
    np.testing.assert_allclose(tonemap(100.0 * img), tonemap(img), rtol=1e-9)
    assert auto_exposure(np.zeros((4, 4, 3))) == 1.0


def test_auto_exposure_ignores_the_noise():
    """A render with the same mean but more noise gets the same exposure. The noisy image is the
    clean one times X = Bernoulli(1/4) x 4 per pixel (mean 1; 3/4 of the pixels black, as a sampler
    that misses the light often). A 2^-0.25 bound: the block means (8x8 pixels at 256x256) have
    relative standard deviation sqrt(3/64) = 0.22, which biases the log-average by about -0.02
    (-0.034 stops) with a spread of 0.22 / sqrt(1024 blocks) = 0.007. A log-average over pixels
    would see the lit pixels alone, 4x brighter: 2 stops darker."""
    y, x = np.mgrid[0:256, 0:256] / 256.0
    clean = np.repeat((0.05 + np.sin(6 * x) ** 2 * (y + 0.2) + 3.0 * ((x - 0.6) ** 2 + (y - 0.3) ** 2 < 0.01))
                      [:, :, None], 3, axis=2)
    clean[:, :32] = 0.0  # a black background on the left
    noisy = clean * (np.random.default_rng(5).random(clean.shape[:2]) < 0.25)[:, :, None] * 4.0
    assert abs(np.log2(auto_exposure(noisy) / auto_exposure(clean))) < 0.25


def test_write_image_is_atomic(tmp_path, monkeypatch):
    path = tmp_path / "a.exr"
    tracer.write_image(path, np.ones((4, 4, 3)))
    before = path.read_bytes()
    tmp = temp_path(path)
    assert os.path.dirname(tmp) == str(tmp_path) and tmp.endswith(".exr") and os.path.basename(tmp).startswith(".a.")

    def fail(src, dst):
        assert os.path.isfile(src) and src == tmp  # written whole under the temporary name first
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(tracer.TracerError, match="a.exr: cannot write output .No space left"):
        tracer.write_image(path, np.zeros((4, 4, 3)))
    assert path.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["a.exr"]
    monkeypatch.undo()
    tracer.write_image(path, np.zeros((4, 4, 3)))
    assert tracer.read_image(path).max() == 0.0 and sorted(os.listdir(tmp_path)) == ["a.exr"]
