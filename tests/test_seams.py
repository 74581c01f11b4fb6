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
from tracer.guiding.contract import empty_state
from tracer.render import make_context
from tracer.rng import BLOCK, BOUNCE, DIR, path_key, pss_dims, uniform_batch
from tracer.session import trace_source
from tracer.sources import CameraSource, PrimarySampleSource, ProbeSource
from tracer.splitting import throughput_plan
from tracer.testing.stats import assert_clean, assert_z
from tracer.wave import WaveBuffers

from . import scenes

A, LE = 0.5, 1.0
W = H = 16


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    return tracer.load_scene(scenes.closed_box(tmp_path_factory.mktemp("box"), A, LE, width=W, height=H))


WAVE = 97  # paths per wave in these tests: every pass spans several waves, the last one partial


def _film_of(ctx, source, spp=1):
    film = Film(W, H)
    st = trace_source(ctx, source, film, spp, buf=WaveBuffers(WAVE))
    assert st.nonfinite == 0
    return film


def _samples_of(ctx, source, spp=1):
    sink = SampleSink()
    st = trace_source(ctx, source, sink, spp, buf=WaveBuffers(WAVE))
    assert st.nonfinite == 0
    return sink.samples()


def _probe_rays(ctx, pixels, jx, jy, seed, shift=(0, 0)):
    """Camera rays through (x + shift, y + shift) at (jx, jy) inside the pixel, with the keys of
    film pixels `pixels` at sample 0 (the rays from camera_ray, the keys from rng.path_key)."""
    o = np.empty((len(pixels), 3))
    d = np.empty((len(pixels), 3))
    keys = np.empty(len(pixels), np.uint64)
    for j, p in enumerate(pixels):
        px, py = p % W, p // W
        o[j], d[j] = camera_ray(ctx.cam, W, H, px + shift[0], py + shift[1], jx, jy)
        keys[j] = path_key(seed, py * W + px, 0)
    return ProbeSource(o, d, keys)


def _stream(ctx, dims, spp=1):
    """The stream's own values of `dims` for every path of a pass of spp (sample-major), computed
    by rng.uniform_batch from (seed, image pixel, sample)."""
    g = np.arange(spp * W * H)
    return uniform_batch(ctx.seed, g % (W * H), g // (W * H), np.asarray(dims, np.int64))


def test_external_samples_equal_to_the_stream_replay_the_camera_exactly(box):
    """PrimarySampleSource fed the stream's own values of pss_dims(2) renders the camera's image
    bit for bit. Detects a seam that reads the wrong column, the wrong row (path slot: with
    rr_depth 1 paths die from the first bounce on, so slots and entries differ), the wrong wave
    offset, or the wrong dimension for any of the 6 replaced dimensions."""
    ctx = make_context(box, seed=3, max_depth=-1, rr_depth=1)
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


def test_a_constant_pixel_position_is_the_ray_through_it(box):
    """u = (0.25, 0.75): every path of pixel (x, y) starts on the camera ray through (x + 0.25,
    y + 0.75), which a ProbeSource of those rays with the same keys replays bit for bit (detects
    swapped or offset pixel dimensions)."""
    L, Lp = _constant_position(box)
    np.testing.assert_array_equal(L, Lp)


def _constant_position(box):
    ctx = make_context(box, seed=4, max_depth=3)
    src = PrimarySampleSource(np.tile([0.25, 0.75], (W * H, 1)), pss_dims(0))
    _, _, L, _ = _samples_of(ctx, src)
    _, _, Lp, _ = _samples_of(ctx, _probe_rays(ctx, range(W * H), 0.25, 0.75, 4))
    return L, Lp


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
    """Random per-path weights over several waves and 2 spp: the film's count, sum and sum of
    squares equal those accumulated here with np.add.at from the unweighted samples (detects
    weights ignored, applied twice, taken from the wrong row or wave, or counted as samples)."""
    ctx = make_context(box, seed=6, max_depth=4)
    u = _stream(ctx, pss_dims(0), spp=2)
    w = np.random.default_rng(7).uniform(0.0, 3.0, size=u.shape[0])
    pix, _, L, _ = _samples_of(ctx, PrimarySampleSource(u, pss_dims(0)), spp=2)
    film = _film_of(ctx, PrimarySampleSource(u, pss_dims(0), weight=w), spp=2)
    count, s, sq = np.zeros(W * H), np.zeros((W * H, 3)), np.zeros((W * H, 3))
    np.add.at(count, pix, 1.0)
    np.add.at(s, pix, w[:, None] * L)
    np.add.at(sq, pix, (w[:, None] * L) ** 2)
    np.testing.assert_array_equal(film.count, count)
    np.testing.assert_allclose(film.sum, s, rtol=1e-12)
    np.testing.assert_allclose(film.sumsq, sq, rtol=1e-12)


@pytest.mark.parametrize("pixel_filter", ["box", "point"])
def test_whole_image_samples_land_where_their_pixel_position_says(box, pixel_filter):
    """whole_image: dims 0 and 1 place the sample anywhere in the film (here a crop window); its
    film pixel is floor(u0 w) + w floor(u1 h), computed here independently, with either pixel
    filter (detects swapped axes, the crop's offset, or pixels taken from the path index)."""
    x0, y0, cw, ch = 3, 5, 9, 7
    ctx = make_context(box, seed=7, max_depth=2, crop=(x0, y0, cw, ch), pixel_filter=pixel_filter)
    u = np.random.default_rng(1).random((3000, 2))
    pix, w, L, _ = _samples_of(ctx, PrimarySampleSource(u, pss_dims(0), whole_image=True))
    np.testing.assert_array_equal(pix, np.floor(u[:, 0] * cw).astype(int) + cw * np.floor(u[:, 1] * ch).astype(int))
    assert (w == 1.0).all() and (L > 0).all()


def test_a_warp_of_the_image_plane_weighted_by_its_density_is_unbiased(box):
    """Samples placed over the whole image with density 2 u0 along x (u0 = sqrt(U)), weighted by
    1 / (2 u0): each pixel's estimate (P / N) sum of weight x value is Le / (1 - a) (z-test of the
    image mean; normalising by the samples that landed instead, pixels on the left, with few
    heavy samples, would read ~3x too much: |z| > 100)."""
    ctx = make_context(box, seed=8, max_depth=-1)
    rng = np.random.default_rng(3)
    n = 64 * W * H
    u = np.stack([np.sqrt(rng.random(n)), rng.random(n)], axis=1)
    film = _film_of(ctx, PrimarySampleSource(u, pss_dims(0), weight=1.0 / (2.0 * u[:, 0]), whole_image=True))
    assert (film.count == n).all()
    img = film.mean().mean(axis=2).ravel()
    var = film.variance().mean(axis=2).ravel()
    assert_z(img.mean(), var.sum() / img.size ** 2, LE / (1 - A), what="warped image mean")


def test_split_copies_read_the_stream_and_stay_unbiased(tmp_path):
    """Throughput splitting in a pass with external samples of the first two bounces, in a box of
    albedo 0.96 (Russian roulette continues with 0.95, so beta grows to 0.96 / 0.95 > 1 and paths
    split): copies are made, and the image mean is Le / (1 - a) = 25 (z-test; copies reading past
    the external rows would crash or bias the image)."""
    a = 0.96
    box = tracer.load_scene(scenes.closed_box(tmp_path, a, LE, width=W, height=H))
    ctx = make_context(box, seed=9, max_depth=-1, rr_depth=1)
    spp = 16
    u = _stream(ctx, pss_dims(2), spp=spp)[::-1].copy()
    film = Film(W, H)
    st = trace_source(ctx, PrimarySampleSource(u, pss_dims(2)), film, spp, buf=WaveBuffers(1000, split=True),
                      split=throughput_plan(1.0))
    assert st.split_copies > 0 and st.nonfinite == 0
    img = film.mean().mean(axis=2).ravel()
    var = film.variance().mean(axis=2).ravel()
    assert_z(img.mean(), var.sum() / img.size ** 2, LE / (1 - a), what="split image mean")


def test_probe_rays_return_the_radiance_along_them(box):
    """Probe rays from inside the closed box in random directions, over several waves: the mean
    radiance is Le / (1 - a) (z-test on the samples' variance; detects a source that drops the
    emission at the first hit: a 5% bias at 4000 rays is |z| ~ 10), the sink index is the ray's
    row, and the depth AOV is the distance to the wall along each ray (detects rays taken from the
    wrong row or wave)."""
    ctx = make_context(box, seed=8, max_depth=-1)
    n = 4000
    rng = np.random.default_rng(2)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = rng.uniform(-0.5, 0.5, size=(n, 3))
    keys = np.array([path_key(8, i, 0) for i in range(n)], np.uint64)
    pix, _, L, aov = _samples_of(ctx, ProbeSource(o, d, keys))
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
    _, _, L, _ = _samples_of(ctx, _probe_rays(ctx, range(W * H), 0.5, 0.5, 9))
    np.testing.assert_array_equal(L, _film_of(ctx, CameraSource()).sum)


def test_a_shifted_camera_replays_the_neighbours_keys(box):
    """CameraSource(shift=(dx, dy)) traces pixel x's key through pixel x + (dx, dy), and its sample
    goes to film pixel x: with the point filter it equals, bit for bit, a ProbeSource through the
    centre of x + (dx, dy) with x's key (detects the shift applied to the key or the film pixel
    instead of the ray, or in the wrong direction)."""
    ctx = make_context(box, seed=10, max_depth=-1, pixel_filter="point")
    for shift in ((1, 0), (0, -1)):
        pix, _, L, _ = _samples_of(ctx, CameraSource(shift=shift))
        np.testing.assert_array_equal(pix, np.arange(W * H))
        _, _, Lp, _ = _samples_of(ctx, _probe_rays(ctx, range(W * H), 0.5, 0.5, 10, shift=shift))
        np.testing.assert_array_equal(L, Lp)


class ToyPixelGuide(Guide):
    """A per-pixel guide: the first bounce of every even film pixel samples the same map (uniform
    over the sphere, so half of it below the surface: a wrong map), mixed with the BSDF at a = 0.5;
    odd pixels have no map."""

    name = "toy-pixel"

    def __init__(self, n_theta=4, n_phi=8):
        self.n_theta, self.n_phi = n_theta, n_phi

    def prepare(self, scene, ctx):
        tabs = build_tables(np.ones((1, self.n_theta, self.n_phi)))
        self._state = empty_state(self.n_theta, self.n_phi)._replace(
            rowcum=tabs.rowcum, dens=tabs.dens, wsum=tabs.wsum, pscale=tabs.pscale,
            pixel_slot=np.where(np.arange(ctx.n_pixels) % 2 == 0, 0, -1).astype(np.int32),
            pixel_alpha=np.full(ctx.n_pixels, 0.5))

    def state(self):
        return self._state


def test_a_per_pixel_guide_guides_the_first_bounce_only(box):
    """The toy per-pixel map is drawn from at the first hits of even pixels with probability 1 - a =
    0.5 (binomial z-test), never at odd pixels, never later (detects locate ignoring the pixel or
    the depth)."""
    ctx = make_context(box, seed=11, max_depth=-1)
    g = ToyPixelGuide()
    g.prepare(box, ctx)
    ctx.guide_state = g.state()
    got = []
    trace_source(ctx, CameraSource(), Film(W, H), 4, observe=got.append)
    rec = got[0]
    used = rec.strategy >= 0
    even = rec.pixel % 2 == 0
    first = used & (rec.prev < 0) & even
    later = used & (rec.prev >= 0)
    n = int(first.sum())
    frac = float((rec.strategy[first] == 1).mean())
    assert_z(frac, 0.25 / n, 0.5, what="share of guided first bounces")
    assert later.sum() > 0 and (rec.strategy[later] == 0).all()
    assert (rec.strategy[used & ~even] == 0).all()
    assert (rec.node[used & (rec.strategy == 1)] == -1).all()  # no voxel is credited with the pixel map


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


def _imported_modules(path, package):
    """The absolute names of the modules a source file imports (relative imports resolved against
    `package`, the file's own package), wherever in the file the import stands."""
    import ast

    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")[:len(package.split(".")) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            found.add(module)
            found.update(f"{module}.{a.name}" for a in node.names)  # `from .. import integrators`
    return found


def _layer_violations(folder, forbidden):
    """(file, module) for each import under tracer/`folder` of a module in or under `forbidden`."""
    import pathlib

    root = pathlib.Path(tracer.__file__).parent
    bad = []
    for path in sorted((root / folder).rglob("*.py")):
        package = ".".join(("tracer",) + path.relative_to(root).parent.parts)
        for module in _imported_modules(path, package):
            if any(module == f or module.startswith(f + ".") for f in forbidden):
                bad.append((str(path.relative_to(root)), module))
    return bad


def test_guides_import_nothing_of_an_integrator(tmp_path):
    """A guide reaches the path engine through the session (session.trace_source, the Session its
    schedule is given), never through an integrator: no module under tracer/guiding imports
    tracer.integrators or tracer.gradient, at top level or inside a function. The import scan is
    checked on a planted file first, so a scan that finds nothing cannot pass."""
    planted = tmp_path / "warm.py"
    planted.write_text("def warm_up(ctx):\n    from ...integrators.path import trace_wave\n"
                       "    from ... import gradient\n")
    mods = _imported_modules(planted, "tracer.guiding.pss")
    assert {"tracer.integrators.path", "tracer.gradient"} <= mods
    assert _layer_violations("guiding", ("tracer.integrators", "tracer.gradient")) == []


def test_the_engine_imports_nothing_above_it():
    """The integrators and gpt stand on tracer/engine, not the other way round: no module under it
    imports tracer.integrators or tracer.gradient, nor of the guides more than the contract their
    kernels read (tracer.guiding.contract) and the records they write for a guide that learns
    (tracer.guiding.records)."""
    bad = _layer_violations("engine", ("tracer.integrators", "tracer.gradient", "tracer.guiding"))
    seams = ("tracer.guiding.contract", "tracer.guiding.records")
    assert [b for b in bad if not b[1].startswith(seams)] == []


def test_the_renderer_imports_nothing_of_learn_bench_or_tests():
    """tracer never imports learn, bench or tests (DESIGN.md's layout): the installed package runs
    without them."""
    assert _layer_violations(".", ("learn", "bench", "tests")) == []


def _jitted_functions(path):
    """(name, parameter count, decorator) of each function of a source file decorated with the
    tracer's `kernel` or `jit`."""
    import ast

    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.FunctionDef):
            for dec in node.decorator_list:
                name = ast.unparse(dec.func if isinstance(dec, ast.Call) else dec)
                if name in ("kernel", "jit"):
                    found.append((node.name, len(node.args.args) + len(node.args.kwonlyargs), name))
    return found


def _source_files():
    import pathlib

    return sorted(pathlib.Path(tracer.__file__).parent.rglob("*.py"))


def test_no_kernel_takes_more_than_16_parameters(tmp_path):
    """Kernels take their state as the bundles declared once (wave.PathState, Continuation,
    ShadowRays, ShadowQueue; records.Records; splitting.SplitPlan; gradient.offsets.BaseBounce,
    Offsets, NeeTerms; photons.PhotonState, Deposits), not as their arrays one by one: no
    parallel kernel takes more than 16 parameters. Detects a kernel that grows a long signature
    again; the scan is checked on a planted file first."""
    planted = tmp_path / "k.py"
    planted.write_text("@kernel\ndef big(" + ", ".join(f"a{i}" for i in range(17)) + "):\n    pass\n"
                       "@jit(inline='always')\ndef small(a):\n    pass\n")
    assert _jitted_functions(planted) == [("big", 17, "kernel"), ("small", 1, "jit")]
    kernels = [(str(path), name, n) for path in _source_files() for name, n, dec in _jitted_functions(path)
               if dec == "kernel"]
    assert len(kernels) > 20
    assert [k for k in kernels if k[2] > 16] == []


_BUNDLES = {"state": "PathState", "cont": "Continuation", "shr": "ShadowRays", "queue": "ShadowQueue",
            "rec": "Records", "plan": "SplitPlan", "bb": "BaseBounce", "off": "Offsets", "nt": "NeeTerms",
            "photons": "PhotonState", "dep": "Deposits"}
# Local names that differ from "prefix + field": (bundle, field) -> name
_RENAMED = {("shr", "has"): "has_shadow", ("plan", "hi"): "split_hi", ("plan", "low"): "split_low"}
_PREFIX = {"shr": "sh_", "bb": "b_", "off": "o_", "nt": "n_", "rec": "r_", "dep": "dep_", "queue": "sp_"}


def _bundle_bindings(path):
    """(line, target, bundle, field, one target) of each assignment in a source file whose value
    reads a field of a bundle parameter (`depth = state.depth`), or several (`a, b = st.a, st.b`)."""
    import ast

    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(node, ast.Assign) or len(node.targets) != 1:
            continue
        target, value = node.targets[0], node.value
        pairs = [(target, value)]
        if isinstance(target, ast.Tuple) and isinstance(value, ast.Tuple):
            pairs = list(zip(target.elts, value.elts))
        for t, v in pairs:
            if (isinstance(t, ast.Name) and isinstance(v, ast.Attribute) and isinstance(v.value, ast.Name)
                    and v.value.id in _BUNDLES):
                out.append((node.lineno, t.id, v.value.id, v.attr, len(pairs) == 1))
    return out


def test_kernels_bind_bundle_fields_by_name_one_per_line(tmp_path):
    """A kernel binds each field of a bundle it takes to the local of its own name before its
    parallel loop (`depth = state.depth`, `o_beta = off.beta`; prefixes sh_, b_, o_, n_, r_, dep_,
    sp_), one per statement. Detects two fields swapped in a binding (which would compile and
    run), and a tuple assignment of several fields, whose arrays lose the loop's writes (next
    test). The scan is checked on a planted file first."""
    planted = tmp_path / "k.py"
    planted.write_text("def f(state, off):\n    depth = state.prev_pdf\n    a, b = off.x, off.beta\n")
    found = _bundle_bindings(planted)
    assert [(t, b, f, one) for _, t, b, f, one in found] == [
        ("depth", "state", "prev_pdf", True), ("a", "off", "x", False), ("b", "off", "beta", False)]
    bad, seen = [], 0
    for path in _source_files():
        for line, target, bundle, field, one in _bundle_bindings(path):
            seen += 1
            names = {field, _PREFIX.get(bundle, "") + field, _RENAMED.get((bundle, field))}
            if target not in names or not one:
                bad.append((path.name, line, target, f"{bundle}.{field}"))
    assert seen > 100
    assert bad == []


def test_numba_keeps_a_parallel_loops_writes_only_into_fields_bound_one_per_line():
    """Why every kernel binds its bundles' fields one per line before its loop: on the pinned
    Numba, a parallel loop loses its writes into arrays unpacked from a NamedTuple argument in one
    tuple assignment (`beta, alive = pair`), and into fields written through the tuple inside the
    loop (`pair.alive[k] = True`), while the fields bound one per statement (`alive = pair.alive`)
    keep them all, as do arrays passed one by one and a helper Numba calls (not `inline="always"`)
    that unpacks the tuple itself. Detects a Numba release that loses the writes of
    the one-per-line binding (the kernels would need their arrays one by one again); if only the
    last assertions fail, a release fixed the other two forms."""
    from typing import NamedTuple

    from numba import njit, prange

    class Pair(NamedTuple):
        beta: np.ndarray
        alive: np.ndarray

    @njit(parallel=True, cache=False)
    def one_per_line(active, pair):
        beta = pair.beta
        alive = pair.alive
        for k in prange(active.shape[0]):
            beta[active[k], 0] = 2.0
            alive[k] = True

    @njit(parallel=True, cache=False)
    def one_by_one(active, beta, alive):
        for k in prange(active.shape[0]):
            beta[active[k], 0] = 2.0
            alive[k] = True

    @njit(parallel=True, cache=False)
    def unpacked(active, pair):
        beta, alive = pair
        for k in prange(active.shape[0]):
            beta[active[k], 0] = 2.0
            alive[k] = True

    @njit(parallel=True, cache=False)
    def through_the_tuple(active, pair):
        for k in prange(active.shape[0]):
            pair.beta[active[k], 0] = 2.0
            pair.alive[k] = True

    @njit(cache=False)
    def put(pair, i, k):
        beta, alive = pair
        beta[i, 0] = 2.0
        alive[k] = True

    @njit(parallel=True, cache=False)
    def called_helper(active, pair):
        for k in prange(active.shape[0]):
            put(pair, active[k], k)

    active = np.arange(0, 1000, 2)
    a, b, c, d, e = (Pair(np.zeros((1000, 3)), np.zeros(1000, np.bool_)) for _ in range(5))
    one_per_line(active, a)
    one_by_one(active, *b)
    unpacked(active, c)
    through_the_tuple(active, d)
    called_helper(active, e)  # a helper Numba calls rather than inlines may unpack (gradient.films._add)
    for kept in (a, b, e):
        assert kept.alive.sum() == 500 and kept.beta[:, 0].sum() == 1000.0
    assert c.alive.sum() < 500 and d.alive.sum() < 500, "Numba kept these writes: see the docstring"
