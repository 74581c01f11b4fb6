"""Render-level properties: determinism, the random stream, the film, time budgets."""
import numba
import numpy as np
import pytest
from scipy import stats

import tracer
from tracer import rng
from tracer.film import Film
from tests.reference import CORNELL, REF_SIZE, load
from tracer.testing.stats import assert_clean, sidak, z_critical


@pytest.fixture(scope="module")
def small_cornell():
    return tracer.load_scene(CORNELL, width=24, height=20)


def test_same_seed_is_bit_identical_across_wave_sizes_and_threads(small_cornell):
    base = tracer.render(small_cornell, spp=6, seed=3, wave_size=1 << 18)
    assert_clean(base)
    n0 = numba.get_num_threads()
    try:
        for wave, threads in [(97, 1), (480, 2), (4096, 1)]:
            r = tracer.render(small_cornell, spp=6, seed=3, wave_size=wave, threads=threads)
            np.testing.assert_array_equal(r.image, base.image)
            np.testing.assert_array_equal(r.variance, base.variance)
    finally:
        numba.set_num_threads(n0)
    other = tracer.render(small_cornell, spp=6, seed=4)
    assert np.any(other.image != base.image)


def test_spp_in_passes_equals_one_render(small_cornell):
    # Passes add samples in index order: 1+1+2+2 spp by passes equals 6 spp in one go.
    r = tracer.render(small_cornell, spp=6, seed=1)
    assert_clean(r)
    assert [p["spp"] for p in r.stats["passes"]] == [1, 2, 3]
    one = tracer.render(small_cornell, spp=6, seed=1, wave_size=10**7)
    np.testing.assert_array_equal(r.image, one.image)


def test_accels_give_the_same_image(small_cornell):
    a = tracer.render(small_cornell, spp=4, accel="embree", path_loop="thread")  # the wavefront's random numbers
    b = tracer.render(small_cornell, spp=4, accel="numba")
    assert_clean(a)
    assert_clean(b)
    # Same random numbers; only float32-vs-float64 hit points differ, so nearly all pixels match.
    close = np.isclose(a.image, b.image, rtol=1e-3, atol=1e-5).all(axis=2)
    assert close.mean() > 0.97, close.mean()


def test_time_budget_is_honoured(small_cornell):
    tracer.render(small_cornell, spp=1)  # compile outside the budget
    r = tracer.render(small_cornell, time=0.5)
    assert r.stats["spp"] >= 1 and r.stats["time_total"] < 1.5
    assert_clean(r)


def test_callback_runs_between_passes_and_can_stop(small_cornell):
    seen = []

    def cb(i, film, st):
        seen.append((i, st["spp"]))
        return i < 1

    r = tracer.render(small_cornell, spp=64, callback=cb)
    assert seen == [(0, 1), (1, 3)] and r.stats["spp"] == 3


def test_random_stream_is_uniform_and_replayable():
    n = 200_000
    pix = np.arange(n, dtype=np.int64) % 1000
    smp = np.arange(n, dtype=np.int64) // 1000
    dims = np.array([0, 1, rng.bounce_dim(0, rng.DIR), rng.bounce_dim(7, rng.RR)], dtype=np.int64)
    u = rng.uniform_batch(5, pix, smp, dims)
    assert u.min() >= 0.0 and u.max() < 1.0
    # each dimension uniform (chi-square on 50 bins), pairs of dimensions independent (2D grid)
    zc = 4  # number of tests below
    level = 1 - (1 - 0.01) ** (1 / zc)
    for j in range(2):
        counts = np.histogram(u[:, j], bins=50, range=(0, 1))[0]
        assert stats.chisquare(counts).pvalue > level
    grid = np.histogram2d(u[:, 0], u[:, 2], bins=15, range=[[0, 1], [0, 1]])[0].ravel()
    assert stats.chisquare(grid).pvalue > level
    grid = np.histogram2d(u[:, 1], u[:, 3], bins=15, range=[[0, 1], [0, 1]])[0].ravel()
    assert stats.chisquare(grid).pvalue > level
    # replay in reverse order gives the same numbers
    u2 = rng.uniform_batch(5, pix[::-1].copy(), smp[::-1].copy(), dims)
    np.testing.assert_array_equal(u2[::-1], u)
    assert np.any(rng.uniform_batch(6, pix, smp, dims) != u)


def test_film_mean_and_variance_match_numpy():
    g = np.random.default_rng(0)
    film = Film(3, 2)
    pix = np.repeat(np.arange(6), 10)
    rad = g.normal(size=(60, 3)) + 1
    film.add(pix.astype(np.int64), rad, np.zeros((60, 7)))
    m = rad.reshape(6, 10, 3).mean(axis=1)
    v = rad.reshape(6, 10, 3).var(axis=1, ddof=1) / 10
    np.testing.assert_allclose(film.mean().reshape(6, 3), m, rtol=1e-12)
    np.testing.assert_allclose(film.variance().reshape(6, 3), v, rtol=1e-10)


def _z_against_reference(name, spp, seed):
    """z-scores of a render against reference `name`, with the variance of the render taken from
    the reference (per-sample variance x REF_SPP / spp): a render's own low-spp variance estimate
    is correlated with its mean and would bias the scores."""
    ref, ref_var, meta = load(name)
    scene = tracer.load_scene(CORNELL, width=REF_SIZE, height=REF_SIZE)
    r = tracer.render(scene, spp=spp, seed=seed, max_depth=meta["max_depth"], rr_depth=meta["rr_depth"],
                      pixel_filter=meta["pixel_filter"])
    assert_clean(r)
    var = ref_var * (meta["spp"] / spp) + ref_var
    # pixels that see only the (black, emitting) light have no variance: they must match exactly
    exact = var == 0
    np.testing.assert_allclose(r.image[exact], ref[exact], rtol=1e-6)
    z = (r.image - ref) / np.sqrt(np.where(exact, 1.0, var))
    return np.where(exact, np.nan, z).reshape(-1, 3)


def _channel_mean_z(z):
    """Per channel, the mean z over pixels scaled to ~N(0,1) (pixels are independent; the
    channels of one pixel are not, so they are tested separately)."""
    n = np.sum(~np.isnan(z), axis=0)
    return np.nansum(z, axis=0) / np.sqrt(n)


def test_cornell_matches_reference_pixels():
    """Three tests of one render (1024 spp, max_depth 5, point filter: every sample bounded, no
    pixel mixing two surfaces; tests/reference.py) against the stored high-spp reference, each at
    1% (Sidak over the three and over the channels):
    - per pixel, |z| (Sidak over all pixels and channels): a bias of about 4 standard deviations in
      one pixel (a per-pixel standard deviation is 1-7% of the pixel here);
    - per channel, the mean z over the image: a bias spread evenly over the image, such as x1.005
      (mean z 9-11 in two seeds; the threshold is 3.26);
    - per channel, the sum of squared z against chi-square with one degree per pixel: biases that
      cancel in the mean and stay below the per-pixel threshold, such as light moved between
      regions: +1% in the left half and -1% in the right half gives p < 1e-12 in two seeds (the
      threshold is 1.1e-3); +-0.5% is not caught (p 0.02-0.1)."""
    z = _z_against_reference("d5", spp=1024, seed=7)
    n_tests = 3
    zc = z_critical(np.sum(~np.isnan(z)), 0.01 / n_tests)
    assert np.nanmax(np.abs(z)) < zc, f"max |z| {np.nanmax(np.abs(z)):.2f} >= {zc:.2f}"
    zm = _channel_mean_z(z)
    assert np.all(np.abs(zm) < z_critical(3, 0.01 / n_tests)), zm
    n = np.sum(~np.isnan(z), axis=0)
    p = stats.chi2.sf(np.nansum(z * z, axis=0), n)
    level = sidak(3, 0.01 / n_tests)
    assert np.all(p > level), f"sum of z^2 per channel too large: p = {p} (level {level:.2g})"


def test_cornell_unlimited_depth_matches_reference_mean():
    """At unlimited depth roulette makes rare huge samples (see tests/reference.py), so only the
    average z over the image is tested: it detects a bias spread over the image of about 0.7%
    (at 64 spp a pixel's standard deviation is about 10% of it)."""
    zm = _channel_mean_z(_z_against_reference("unlimited", spp=64, seed=7))
    assert np.all(np.abs(zm) < z_critical(3, 0.01)), zm


def test_ctrl_c_returns_the_image_so_far(small_cornell):
    def cb(i, film, st):
        if i == 1:
            raise KeyboardInterrupt

    r = tracer.render(small_cornell, spp=64, callback=cb)
    assert r.stats["interrupted"] and r.stats["spp"] == 3
    assert_clean(r)
    assert r.image.mean() > 0


def test_aovs_at_the_first_hit(small_cornell):
    r = tracer.render(small_cornell, spp=2, pixel_filter="point")
    assert_clean(r)
    n = r.aovs["normal"]
    hit = r.aovs["depth"][:, :, 0] > 0
    np.testing.assert_allclose(np.linalg.norm(n[hit], axis=1), 1.0, rtol=1e-5)
    # the Cornell walls are axis-aligned or the blocks' faces; the back wall faces the camera (-z)
    centre = n[10, 12]
    assert centre[2] < -0.99 or centre[1] > 0.99
    red = r.aovs["albedo"][hit][:, 0].astype(np.float64)
    assert np.all(np.min(np.abs(red[:, None] - [0.725, 0.63, 0.14, 0.0]), axis=1) < 1e-6)


def test_crop_reproduces_the_window_of_the_full_render(small_cornell):
    full = tracer.render(small_cornell, spp=3, seed=5)
    part = tracer.render(small_cornell, spp=3, seed=5, crop=(7, 4, 10, 9))
    assert_clean(full)
    np.testing.assert_array_equal(part.image, full.image[4:13, 7:17])
    assert part.stats["width"] == 10 and part.stats["height"] == 9
    with pytest.raises(tracer.SettingsError, match="not inside"):
        tracer.render(small_cornell, spp=1, crop=(20, 0, 10, 10))


def test_combined_films_are_unbiased_under_heavy_tails():
    """film.combine_films over three films of lognormal samples (sigma 1.5: a few samples carry
    much of the mean, as fireflies do), 2000 trials: the mean of the combined image's mean is the
    distribution's mean, z-tested with the trials' spread. Weights from each film's own variance
    (the film that fell high gets less weight) fail it: they came out 3.6% low, z = -24."""
    from tracer.film import Film, combine_films

    rng = np.random.default_rng(1)
    trials, h, w = 2000, 8, 8
    out = np.empty(trials)
    for t in range(trials):
        films = []
        for n in (4, 8, 16):
            f = Film(w, h)
            x = rng.lognormal(0.0, 1.5, size=(h * w, n))
            f.count[:] = n
            f.sum[:] = x.sum(axis=1)[:, None]
            f.sumsq[:] = (x * x).sum(axis=1)[:, None]
            films.append(f)
        image, _, weights = combine_films(films)
        out[t] = image.mean()
    assert abs(sum(weights) - 1.0) < 1e-12 and min(weights) > 0.0
    mu = np.exp(1.5**2 / 2.0)
    z = (out.mean() - mu) / (out.std(ddof=1) / np.sqrt(trials))
    assert abs(z) < z_critical(1), (out.mean() / mu, z)


@pytest.mark.parametrize("kw", [{}, {"guide": "photon"}, {"integrator": "gpt"}, {"time": 0.2}],
                         ids=["bsdf", "photon", "gpt", "time"])
def test_a_finished_render_frees_its_accel_without_the_cyclic_gc(small_cornell, monkeypatch, kw):
    """Each render builds its own Embree scene (C memory: about 150 MB on Mitsuba's staircase). A
    reference cycle left behind by render() keeps it alive until Python's cyclic collector happens
    to run, so a process that renders many times (a bench sweep's worker) grows without bound: one
    reached 20 GB after 460 renders. With the collector off, the accel must be freed as soon as the
    result is dropped. Detects any cycle through the render's session, context or guide."""
    import gc
    import importlib
    import weakref

    render_module = importlib.import_module("tracer.render")  # (tracer.render is also the function)

    made, real = [], render_module.make_accel

    def tracked(*a, **k):
        acc = real(*a, **k)
        made.append(weakref.ref(acc))
        return acc

    args = dict({"spp": 2}, **kw)
    tracer.render(small_cornell, **args)  # compile first: a kernel compiled during a render holds its arguments
    monkeypatch.setattr(render_module, "make_accel", tracked)
    gc.collect()
    gc.disable()
    try:
        r = tracer.render(small_cornell, **args)
        assert r.stats["nonfinite_samples"] == 0
        del r
        assert made and all(ref() is None for ref in made)
    finally:
        gc.enable()
