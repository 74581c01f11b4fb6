"""Toy methods plugged into each seam of the renderer: the sample seam (external primary
samples), ray sources (probe rays, shifted camera), and a per-pixel guide.

Each test names the error it detects. The closed box (walls emit Le and reflect a, camera
inside) has radiance Le / (1 - a) along every ray, the independent answer used here.
"""
import numpy as np
import pytest

import tracer
from tracer.camera import camera_ray
from tracer.film import Film, SampleSink
from tracer.guiding.base import Guide
from tracer.guiding.directional import build_tables
from tracer.guiding.spatial import empty_state
from tracer.render import make_context
from tracer.rng import BLOCK, BOUNCE, DIR, path_key, pss_dims, uniform_batch
from tracer.session import trace_source
from tracer.sources import CameraSource, PrimarySampleSource, ProbeSource

from . import scenes
from .stats import assert_clean, assert_z

A, LE = 0.5, 1.0
W = H = 16


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    return tracer.load_scene(scenes.closed_box(tmp_path_factory.mktemp("box"), A, LE, width=W, height=H))


def _film_of(ctx, source, spp=1):
    film = Film(W, H)
    st = trace_source(ctx, source, film, spp)
    assert st.nonfinite == 0
    return film


def _stream(ctx, dims, spp=1):
    """The stream's own values of `dims` for every path of a pass of spp (sample-major), computed
    by rng.uniform_batch from (seed, image pixel, sample)."""
    g = np.arange(spp * W * H)
    return uniform_batch(ctx.seed, g % (W * H), g // (W * H), np.asarray(dims, np.int64))


def test_external_samples_equal_to_the_stream_replay_the_camera_exactly(box):
    """PrimarySampleSource fed the stream's own values of pss_dims(2) renders the camera's image
    bit for bit. Detects a seam that reads the wrong column, the wrong row (path slot), or the
    wrong dimension for any of the 6 replaced dimensions."""
    ctx = make_context(box, seed=3, max_depth=-1)
    dims = pss_dims(2)
    base = _film_of(ctx, CameraSource(), spp=2)
    warped = _film_of(ctx, PrimarySampleSource(_stream(ctx, dims, spp=2), dims), spp=2)
    assert np.array_equal(base.sum, warped.sum) and np.array_equal(base.count, warped.count)
    shuffled = _stream(ctx, dims, spp=2)[::-1].copy()  # each path another path's values
    other = _film_of(ctx, PrimarySampleSource(shuffled, dims), spp=2)
    assert not np.array_equal(base.sum, other.sum)


def test_a_constant_pixel_position_is_the_point_filter(box):
    """u = (0.5, 0.5) for the two pixel dimensions of every path puts every ray through its pixel's
    centre: the image equals a point-filter render. Detects the pixel dimensions not reaching the
    camera, or reaching it swapped or offset."""
    ctx = make_context(box, seed=4, max_depth=3)
    point = make_context(box, seed=4, max_depth=3, pixel_filter="point")
    src = PrimarySampleSource(np.full((W * H, 2), 0.5), pss_dims(0))
    assert np.array_equal(_film_of(ctx, src).sum, _film_of(point, CameraSource()).sum)


def test_a_constant_first_direction_is_shared_by_every_sample_of_a_pixel(box):
    """With the pixel position and bounce 0's direction constant, all samples of a pixel leave
    their (shared) first hit in one direction, while their second directions come from the
    stream and differ. Detects the direction dimensions of bounce 0 not being replaced, or those
    of bounce 1 being replaced too."""
    ctx = make_context(box, seed=5, max_depth=-1)
    spp = 8
    u = np.tile([0.3, 0.6, 0.3, 0.7], (spp * W * H, 1))  # off the pixel centres: no hit on a box edge
    got = []
    trace_source(ctx, PrimarySampleSource(u, pss_dims(1)), Film(W, H), spp, observe=got.append)
    rec = got[0]
    used = rec.strategy >= 0
    first = used & (rec.prev < 0)
    second = used & (rec.prev >= 0) & np.isin(rec.prev, np.flatnonzero(first))
    for p in (0, 77, W * H - 1):
        wi1 = rec.wi[first & (rec.pixel == p)]
        wi2 = rec.wi[second & (rec.pixel == p)]
        assert wi1.shape[0] == spp and np.ptp(wi1, axis=0).max() == 0.0
        assert wi2.shape[0] >= 2 and np.ptp(wi2, axis=0).max() > 1e-3


def test_weights_multiply_the_samples(box):
    """A per-path weight w scales that path's value: weights of 2 double the film's sums exactly
    (detects weights ignored by the sink, or applied twice)."""
    ctx = make_context(box, seed=6, max_depth=4)
    u = _stream(ctx, pss_dims(0))
    one = _film_of(ctx, PrimarySampleSource(u, pss_dims(0)))
    two = _film_of(ctx, PrimarySampleSource(u, pss_dims(0), weight=np.full(W * H, 2.0)))
    np.testing.assert_array_equal(two.sum, 2.0 * one.sum)


def test_whole_image_samples_land_where_their_pixel_position_says(box):
    """whole_image: dims 0 and 1 place the sample anywhere in the film; its pixel is
    floor(u0 W) + W floor(u1 H), computed here independently (detects swapped axes or pixels
    taken from the path index)."""
    ctx = make_context(box, seed=7, max_depth=2)
    u = np.random.default_rng(1).random((3000, 2))
    sink = SampleSink()
    trace_source(ctx, PrimarySampleSource(u, pss_dims(0), whole_image=True), sink)
    pix, w, L, _ = sink.samples()
    np.testing.assert_array_equal(pix, np.floor(u[:, 0] * W).astype(int) + W * np.floor(u[:, 1] * H).astype(int))
    assert (w == 1.0).all() and (L > 0).all()


def test_probe_rays_return_the_radiance_along_them(box):
    """Probe rays from inside the closed box in random directions: the mean radiance is Le / (1 - a)
    (z-test on the samples' variance; detects a source that drops emission at the first hit, or
    keys shared between rays: a 5% bias at 4000 rays is |z| ~ 10)."""
    ctx = make_context(box, seed=8, max_depth=-1)
    n = 4000
    rng = np.random.default_rng(2)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = rng.uniform(-0.5, 0.5, size=(n, 3))
    keys = np.array([path_key(8, i, 0) for i in range(n)], np.uint64)
    sink = SampleSink()
    trace_source(ctx, ProbeSource(o, d, keys), sink)
    pix, _, L, aov = sink.samples()
    np.testing.assert_array_equal(pix, np.arange(n))
    lum = L.mean(axis=1)
    assert_z(lum.mean(), lum.var(ddof=1) / n, LE / (1 - A), what="probe radiance")
    # the depth AOV is the distance to the box's wall along each ray (an independent formula)
    t_wall = np.min(np.where(d > 0, (1 - o) / np.where(d > 0, d, 1), np.where(d < 0, (-1 - o) / np.where(d < 0, d, 1),
                                                                                np.inf)), axis=1)
    np.testing.assert_allclose(aov[:, 6], t_wall, rtol=1e-6)


def test_probe_rays_through_the_pixel_centres_replay_a_point_filter_render(box):
    """Probe rays equal to the camera's rays through the pixel centres, with the camera's keys,
    give the point-filter image bit for bit (detects a probe source that keys, orders or starts
    paths differently from the camera)."""
    ctx = make_context(box, seed=9, max_depth=-1, pixel_filter="point")
    o = np.empty((W * H, 3))
    d = np.empty((W * H, 3))
    keys = np.empty(W * H, np.uint64)
    for p in range(W * H):
        px, py = p % W, p // W
        ro, rd = camera_ray(ctx.cam, W, H, px, py, 0.5, 0.5)
        o[p], d[p] = ro, rd
        keys[p] = path_key(9, py * W + px, 0)
    sink = SampleSink()
    trace_source(ctx, ProbeSource(o, d, keys), sink)
    _, _, L, _ = sink.samples()
    np.testing.assert_array_equal(L, _film_of(ctx, CameraSource()).sum)


def test_a_shifted_camera_replays_the_neighbours_keys(box):
    """CameraSource(shift=(1, 0)) traces pixel x's key through pixel x + 1: film pixel x of the
    shifted render is what pixel x+1 gives with pixel x's key, so a shifted render is not the
    camera's image moved by one pixel (different keys), while its mean is the same (z-test;
    detects the shift applied to the key instead of the ray: then the shifted image would equal
    the moved one exactly)."""
    ctx = make_context(box, seed=10, max_depth=-1)
    spp = 16
    base = _film_of(ctx, CameraSource(), spp)
    shifted = _film_of(ctx, CameraSource(shift=(1, 0)), spp)
    b = base.mean()[:, 1:]
    s = shifted.mean()[:, :-1]
    assert not np.array_equal(b, s)
    v = shifted.variance()[:, :-1].mean(axis=2)
    assert_z(s.mean(), v.sum() / v.size ** 2, LE / (1 - A), what="shifted camera mean")


class ToyPixelGuide(Guide):
    """A per-pixel guide: every pixel's first bounce samples the same map (uniform over the sphere,
    so half of it below the surface: a wrong map), mixed with the BSDF at a = 0.5."""

    name = "toy-pixel"

    def __init__(self, n_theta=4, n_phi=8):
        self.n_theta, self.n_phi = n_theta, n_phi

    def prepare(self, scene, ctx):
        tabs = build_tables(np.ones((1, self.n_theta, self.n_phi)))
        self._state = empty_state(self.n_theta, self.n_phi)._replace(
            rowcum=tabs.rowcum, dens=tabs.dens, wsum=tabs.wsum, pscale=tabs.pscale,
            pixel_slot=np.zeros(ctx.n_pixels, np.int32), pixel_alpha=np.full(ctx.n_pixels, 0.5))

    def state(self):
        return self._state


def test_a_per_pixel_guide_guides_the_first_bounce_only(box):
    """The toy per-pixel map is drawn from at first hits with probability 1 - a = 0.5 (binomial
    z-test), never later (detects locate ignoring the pixel or the depth)."""
    ctx = make_context(box, seed=11, max_depth=-1)
    g = ToyPixelGuide()
    g.prepare(box, ctx)
    ctx.guide_state = g.state()
    got = []
    trace_source(ctx, CameraSource(), Film(W, H), 4, observe=got.append)
    rec = got[0]
    used = rec.strategy >= 0
    first = used & (rec.prev < 0)
    later = used & (rec.prev >= 0)
    n = int(first.sum())
    frac = float((rec.strategy[first] == 1).mean())
    assert_z(frac, 0.25 / n, 0.5, what="share of guided first bounces")
    assert later.sum() > 0 and (rec.strategy[later] == 0).all()


def test_a_wrong_per_pixel_map_stays_unbiased(box):
    """render() with the toy guide (its default schedule: final passes only): every pixel's mean
    is Le / (1 - a) (z-test over pixels; detects a mixture pdf that is not the one sampled from,
    e.g. the map's pdf left out of the MIS weights or the BSDF's weight not divided by it)."""
    r = tracer.render(box, spp=32, guide=ToyPixelGuide(), seed=12, max_depth=-1)
    assert_clean(r)
    img = r.image.astype(np.float64).mean(axis=2).ravel()
    var = r.variance.astype(np.float64).mean(axis=2).ravel()
    assert_z(img.mean(), var.sum() / img.size ** 2, LE / (1 - A), what="toy-guided image mean")
    plain = tracer.render(box, spp=32, seed=12, max_depth=-1)
    assert not np.array_equal(plain.image, r.image)  # the map was used


def test_pss_dims_follow_the_dimension_table():
    """pss_dims(m): pixel (0, 1), then each bounce's two direction dimensions, from the table's
    constants (detects a layout change that forgets the seam)."""
    assert pss_dims(0).tolist() == [0, 1]
    assert pss_dims(2).tolist() == [0, 1, BOUNCE + DIR, BOUNCE + DIR + 1, BOUNCE + BLOCK + DIR,
                                    BOUNCE + BLOCK + DIR + 1]
    with pytest.raises(ValueError):
        pss_dims(-1)
