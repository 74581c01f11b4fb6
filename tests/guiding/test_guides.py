"""Guided renders stay unbiased, and guides fall back to BSDF sampling where they have nothing.

Unbiasedness: the image mean (per channel) of a guided render equals the `bsdf` render's mean
within a two-sided z-test whose variance is the sum of both means' variances (each estimated from
the per-pixel variances of the mean; pixels are independent). Sidak-corrected over every
scene x guide x channel. `ajar-textured` is ajar with a checkerboard on its diffuse walls and
tilted shading normals (tests/scenes.textured): the material step, the light-leak mask and the
photons' adjoint factor all act there.
"""
import os

import numpy as np
import pytest

import tracer
from tests import scenes
from tracer.testing.stats import assert_clean, assert_z, image_mean
from tracer.errors import SettingsError
from tracer.guiding import REGISTRY, FrozenGuide, guide_names, make_guide
from tracer.integrators.path import trace_wave
from tracer.sources import CameraSource
from tracer.splitting import WeightWindow, throughput_plan
from tracer.wave import Stats, WaveBuffers

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
GUIDES = [g for g in guide_names() if hasattr(REGISTRY[g][0], "fixed_state")]  # the directional guides
# every guide at its defaults (mixing weights of least second moment), and the paper's eq. 14
# weights (which change how often each strategy is drawn, so they must leave the mean alone too)
# and paths split where they become overweight (split 1.5: often, so that the test sees it), and a
# narrow weight window (which splits and roulettes often), and maps reconstructed by the network;
# switch_off 0 so that the final passes are guided whatever the small scenes predict, and one
# variant where the guide always switches itself off after training (guiding.mixing); ppg with
# the 2019 filters, with its old roulette, records, image and empty leaves, and with a narrow
# weight window; grid with the late roulette, photon with unbiased records (guiding.base); photon
# with its maps replaced by reference maps before the final passes
VARIANTS = [(g, {"switch_off": 0}) for g in GUIDES] + [("photon", {"mixing": "eq14"}),
                                                       ("photon", {"light_guiding": 0.5, "switch_off": 0}),
                                                       ("photon", {"split": 1.5, "window": 0.0, "switch_off": 0}),
                                                       ("photon", {"window": 1.0, "window_low": 0.5, "window_spp": 0,
                                                                   "switch_off": 0}),
                                                       ("photon", {"reconstruct": "cnn", "switch_off": 0}),
                                                       ("photon", {"switch_off": 1e-9}),
                                                       ("photon", {"reference_photons": 16.0, "switch_off": 0}),
                                                       ("ppg", {"spatial_filter": "stochastic",
                                                                "directional_filter": "box", "switch_off": 0}),
                                                       ("ppg", {"roulette": "path", "records": "survivors",
                                                                "image": "all", "empty": "bsdf", "switch_off": 0}),
                                                       ("ppg", {"roulette": "reference", "window": 1.0, "window_low": 0.5,
                                                                "window_spp": 0, "switch_off": 0}),
                                                       ("grid", {"roulette": "late", "switch_off": 0}),
                                                       ("photon", {"records": "unbiased", "switch_off": 0})]
WINDOW_NOW = {"window_spp": 0}  # the window from the first final pass, whatever the training passes hold
CASES = [("cornell", 32, 32, 96), ("ajar", 48, 36, 96), ("ajar-textured", 48, 36, 96)]
N_TESTS = len(CASES) * len(VARIANTS) * 3


def _scene(name, w, h):
    return scenes.builtin(ROOT, name, w, h)


@pytest.fixture(scope="module")
def bsdf_renders():
    out = {name: tracer.render(_scene(name, w, h), spp=spp, seed=101) for name, w, h, spp in CASES}
    for name, r in out.items():
        assert_clean(r, f"bsdf on {name}")
    return out


@pytest.mark.parametrize("variant", VARIANTS, ids=[g + "".join(f"-{k}={v}" for k, v in o.items()) for g, o in VARIANTS])
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_guided_mean_equals_bsdf_mean(case, variant, bsdf_renders):
    name, w, h, spp = case
    guide, opts = variant
    g = make_guide(guide, **opts)
    r = tracer.render(_scene(name, w, h), spp=spp, guide=g, seed=202)
    assert_clean(r, f"{guide} {opts} on {name}")
    assert r.stats["spp"] == spp and r.stats["guide"] == guide
    st = g.stats()
    assert st["voxels_with_map"] > 0, "the guide never built a map: this test would not test guiding"
    kinds = [p["kind"] for p in r.stats["passes"]]
    assert kinds[0] == "pilot" and "train" in kinds and kinds[-1] == "final"
    if opts.get("split") or opts.get("window"):
        assert r.stats["split_copies"] > 0, "no path was split: this test would not test splitting"
    if opts.get("window"):
        assert r.stats["window_ended"] > 0, "the window ended no path: this test would not test its roulette"
    assert st["switched_off"] == (opts.get("switch_off") == 1e-9), st.get("predicted_ratios")
    if opts.get("reference_photons"):
        assert st["reference_photons"] == round(opts["reference_photons"] * w * h), st
    if st["switched_off"]:  # final passes of BSDF sampling alone: no splitting, no window
        assert r.stats["split_copies"] == 0 and r.stats["window_ended"] == 0
    m_g, v_g = image_mean(r)
    m_b, v_b = image_mean(bsdf_renders[name])
    assert_z(m_g, v_g + v_b, m_b, n_tests=N_TESTS, what=f"{guide} on {name} vs bsdf")


@pytest.mark.parametrize("guide", ["grid", "photon", "ppg"])
def test_nee_off_guides_with_the_reference_roulette_keep_the_mean(guide):
    """With NEE off, `roulette` auto plays the reference's roulette (drawn after the ray, survival
    0.99 once there are maps): the guided Cornell box's mean equals the NEE-off path tracer's
    within a two-sided z-test (Sidak over guides x channels). Detects a roulette, a late draw or a
    record that lost its 1 / q, or a bias of the window's roulette (ppg's window on here)."""
    name, w, h, spp = CASES[0]
    opts = {"switch_off": 0, "roulette": "auto",
            **({"window": 1.0, "window_low": 0.5, "window_spp": 0} if guide == "ppg" else {})}
    g = make_guide(guide, **opts)
    r = tracer.render(_scene(name, w, h), spp=spp, guide=g, integrator="path:nee=0", seed=303)
    b = tracer.render(_scene(name, w, h), spp=4 * spp, integrator="path:nee=0", seed=304)
    assert_clean(r)
    assert_clean(b)
    st = g.stats()
    assert st["roulette"] == "reference" and st["voxels_with_map"] > 0, st
    m_g, v_g = image_mean(r)
    m_b, v_b = image_mean(b)
    assert_z(m_g, v_g + v_b, m_b, n_tests=9, what=f"{guide} NEE off vs path NEE off")


def _mirror_world(folder):
    """Only delta BSDFs: a mirror floor under a mirror-backed emitter (illum 3 with Ke)."""
    floor = np.array([[-3, 0, -3], [3, 0, -3], [3, 0, 3], [-3, 0, 3]], float)
    lamp = np.array([[-1, 2, -1], [-1, 2, 1], [1, 2, 1], [1, 2, -1]], float)  # faces -y (down)
    quad = np.array([[0, 2, 1], [0, 3, 2]])
    return scenes.write_scene(
        folder, "mirrors", [("floor", floor, quad), ("lamp", lamp, quad)],
        {"floor": "illum 3\nKs 0.8 0.8 0.8", "lamp": "illum 3\nKs 0 0 0\nKe 4 4 4"},
        {"camera": {"origin": [0, 1, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 50},
         "film": {"width": 24, "height": 24}, "render": {"spp": 8, "max_depth": -1}})


@pytest.mark.parametrize("guide", GUIDES)
def test_only_delta_bsdfs(tmp_path, guide):
    scene = tracer.load_scene(_mirror_world(tmp_path))
    g = make_guide(guide)
    r = tracer.render(scene, spp=32, guide=g, seed=3)
    b = tracer.render(scene, spp=32, seed=3)
    assert_clean(r)
    assert_clean(b)
    assert g.grid is None  # no vertex to guide: no grid, no maps, no photons
    assert r.image.max() > 0
    # The same paths as plain BSDF sampling; only the passes are weighted differently
    flat = (r.variance.max(axis=2) == 0) & (b.variance.max(axis=2) == 0)
    np.testing.assert_allclose(r.image[flat], b.image[flat], rtol=1e-6)
    m_g, v_g = image_mean(r)
    m_b, v_b = image_mean(b)
    assert_z(m_g, v_g + v_b, m_b, n_tests=3 * len(GUIDES), what=f"{guide} on mirrors vs bsdf")


def test_photon_guide_without_photons_falls_back(tmp_path):
    scene = _scene("cornell", 24, 24)
    g = make_guide("photon", photons_per_pixel=0.0)
    r = tracer.render(scene, spp=64, guide=g, seed=8)
    b = tracer.render(scene, spp=64, seed=9)
    assert_clean(r)
    assert_clean(b)
    st = g.stats()
    assert st["valid_voxels"] > 0 and st["voxels_with_map"] == 0 and st["photons"] == 0
    m_g, v_g = image_mean(r)
    m_b, v_b = image_mean(b)
    assert_z(m_g, v_g + v_b, m_b, n_tests=3, what="photon guide without photons vs bsdf")


@pytest.mark.parametrize("guide", GUIDES)
def test_camera_that_sees_no_surface(tmp_path, guide):
    # The camera looks away from the only object, into a constant sky: no vertex, no grid, and
    # every sample reads the sky exactly.
    v, f = scenes.icosphere(1)
    obj = scenes.write_scene(
        tmp_path, "away", [("ball", v, f)], {"ball": "Kd 0.5 0.5 0.5"},
        {"camera": {"origin": [0, 0, 4], "target": [0, 0, 8], "up": [0, 1, 0], "fov": 30},
         "film": {"width": 12, "height": 12}, "environment": {"radiance": [0.7, 0.7, 0.7]},
         "render": {"spp": 8, "max_depth": -1}})
    g = make_guide(guide)
    r = tracer.render(tracer.load_scene(obj), spp=8, guide=g, seed=1)
    assert_clean(r)
    assert g.grid is None
    np.testing.assert_allclose(r.image, 0.7, rtol=1e-6)


# the loops that record: the wavefront's shade, the lanes' listed kernel (the closed box is diffuse),
# the lanes' general kernel (every triangle's class made general)
RECORDING_LOOPS = ("wave", "lanes", "lanes-general")


def _recorded(ctx, loop, n, **kw):
    """The Records of one wave of n camera paths traced on `loop` (RECORDING_LOOPS), checking that
    the lanes' kernel named traced them where asked."""
    from tracer.engine import lanes
    from tracer.film import Film

    ctx.path_loop = loop.split("-")[0]
    if loop == "lanes-general":
        lanes._lane_scene(ctx).tl[:, lanes.TL_FAST] = lanes.GENERAL
    got, stats = [], Stats()
    trace_wave(ctx, WaveBuffers(n), CameraSource(), Film(16, 16), 0, 0, n, stats, observe=got.append, **kw)
    on_lanes = loop != "wave"
    assert stats.lane_samples == (n if on_lanes else 0)
    assert (stats.lane_listed > 0) == (loop == "lanes") and (stats.lane_general > 0) == (loop == "lanes-general")
    return got[0]


@pytest.mark.parametrize("loop", RECORDING_LOOPS)
def test_records_carry_the_incident_radiance(tmp_path, loop):
    # In a closed box whose walls all emit Le and reflect a, the radiance arriving along any
    # direction is Le / (1 - a). The first vertex's record of every path must estimate exactly
    # that (its own NEE excluded: with it the mean would be larger), on either loop that records.
    a, le = 0.5, 1.0
    scene = tracer.load_scene(scenes.closed_box(tmp_path, a, le, width=16, height=16))
    from tracer.context import RenderContext
    from tracer.bvh import make_accel
    from tracer.lights import build_lights

    ctx = RenderContext(scene, make_accel("embree", scene.tri), build_lights(scene), 5, -1, 3, "box", (0, 0, 16, 16))
    n = 16 * 16 * 64
    # direct=True: the full incident radiance; direct=False: less the emission hit directly
    for direct, expected in ((True, le / (1 - a)), (False, le * a / (1 - a))):
        rec = _recorded(ctx, loop, n, direct=direct)
        first = rec.radiance[:n][rec.strategy[:n] >= 0].astype(np.float64)
        assert first.size > 0.9 * n
        assert (rec.strategy[:n] <= 0).all()  # no guide: BSDF only
        assert_z(first.mean(), first.var(ddof=1) / first.size, expected, n_tests=2,
                 what=f"recorded radiance (direct={direct})")


@pytest.mark.parametrize("loop", RECORDING_LOOPS)
@pytest.mark.parametrize("roulette,records", [("path", "survivors"), ("path", "unbiased"), ("late", "survivors"),
                                              ("reference", "survivors")])
def test_records_past_the_roulette(tmp_path, roulette, records, loop):
    """In the closed box of test_records_carry_the_incident_radiance every record, at any depth,
    estimates Le / (1 - a), unless the roulette starves it: with `records` survivors and the
    roulette drawn before the ray (roulette path), a record whose path is killed reads 0 and a
    survivor X, so records past rr_depth estimate q L_i and their mean is low. The test checks
    the three kinds that must be unbiased by a two-sided z-test of all records' mean (Sidak over 3),
    and that the starved kind is detected below it (one-sided, z < -3), so that it can fail: a
    roulette or record that lost the 1 / q, or the late roulette's emission, would show here."""
    from tracer.bvh import make_accel
    from tracer.context import RenderContext
    from tracer.guiding.base import Guide
    from tracer.guiding.contract import empty_state
    from tracer.lights import build_lights

    a, le = 0.5, 1.0
    scene = tracer.load_scene(scenes.closed_box(tmp_path, a, le, width=16, height=16))
    ctx = RenderContext(scene, make_accel("embree", scene.tri), build_lights(scene), 5, -1, 3, "box", (0, 0, 16, 16))
    g = Guide()
    g.roulette_settings({"roulette": roulette, "records": records})
    ctx.guide_state = g.with_roulette(empty_state(), False)
    n = 16 * 16 * 64
    rec = _recorded(ctx, loop, n)
    x = rec.radiance[rec.strategy >= 0].astype(np.float64)
    assert x.size > 2 * n  # paths past rr_depth are recorded
    expected = le / (1 - a)
    if (roulette, records) == ("path", "survivors"):
        z = (x.mean() - expected) / np.sqrt(x.var(ddof=1) / x.size)
        assert z < -3.0, f"records past the roulette should read q L_i on average, z = {z:.2f}"
    else:
        assert_z(x.mean(), x.var(ddof=1) / x.size, expected, n_tests=3, what=f"records ({roulette}, {records})")


def test_frozen_guide_renders_final_passes_only_and_stays_unbiased(bsdf_renders):
    name, w, h, spp = CASES[0]
    g = make_guide("photon")
    tracer.render(_scene(name, w, h), spp=32, guide=g, seed=303)
    frozen = FrozenGuide(g)
    r = tracer.render(_scene(name, w, h), spp=spp, guide=frozen, seed=202)
    assert_clean(r)
    assert {p["kind"] for p in r.stats["passes"]} == {"final"} and r.stats["spp"] == spp
    assert r.stats["guide_stats"]["frozen"] and r.stats["guide_time_learning"] == 0.0
    assert frozen.state() is g.state()  # the maps it samples are the trained ones
    m_g, v_g = image_mean(r)
    m_b, v_b = image_mean(bsdf_renders[name])
    assert_z(m_g, v_g + v_b, m_b, n_tests=3, what="frozen photon on cornell vs bsdf")
    with pytest.raises(SettingsError, match="has learned"):
        FrozenGuide(make_guide("photon"))


def test_frozen_photon_guide_on_ajar_is_unbiased_where_it_acts():
    """Final passes only (the guide trained at 32 spp, then frozen), at its defaults (splitting and
    the weight window on: both act, checked), on `ajar` at full resolution, where the guide carries
    nearly all of the image (direct light is 2.3% of it): the image mean must equal the stored
    reference's (scenes/ajar/reference.exr, 76138 spp; z-test per channel on both variances, Sidak
    over the channels). What it detects: the image mean's relative standard error is 0.42% at 16
    spp, so a 2% bias in the indirect light (1.95% of the image) gives |z| of about 4.6 against the
    threshold 2.94 (found with probability 0.97); scaling the render by 0.98 gave z of -3.6 to -6.3
    in two seeds, and 20 unscaled renders (2 trainings x 10 seeds) gave mean z -0.15, sd 0.88."""
    from bench.reference import load

    ref, ref_var, _ = load(os.path.join(ROOT, "scenes", "ajar"))
    scene = _scene("ajar", ref.shape[1], ref.shape[0])
    g = make_guide("photon", window_spp=0)
    tracer.render(scene, spp=32, guide=g, seed=303)
    r = tracer.render(scene, spp=16, guide=FrozenGuide(g), seed=202)
    assert_clean(r, "frozen photon on ajar")
    assert {p["kind"] for p in r.stats["passes"]} == {"final"}
    assert r.stats["split_copies"] > 0 and r.stats["window_ended"] > 0, "splitting or the window did not act"
    m, v = image_mean(r)
    n = ref.shape[0] * ref.shape[1]
    assert_z(m, v + ref_var.reshape(-1, 3).sum(axis=0) / n**2, ref.reshape(-1, 3).mean(axis=0), n_tests=3,
             what="frozen photon guide on ajar vs reference")


def test_photon_render_is_bit_identical_across_threads_and_wave_size_only_limits_copies():
    """A render with the default photon guide (training, photons, splitting, weight window) gives
    the same bits on 1 and 2 threads. Across wave sizes it is the same only when nothing splits
    (split 0, window 0): a path splits only into free room of its wave's buffer (twice the wave
    size), so a small wave makes fewer copies; each choice is unbiased (the z-tests above)."""
    import numba

    scene = _scene("ajar", 48, 36)
    n0 = numba.get_num_threads()
    try:
        one = tracer.render(scene, spp=24, guide="photon", guide_settings=WINDOW_NOW, seed=3, threads=1)
        two = tracer.render(scene, spp=24, guide="photon", guide_settings=WINDOW_NOW, seed=3, threads=2)
    finally:
        numba.set_num_threads(n0)
    assert_clean(one)
    assert one.stats["split_copies"] > 0 and one.stats["window_ended"] > 0
    np.testing.assert_array_equal(one.image, two.image)
    np.testing.assert_array_equal(one.variance, two.variance)
    small = tracer.render(scene, spp=24, guide="photon", guide_settings=WINDOW_NOW, seed=3, wave_size=997)
    assert 0 < small.stats["split_copies"] < one.stats["split_copies"]
    plain = {"split": 0, "window": 0}
    a, b = (tracer.render(scene, spp=24, guide="photon", guide_settings=plain, seed=3, wave_size=w)
            for w in (1 << 16, 997))
    np.testing.assert_array_equal(a.image, b.image)


def _guided_below_surface(scene, **settings):
    """Fraction of the last training iteration's guided directions that left below the surface
    (|f cos| = 0 at a diffuse vertex), for a photon guide with these settings."""
    g = make_guide("photon", iterations=3, **settings)
    seen = [0, 0]
    observe = g.observe

    def watch(rec):
        if g.iteration == g.iterations:
            guided = np.asarray(rec.strategy) == 1
            seen[0] += int(guided.sum())
            seen[1] += int((guided & (np.asarray(rec.fcos) <= 0.0)).sum())
        observe(rec)

    g.observe = watch
    tracer.render(scene, spp=32, guide=g, seed=4)
    assert seen[0] > 1000
    return seen[1] / seen[0]


def test_maps_per_side_keep_guided_directions_above_the_surface():
    # In the Ajar room every voxel on the door wall holds both of its sides, and every corner
    # voxel a floor and a wall: one map per voxel sends a good share of guided directions behind
    # the surface. One map per side (photons and camera vertices keyed by the side they arrive
    # on) must cut that share several times; were the photons' side the opposite of the camera
    # paths', nearly every guided direction would go below the surface instead.
    scene = _scene("ajar", 64, 48)
    one = _guided_below_surface(scene, normal_classes=1)
    six = _guided_below_surface(scene)
    assert six < 0.05 and six < one / 3, (one, six)


@pytest.mark.parametrize("loop", RECORDING_LOOPS)
def test_records_link_each_vertex_to_the_one_before(tmp_path, loop):
    # Record r's prev is the record of the same path's previous vertex: the direction sampled
    # there points at r's position. First hits have none.
    scene = tracer.load_scene(scenes.closed_box(tmp_path, 0.5, 1.0, width=16, height=16))
    from tracer.bvh import make_accel
    from tracer.lights import build_lights
    from tracer.context import RenderContext

    ctx = RenderContext(scene, make_accel("embree", scene.tri), build_lights(scene), 5, -1, 3, "box", (0, 0, 16, 16))
    n = 16 * 16 * 8
    rec = _recorded(ctx, loop, n)
    r = np.flatnonzero(rec.strategy >= 0)
    p = rec.prev[r]
    first = p < 0
    assert first.sum() == n  # one first hit per path (no delta vertex in the box)
    assert (~first).sum() > n  # and deeper vertices, linked
    r, p = r[~first], p[~first]
    assert (rec.strategy[p] >= 0).all() and (rec.path[p] == rec.path[r]).all() and (p < r).all()
    d = rec.x[r].astype(np.float64) - rec.x[p].astype(np.float64)
    ln = np.linalg.norm(d, axis=1)
    # positions are float32 and rays start off the surface: judge segments that are not tiny
    far = ln > 0.05 * np.median(ln)
    assert far.mean() > 0.9
    np.testing.assert_allclose(d[far] / ln[far, None], rec.wi[p[far]], atol=1e-3)


def test_guided_light_tracing_keeps_the_expected_photon_power_per_voxel():
    # With light_guiding, a photon samples its voxel's importance map or its BSDF and carries
    # f |cos| / (mixture pdf): each voxel's expected deposited power must be what unguided light
    # tracing deposits. Same grid for both; batches of photons give the variances of the means.
    from tracer.guiding.grid.photons import trace_photons

    g = make_guide("photon", light_guiding=0.5)
    tracer.render(_scene("cornell", 32, 32), spp=16, guide=g, seed=5)
    G = g.grid
    assert G.imap_ok[: G.n_nodes].sum() > 10, "no importance maps: nothing would be guided"
    n_nodes = G.n_nodes
    batches, per_batch = 24, 40_000

    def run(guided):
        power = np.zeros((batches, n_nodes))
        count = np.zeros(n_nodes)
        imp = G.state(importance=True) if guided else None
        for b in range(batches):
            def sink(node, bins, val, x, nrm, b=b):
                np.add.at(power[b], node, val)
                np.add.at(count, node, 1.0)
            trace_photons(g.ctx, G.lookup_state(), G.data_slot[:n_nodes], per_batch, 100 + b, sink,
                          first_hit=False, imp=imp, p_imp=0.5)
        return power, count

    pu, cu = run(False)
    pg, cg = run(True)
    # guiding must change where the photons go (else this test tests nothing) ...
    top = np.argsort(-(cu + cg))[:40]
    assert np.abs(cg[top] - cu[top]).max() > 0.2 * cu[top].max()
    # ... but not the expected power of any voxel
    mu, mg = pu[:, top].mean(0), pg[:, top].mean(0)
    var = pu[:, top].var(0, ddof=1) / batches + pg[:, top].var(0, ddof=1) / batches
    assert_z(mg, var, mu, n_tests=top.size, what="guided vs unguided photon power per voxel")


def test_splitting_keeps_one_sample_per_path_and_is_off_while_recording():
    """Copies add into their path's sample: the film counts spp samples per pixel, the stats count
    the copies; without `split`, or in a wave whose vertices a guide records, nothing splits."""
    from tracer.film import Film

    name, w, h, _ = CASES[1]
    scene = _scene(name, w, h)
    g = make_guide("photon", iterations=3, window_spp=0)
    tracer.render(scene, spp=16, guide=g, seed=5)
    frozen = FrozenGuide(g)
    frozen.splitting = WeightWindow(0.0, 0.0, 0.0)
    off = tracer.render(scene, spp=8, guide=frozen, seed=6)
    frozen.splitting = WeightWindow(1.0, 0.0, 0.0)
    on = tracer.render(scene, spp=8, guide=frozen, seed=6)
    frozen.splitting = WeightWindow(0.0, 1.0, 0.5)
    frozen.splitting.pixel_est = g.splitting.pixel_est
    win = tracer.render(scene, spp=8, guide=frozen, seed=6)
    frozen.splitting.pixel_est = np.zeros_like(g.splitting.pixel_est)  # no pixel known: no window
    unknown = tracer.render(scene, spp=8, guide=frozen, seed=6)
    assert off.stats["split_copies"] == 0 and on.stats["split_copies"] > 0
    assert off.stats["window_ended"] == 0 and on.stats["window_ended"] == 0
    assert win.stats["split_copies"] > 0 and win.stats["window_ended"] > 0
    assert unknown.stats["split_copies"] == 0 and unknown.stats["window_ended"] == 0
    for r in (off, on, win, unknown):
        assert_clean(r)
        assert (r.film.count == 8).all()
    assert on.stats["camera_and_bounce_rays"] > off.stats["camera_and_bounce_rays"]
    ctx = g.ctx
    ctx.guide_state = g.state()
    n = w * h * 8
    for observe, copies in ((None, True), (lambda rec: None, False)):
        st = Stats()
        trace_wave(ctx, WaveBuffers(n, split=True), CameraSource(), Film(w, h), 0, 0, n, st, observe=observe,
                   split=throughput_plan(1.0))
        assert (st.split_copies > 0) == copies


def test_pixel_estimate_leaves_out_noisy_pixels():
    """splitting.pixel_estimate against the same figures written out pixel by pixel here: the 3x3
    box mean (edges clamped) of a film's luminance, floored at 1% of the image's mean, and 0 where
    the box mean's standard error (its pixels' variances of the mean over 81, square-rooted) is
    above PIXEL_REL_ERR of it. The film has grey samples: constant ones in most pixels, a firefly
    in one (its box neighbours are then too noisy to trust) and nothing in two dark rows (known:
    no variance, the floor). Detects a box of another size, a missing floor, the error test
    reversed or scaled, an error taken per pixel instead of per box."""
    import math

    from tracer.film import Film
    from tracer.splitting import PIXEL_REL_ERR, pixel_estimate

    w, h, n = 7, 6, 4
    value = np.ones((h, w))
    value[:, 3] = 2.0
    value[4:] = 0.0
    samples = np.repeat(value[..., None], n, axis=2)  # (h, w, n)
    samples[2, 1] = [0.0, 0.0, 0.0, 60.0]  # a firefly
    film = Film(w, h)
    for k in range(n):
        rad = np.repeat(samples[..., k].reshape(-1, 1), 3, axis=1)
        film.add(np.arange(w * h), rad, np.zeros((w * h, film.aov.shape[1]), np.float32))
    got = pixel_estimate([film], w, h).reshape(h, w)
    mean = samples.mean(axis=2)
    var_mean = samples.var(axis=2, ddof=1) / n
    floor = 0.01 * mean.mean()
    known = 0
    for y in range(h):
        for x in range(w):
            nb = [(min(max(y + dy, 0), h - 1), min(max(x + dx, 0), w - 1)) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
            est = max(sum(mean[p] for p in nb) / 9.0, floor)
            err = math.sqrt(sum(var_mean[p] for p in nb)) / 9.0
            want = est if err <= PIXEL_REL_ERR * est else 0.0
            assert got[y, x] == pytest.approx(want, rel=1e-6), (y, x)
            known += want > 0.0
    assert 0 < known < w * h  # both kinds of pixel are there
    assert got[1:4, 0:3].max() == 0.0 and got[5, 5] == pytest.approx(floor)


def test_window_waits_for_window_spp_samples_a_pixel():
    """WeightWindow.plan plays the window only once the training films hold window_spp samples a
    pixel (their counts summed over films, over the pixels): none at 4 of 8 (held_back, no pixel
    estimate, the throughput plan of `split` or nothing), a window at 4 + 4; a frozen copy (no
    films) keeps what the last plan decided; window_spp 0 plays it from one sample. Detects a rule
    reversed, counted per film instead of over the films, or a held-back estimate that a frozen
    copy still plays."""
    from tracer.film import Film

    w, h = 6, 5
    crop = (0, 0, w, h)
    outgoing = np.ones(4)

    def film(spp):
        f = Film(w, h)
        for _ in range(spp):
            f.add(np.arange(w * h), np.ones((w * h, 3)), np.zeros((w * h, f.aov.shape[1]), np.float32))
        return f

    for split in (0.0, 2.0):
        ww = WeightWindow(split, 1.0, 0.5, 8)
        plan = ww.plan(outgoing, [film(4)], crop)
        assert ww.held_back and ww.pixel_est is None
        assert (plan is None) if split == 0.0 else (plan.hi == 0.0 and plan.threshold == split)
        assert ww.plan(outgoing, [], crop) == plan  # a frozen copy: still no window
        plan = ww.plan(outgoing, [film(4), film(4)], crop)
        assert not ww.held_back and plan.hi == 1.0 and plan.pixel_est.shape == (w * h,)
        frozen = ww.plan(outgoing, [], crop)  # a frozen copy: the window, on the kept estimate
        assert frozen.hi == 1.0 and frozen.pixel_est is plan.pixel_est
    ww = WeightWindow(0.0, 1.0, 0.5, 0)
    assert ww.plan(outgoing, [film(1)], crop).hi == 1.0 and not ww.held_back


def test_photon_holds_its_window_back_in_a_short_training():
    """A photon render whose training passes hold fewer than window_spp samples a pixel plays no
    window (stats window_held_back, no path ended by it) and the same render with window_spp 0
    does. Detects the setting not reaching the guide, or a held-back window still played."""
    name, w, h, _ = CASES[1]
    scene = _scene(name, w, h)
    g = make_guide("photon", iterations=3)
    r = tracer.render(scene, spp=16, guide=g, seed=5)
    held = sum(p["spp"] for p in r.stats["passes"] if p["kind"] != "final")
    assert 0 < held < g.splitting.window_spp, "the training held enough samples: this test would test nothing"
    assert g.stats()["window_held_back"] and r.stats["window_ended"] == 0
    g0 = make_guide("photon", iterations=3, window_spp=0)
    r0 = tracer.render(scene, spp=16, guide=g0, seed=5)
    assert not g0.stats()["window_held_back"] and r0.stats["window_ended"] > 0


@pytest.mark.parametrize("bad", [0.5, -1.0, "2"])
def test_split_setting_is_checked(bad):
    with pytest.raises(SettingsError, match="split"):
        make_guide("photon", split=bad)


@pytest.mark.parametrize("bad", [{"window": -1.0}, {"window": "3"}, {"window": 1.0, "window_low": 1.0},
                                 {"window_low": -0.1}, {"window_low": "0.2"}, {"window": 0.1}])
def test_window_settings_are_checked(bad):
    with pytest.raises(SettingsError, match="window"):
        make_guide("photon", **bad)


@pytest.mark.parametrize("guide, key, with_nee, without, given",
                         [("photon", "window_low", 0.05, 0.2, 0.1), ("grid", "window", 0.0, 3.0, 2.0)])
def test_window_auto_follows_next_event_estimation(guide, key, with_nee, without, given):
    """photon's default window_low "auto" is 0.05 of the pixel in a render with next-event
    estimation and 0.2 without; grid's window "auto" is off (0) with it and 3 x the pixel without
    (the values docs/guiding.md gives, written here), in the guide's window and its stats; a number
    given stays as given; grid's follow_nee settles it before a render. Detects auto resolved the
    wrong way round, not at all (an unresolved auto window reads 3, so that buffers sized before the
    render keep room for copies), or over a user's number."""
    for integrator, want in (("path", with_nee), ("path:nee=0", without)):
        for setting, expect in (({}, want), ({key: given}, given)):
            g = make_guide(guide, iterations=1, **setting)
            r = tracer.render(_scene("cornell", 16, 16), spp=4, guide=g, integrator=integrator, seed=7)
            assert getattr(g.splitting, key) == expect, (integrator, setting)
            assert r.stats["guide_stats"][key] == expect, (integrator, setting)
    if key == "window":  # settled before the render sizes its buffers: no room for copies with NEE
        for nee in (True, False):
            g = make_guide(guide)
            g.follow_nee(nee)
            assert g.splits == (not nee)


@pytest.mark.parametrize("bad", [{"reference_photons": -1.0}, {"reference_photons": "8"}, {"reference_sigma": -0.5}])
def test_reference_map_settings_are_checked(bad):
    with pytest.raises(SettingsError, match="reference"):
        make_guide("photon", **bad)


def test_outgoing_radiance_per_voxel_is_the_mean_of_what_arrivals_collected():
    """A record's vertex sent back what its path's previous record received: per leaf, outgoing()
    is the mean of those, over leaves with enough of them; halves go to both children on a split."""
    from tracer.guiding.records import Records
    from tracer.guiding.grid.spatial import HierarchicalGrid
    from tracer.splitting import OUT_MIN_SAMPLES, observe_outgoing, outgoing

    g = HierarchicalGrid(np.zeros(3), np.ones(3), 1, 4, 8, 1)
    g.visit(np.arange(g.n_cells), 0)
    rng = np.random.default_rng(3)
    n = 4 * OUT_MIN_SAMPLES
    rec = Records.allocate(2 * n)
    rec.strategy[:] = 0
    rec.node[:n] = 0  # first vertices: no previous record, so they tell nothing about their voxel
    rec.radiance[:n] = rng.exponential(size=n).astype(np.float32)
    rec.node[n:] = 0
    rec.prev[n:] = np.arange(n)
    rec.strategy[n + 1] = -1  # not a vertex
    observe_outgoing(g, rec)
    keep = np.ones(n, bool)
    keep[1] = False
    assert np.isclose(outgoing(g)[0], rec.radiance[:n][keep].mean(), rtol=1e-6)
    g2 = HierarchicalGrid(np.zeros(3), np.ones(3), 1, 4, 8, 1)
    g2.visit(np.arange(g2.n_cells), 0)
    few = rec.head(n + OUT_MIN_SAMPLES - 1)
    few.prev[n:] = np.arange(OUT_MIN_SAMPLES - 1)
    observe_outgoing(g2, few)
    assert outgoing(g2)[0] == 0.0  # too few arrivals: unknown
