"""The hybrid shift's mappings (tracer.gradient.hybrid): inverses, Jacobians, failed shifts."""
import math
import os

import numpy as np
import pytest
from scipy import stats as sstats

import tracer
from tracer import bsdfs
from tracer.gradient.shift import half_vector_shift, reconnection
from tests.gradient.zscores import ROOT, gradient_z, scene_gradient_z
from tracer.testing.stats import z_critical

# material 0: rough conductor, 1: rough dielectric (ior 1.5), 2: plastic, 3: mirror, 4: smooth glass
MAT_TYPE = np.array([bsdfs.CONDUCTOR, bsdfs.ROUGH_DIELECTRIC, bsdfs.PLASTIC, bsdfs.MIRROR, bsdfs.DIELECTRIC], np.int32)
MAT_PARAM = np.array([[0, 0, 0, 0.9, 0.8, 0.7, 0.3, 0],
                      [0, 0, 0, 0, 0, 0, 0.3, 1.5],
                      [0.5, 0.4, 0.3, 0.2, 0.2, 0.2, 0.2, 0],
                      [0, 0, 0, 0.9, 0.9, 0.9, 0, 0],
                      [0, 0, 0, 0, 0, 0, 0, 1.5]], np.float64)
NO_TABLE = bsdfs.bsdf_tables(MAT_TYPE, MAT_PARAM)  # (no coated material: zeros)


def _bp(m):
    """Material m's BSDF as the shading code takes it."""
    return bsdfs.bsdf_row(MAT_TYPE, MAT_PARAM, m)


def _unit(v):
    v = np.asarray(v, np.float64)
    return tuple(v / np.linalg.norm(v))


def _configurations(m, transmit, rng, count):
    """(wo_b, wi_b, wo_o) with wi_b sampled by material m's BSDF from wo_b (a refraction where
    `transmit`, else a reflection), wo_o on a random side for a dielectric, above for the rest."""
    out = []
    while len(out) < count:
        wo_b = _unit(rng.normal(size=3))
        if m not in (1, 4):
            wo_b = (wo_b[0], wo_b[1], abs(wo_b[2]))
        wi_b, _, pdf, _ = bsdfs.bsdf_sample(_bp(m), wo_b, *rng.random(3), True, NO_TABLE)
        if not pdf > 0 or (wo_b[2] * wi_b[2] < 0) != transmit:
            continue
        wo_o = _unit(np.asarray(wo_b) + 0.3 * rng.normal(size=3))
        if m not in (1, 4):
            wo_o = (wo_o[0], wo_o[1], abs(wo_o[2]))
        if math.copysign(1, wo_o[2]) != math.copysign(1, wo_b[2]):
            continue
        out.append((wo_b, tuple(wi_b), wo_o))
    return out


CASES = [(0, False, False), (2, False, False), (1, False, False), (1, True, False), (3, False, True),
         (4, False, True), (4, True, True)]


@pytest.mark.parametrize("m,transmit,delta", CASES)
def test_half_vector_shift_is_its_own_inverse(m, transmit, delta):
    """Shifting the offset back (its bounce as the base, the base's incoming direction as the offset's)
    returns the base's direction, and the two Jacobians multiply to 1: the mapping is a bijection, so
    the two sides' MIS weights add to one. Detects a wrong half-vector for refraction (eta on the
    wrong side), a non-inverse Jacobian, and a lobe that changes between the two."""
    rng = np.random.default_rng(m * 10 + transmit)
    tried = 0
    for wo_b, wi_b, wo_o in _configurations(m, transmit, rng, 40):
        ok, wi_o, _, pdf, jac = half_vector_shift(_bp(m), _bp(m), wo_b, wi_b, wo_o, delta, NO_TABLE)
        if not ok:  # total internal reflection of the offset: a failed shift, checked below
            continue
        tried += 1
        assert pdf > 0 and jac > 0
        assert (wo_o[2] * wi_o[2] < 0) == transmit
        ok2, back, _, _, jac2 = half_vector_shift(_bp(m), _bp(m), wo_o, wi_o, wo_b, delta, NO_TABLE)
        assert ok2
        np.testing.assert_allclose(back, wi_b, atol=1e-9)
        assert jac * jac2 == pytest.approx(1.0, rel=1e-9)
        if delta:
            assert jac == 1.0
    assert tried >= 20


def _solid_angle_ratio(f, w, eps=1e-6):
    """|d f(w) / d w| for a map f of unit vectors, by central differences along two tangents of w."""
    w = np.asarray(w)
    u = np.cross(w, [0.0, 0.0, 1.0] if abs(w[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    ends = []
    for t in (u, v):
        pair = []
        for s in (eps, -eps):
            wp = w + s * t
            wp /= np.linalg.norm(wp)
            pair.append((wp, np.asarray(f(wp))))
        ends.append(pair)
    area_in = np.linalg.norm(np.cross(ends[0][0][0] - ends[0][1][0], ends[1][0][0] - ends[1][1][0]))
    area_out = np.linalg.norm(np.cross(ends[0][0][1] - ends[0][1][1], ends[1][0][1] - ends[1][1][1]))
    return area_out / area_in


@pytest.mark.parametrize("m,transmit", [(0, False), (1, False), (1, True)])
def test_half_vector_jacobian_matches_finite_differences(m, transmit):
    """The Jacobian d wi_o / d wi_b of the half-vector copy equals the solid-angle ratio measured by
    central differences (relative 1e-4). Detects a Jacobian of reflection used for refraction (off
    by the |H|^2 ratio: tens of percent here) or one without the eta_t^2 of its side."""
    rng = np.random.default_rng(7 + m + transmit)
    for wo_b, wi_b, wo_o in _configurations(m, transmit, rng, 15):
        ok, _, _, _, jac = half_vector_shift(_bp(m), _bp(m), wo_b, wi_b, wo_o, False, NO_TABLE)
        if not ok:
            continue

        def shifted(w):
            good, wi, _, _, _ = half_vector_shift(_bp(m), _bp(m), wo_b, tuple(w), wo_o, False, NO_TABLE)
            assert good
            return wi

        assert jac == pytest.approx(_solid_angle_ratio(shifted, wi_b), rel=1e-4)


def test_reconnection_jacobian_matches_finite_differences():
    """The reconnection Jacobian |cos_y| d(x, z)^2 / (|cos_x| d(y, z)^2) equals the solid-angle ratio
    of the map (direction from x) -> (point on z's plane) -> (direction from y), by central
    differences (relative 1e-4); the same helper gives NEE's Jacobian at a light point. Detects
    swapped distances or a cosine taken at the wrong end."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, y, z = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3) + [0, 0, 3]
        nz = np.asarray(_unit(rng.normal(size=3)))
        w, dist, jac = reconnection(tuple(x), tuple(y), tuple(z), tuple(nz))
        np.testing.assert_allclose(np.asarray(y) + dist * np.asarray(w), z, atol=1e-12)

        def through_plane(wb):
            t = np.dot(z - x, nz) / np.dot(wb, nz)
            d = x + t * wb - y
            return d / np.linalg.norm(d)

        assert jac == pytest.approx(_solid_angle_ratio(through_plane, _unit(z - x)), rel=1e-4)


def test_a_delta_lobe_shifts_only_to_a_delta_lobe():
    """A mirror bounce cannot be copied onto a rough surface, nor a rough bounce onto a mirror, and
    a refraction that becomes total internal reflection at the offset fails: each is a failed
    shift (ok False), which the kernel turns into a zero offset contribution."""
    wo, wi = _unit([0.3, 0.1, 0.9]), _unit([-0.3, -0.1, 0.9])
    assert not half_vector_shift(_bp(3), _bp(0), wo, wi, wo, True, NO_TABLE)[0]
    assert not half_vector_shift(_bp(0), _bp(3), wo, wi, wo, False, NO_TABLE)[0]
    # From inside the glass: a steep base refracts out, a grazing offset is totally reflected
    wo_b = _unit([0.1, 0.0, -1.0])
    wi_b, _, pdf, _ = bsdfs.bsdf_sample(_bp(4), wo_b, 0.5, 0.5, 0.99, True, NO_TABLE)
    assert pdf > 0 and wi_b[2] > 0
    assert not half_vector_shift(_bp(4), _bp(4), wo_b, tuple(wi_b), _unit([0.9, 0.0, -0.3]), True, NO_TABLE)[0]


@pytest.mark.parametrize("name,roughness", [("ajar", 0.001), ("caustic", 0.001), ("cornell", math.inf),
                                            ("ajar-textured", 0.001), ("cornell-black", 0.001)])
def test_hybrid_gradients_are_unbiased(name, roughness):
    """dx, dy of the hybrid shift at 2048 spp against a 16384-spp path render (16x16): sum of z^2
    below the chi-square 1% quantile, mean z within its bound (Sidak over 4 tests).
    - `ajar`: many reconnections are blocked by the door; counting a blocked one as a success gave
      sum z^2 = 1.67 m and 1.95 m (bound 1.28 m), and mean z 3.7 and 2.3 sigma off.
    - `caustic`: half-vector copies through glass, total internal reflection, the reverse-
      reconnection check.
    - `cornell` with no vertex rough enough to reconnect: half-vector copies everywhere, so the pairs
      take no NEE and weigh emission over the BSDF techniques alone (NEE reconnecting while the
      BSDF sample is copied would pair a path with two different partners).
    - `ajar-textured` (tests/scenes.textured): offsets evaluate the textured BSDF and the shading
      frame at their own points (material.surface_at_point), with the light-leak mask.
    - `cornell-black` (its red wall black, tests/scenes.blackened): a base whose throughput is 0
      must still carry its offsets, which the pair's other side weighs as found from here too;
      dropping them darkened the pairs across the wall's edges (as it did around every black-BSDF
      light): dx's sum z^2 was 582 over 211 pixels there, against a bound of 273."""
    for key, z in gradient_z(name, 16, 2048, 16384, shift="hybrid", shift_roughness=roughness):
        m = z.size
        assert m > 150
        chi = float(np.sum(z * z))
        assert chi < sstats.chi2.isf(0.01 / 4, m), f"{name} {key}: sum z^2 = {chi:.0f} over {m} pixels"
        assert abs(z.mean()) * np.sqrt(m) < z_critical(4, 0.01), f"{name} {key}: mean z {z.mean():.3f}"


VEACH_MIS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))),
                         "shared", "scenes", "veach-mis", "scene.obj")


@pytest.mark.skipif(not os.path.isfile(VEACH_MIS), reason="../shared/scenes/veach-mis is not there")
@pytest.mark.parametrize("direct_roughness", [0.0, 0.01])
def test_hybrid_gradients_are_unbiased_on_glossy_plates_under_small_lights(direct_roughness):
    """`veach-mis` (../shared/scenes) at 64x36: dx, dy at 128 spp against a 2048-spp path render,
    the chi-square and mean-z bounds of test_hybrid_gradients_are_unbiased. Its plates are near-
    specular (GGX alpha 1e-8 and 1.3e-4, below the shift's threshold, and 0.0017 and 0.008 above)
    beside a diffuse wall, under four small bright lights. Detects (both measured at 256 spp against
    4096; each leaves pixel pairs whose gradient is 0 in every sample, fewer spp only adds to them):
    - a half-vector copy between a rough vertex and a glossy one (the wall's diffuse bounce onto a
      near-delta lobe), whose pair took no NEE: the wall's light then came from BSDF samples alone,
      which at the plates' edges never hit the lights (sum z^2 = 17 m and 51 m, mean z 10 sigma);
    - a copy between two glossy vertices that drops NEE from the gradient instead of keeping each
      side's own (the lobes' tails, lit by NEE alone: sum z^2 = 12 m and 4.2 m, mean z -13.6 sigma).
    With direct_roughness 0 every plate pixel is tested; with the default 0.01 the light the plates
    reflect is direct light, its pixels are left out (as those that see a light), and the test
    checks the gradients of the rest, from which that light must be left out alike."""
    scene = tracer.load_scene(VEACH_MIS, width=64, height=36)
    for key, z in scene_gradient_z(scene, 128, 2048, integrator_settings={"direct_roughness": direct_roughness}):
        m = z.size
        assert m > (1500 if direct_roughness == 0.0 else 800)
        chi = float(np.sum(z * z))
        assert chi < sstats.chi2.isf(0.01 / 4, m), f"veach-mis {key}: sum z^2 = {chi:.0f} over {m} pixels"
        assert abs(z.mean()) * np.sqrt(m) < z_critical(4, 0.01), f"veach-mis {key}: mean z {z.mean():.3f}"


def test_packet_queries_answer_as_the_batch_calls(monkeypatch):
    """The hybrid wave's ray queries beyond the base's hits (the offsets' own rays, their
    reconnections' visibility, the base's and offsets' shadow rays) answered in place by
    embree.intersect_listed / occluded_listed (PacketQueries) against the same queries gathered
    into the accel's batch calls and scattered back (BatchQueries): the same gradients and images
    bit for bit, and the same ray counts, on `ajar` (blocked reconnections) and `caustic` (copied
    offsets through glass). Detects a ray lost, read from the wrong row, answered for the wrong
    offset, or a tmax or visibility mistaken."""
    from tests import scenes
    from tracer.gradient import hybrid

    for name in ("ajar", "caustic"):
        scene = scenes.builtin(ROOT, name, 24, 24)
        kw = dict(spp=2, seed=4, integrator="gpt", recon="none", progress=False)
        packet = tracer.render(scene, **kw)
        with monkeypatch.context() as m:
            m.setattr(hybrid, "_queries", lambda accel, buf, hb: hybrid.BatchQueries(accel, buf, hb))
            batch = tracer.render(scene, **kw)
        assert packet.stats["camera_and_bounce_rays"] == batch.stats["camera_and_bounce_rays"]
        assert packet.stats["shadow_rays"] == batch.stats["shadow_rays"]
        for key in ("base", "dx", "dy", "direct"):
            assert np.array_equal(packet.buffers[key], batch.buffers[key]), f"{name} {key}"


def test_a_waves_gradient_samples_land_as_film_add_puts_them():
    """gradient.films.add_gradients (one kernel over the five films) against the films filled
    by film.Film.add written out in the test: the base, direct and indirect samples in their
    pixels, dx at (x, y) the +x sample of (x, y) and minus the -x sample of (x + 1, y), dy likewise,
    the gradients scaled; every sum, square sum, count and AOV equal bit for bit (np.add.at adds in
    order, as the kernel must). Detects a gradient put in the wrong pixel or film, a sign or scale
    lost, an edge pixel's sample kept, or samples summed out of order."""
    from types import SimpleNamespace

    from tracer.film import N_AOV, Film
    from tracer.gradient.films import GradientFilms, add_gradients

    rng = np.random.default_rng(7)
    w, h, n = 7, 5, 400
    pix = rng.integers(0, w * h, n)
    L, L_cam = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    aov, G = rng.normal(size=(n, N_AOV)), rng.normal(size=(n, 4, 3))
    buf = SimpleNamespace(index=pix, L=L, L_cam=L_cam, aov=aov)
    films = GradientFilms(w, h)
    add_gradients(SimpleNamespace(crop=(0, 0, w, h)), buf, films, n, G, 2.0)

    def film(parts):
        f = Film(w, h, aovs=False)
        for p, v in parts:
            np.add.at(f.count, p, 1.0)
            np.add.at(f.sum, p, v)
            np.add.at(f.sumsq, p, v * v)
        return f

    x, y = pix % w, pix // w
    want = {"base": film([(pix, L)]), "direct": film([(pix, L_cam)]), "indirect": film([(pix, L - L_cam)]),
            "dx": film([(pix, 2.0 * G[:, 0]), (pix[x >= 1] - 1, -(2.0 * G[x >= 1, 1]))]),
            "dy": film([(pix, 2.0 * G[:, 2]), (pix[y >= 1] - w, -(2.0 * G[y >= 1, 3]))])}
    for name, f in want.items():
        got = getattr(films, name)
        for a in ("count", "sum", "sumsq"):
            assert np.array_equal(getattr(got, a), getattr(f, a)), f"{name}.{a}"
    want_aov = np.zeros((w * h, N_AOV))
    np.add.at(want_aov, pix, aov)
    assert np.array_equal(films.base.aov, want_aov)
    assert films.dx.aov.shape[1] == 0
