"""The ODIS input gather (tracer.guiding.odis.features) against a slow twin written here.

The twin loops in Python over the centre's window and its samples, bins each direction by its own
z = cos(theta) and phi = atan2(y, x) formulas, and averages; the kernel must give the same means and
sampled mask (detects a wrong window, a sample binned into the wrong bin or counted twice, channels
out of order). The valid mask is checked analytically: for a normal along +z it is exactly the
upper half of the rows (detects a hemisphere taken from the wrong normal or the wrong side).
"""
import math

import numpy as np
import pytest

from tracer.guiding.odis.features import N_CHANNELS, gather


def _random_samples(rng, width, height, per_pixel):
    pix = np.repeat(np.arange(width * height), per_pixel)
    keep = rng.random(pix.shape[0]) < 0.7  # some pixels get fewer samples, some none
    pix = pix[keep]
    n = pix.shape[0]
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return dict(pix=pix, dirs=d, radiance=rng.random((n, 3)), depth1=rng.random(n) * 5, normal1=nrm,
                depth2=rng.random(n), normal2=-nrm)


def _twin(s, width, height, centre, k, nt, nphi):
    feats = np.zeros((N_CHANNELS, nt, nphi))
    count = np.zeros((nt, nphi))
    cx, cy = centre % width, centre // width
    chans = np.column_stack([s["radiance"].mean(axis=1), s["depth1"], s["normal1"], s["depth2"], s["normal2"]])
    for i in range(s["pix"].shape[0]):
        x, y = s["pix"][i] % width, s["pix"][i] // width
        if abs(x - cx) <= k // 2 and abs(y - cy) <= k // 2:
            d = s["dirs"][i]
            row = min(int((d[2] + 1) / 2 * nt), nt - 1)
            col = min(int((math.atan2(d[1], d[0]) + math.pi) / (2 * math.pi) * nphi), nphi - 1)
            count[row, col] += 1
            feats[:, row, col] += chans[i]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, feats / count, 0.0), count > 0


@pytest.mark.parametrize("k", [1, 3, 5])
def test_gather_matches_a_slow_twin(k):
    rng = np.random.default_rng(k)
    width, height, nt, nphi = 7, 5, 8, 12
    s = _random_samples(rng, width, height, 4)
    centres = np.array([0, 8, 17, 34, 22])
    feats, sampled, _ = gather(s["pix"], s["dirs"], s["radiance"], s["depth1"], s["normal1"], s["depth2"],
                               s["normal2"], width, height, centres, k=k, n_theta=nt, n_phi=nphi)
    assert feats.shape == (5, N_CHANNELS, nt, nphi) and sampled.shape == (5, nt, nphi)
    for m, c in enumerate(centres):
        want, mask = _twin(s, width, height, c, k, nt, nphi)
        np.testing.assert_array_equal(sampled[m].astype(bool), mask)
        np.testing.assert_allclose(feats[m], want, rtol=1e-6, atol=1e-6)


def test_valid_mask_is_the_upper_hemisphere_for_an_up_normal():
    nt, nphi = 8, 16
    d = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    up = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    _, _, valid = gather(np.array([0, 0]), d, np.ones(2), np.ones(2), up, np.zeros(2), np.zeros((2, 3)), 2, 1,
                         np.array([0, 1]), k=1, n_theta=nt, n_phi=nphi)
    np.testing.assert_array_equal(valid[0], np.repeat((np.arange(nt) >= nt // 2)[:, None], nphi, axis=1))
    assert valid[1].sum() == 0  # pixel 1 has no sample of its own: no valid hemisphere


def test_window_is_clipped_at_the_film_border_and_k_must_be_odd():
    s = _random_samples(np.random.default_rng(0), 3, 3, 2)
    args = (s["pix"], s["dirs"], s["radiance"], s["depth1"], s["normal1"], s["depth2"], s["normal2"], 3, 3)
    _, sampled, _ = gather(*args, np.array([4]), k=11, n_theta=4, n_phi=4)
    assert sampled.sum() == np.unique(
        [int((d[2] + 1) / 2 * 4) * 4 + int((math.atan2(d[1], d[0]) + math.pi) / (2 * math.pi) * 4)
         for d in s["dirs"]]).size  # every sample of the 3 x 3 film, nothing outside
    with pytest.raises(ValueError):
        gather(*args, np.array([4]), k=4)


def test_initial_samples_in_a_closed_box_match_the_geometry(tmp_path):
    # Inside the cube [-1, 1]^3 every first-bounce direction meets another wall: depth2 is the
    # exit distance along the direction and normal2 that wall's inward normal (the slab formula,
    # written here), depth1 the distance from the camera to the first hit.
    import tracer
    from tests import scenes
    from tracer.film import Film
    from tracer.guiding.odis.features import initial_samples
    from tracer.render import make_context
    from tracer.session import trace_source
    from tracer.sources import CameraSource
    from tracer.wave import WaveBuffers

    scene = tracer.load_scene(scenes.closed_box(tmp_path, 0.5, 1.0, width=10, height=8))
    ctx = make_context(scene, seed=3, max_depth=3)
    origin = np.array([0.0, 0.0, 0.5])
    sizes, counts = [], []

    def check(rec):  # the records are the wave buffer's: check them before the next wave
        n = sizes[-1]
        s = initial_samples(rec, n, origin)
        first = np.nonzero(rec.strategy[:n] >= 0)[0]
        assert s["pix"].shape[0] == first.shape[0] > 0
        x0 = rec.x[first].astype(np.float64)
        np.testing.assert_allclose(s["depth1"], np.linalg.norm(x0 - origin, axis=1), rtol=1e-6)
        d = s["dirs"]
        with np.errstate(divide="ignore", invalid="ignore"):
            t_axes = (np.sign(d) - x0) / d
        t_axes[~np.isfinite(t_axes) | (t_axes <= 0)] = np.inf
        axis = np.argmin(t_axes, axis=1)
        rows = np.arange(d.shape[0])
        np.testing.assert_allclose(s["depth2"], t_axes[rows, axis], rtol=1e-4, atol=1e-4)
        want_n = np.zeros_like(d)
        want_n[rows, axis] = -np.sign(d[rows, axis])
        np.testing.assert_allclose(s["normal2"], want_n, atol=1e-5)
        assert np.abs(s["normal1"]).max(axis=1).min() > 0.99999  # axis-aligned walls
        assert np.isfinite(s["radiance"]).all() and (s["radiance"] >= 0).all()
        counts.append(first.shape[0])

    trace_source(ctx, CameraSource(), Film(10, 8), spp=3, buf=WaveBuffers(100), observe=check,
                 before_wave=sizes.append)
    assert sizes == [100, 100, 40]
    assert sum(counts) == 240  # every camera ray hits a diffuse wall and samples a direction
