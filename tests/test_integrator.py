"""The integrator against scenes with known answers (z-tests on the estimated variance)."""
import numpy as np
import pytest

import tracer
from tests import scenes
from tracer.testing.stats import assert_clean, assert_z, image_mean

ACCELS = ["embree", "numba"]


@pytest.mark.parametrize("accel", ACCELS)
def test_closed_box_reads_le_over_one_minus_albedo(tmp_path, accel):
    # Every wall emits Le and reflects a: radiance everywhere is Le / (1 - a) at unlimited depth.
    a, le = 0.6, 1.5
    scene = tracer.load_scene(scenes.closed_box(tmp_path, a, le, width=16, height=16))
    r = tracer.render(scene, spp=64, accel=accel, max_depth=-1, rr_depth=3)
    assert_clean(r)
    mean, var = image_mean(r)
    assert_z(mean, var, le / (1 - a), n_tests=6, what="closed box radiance")


@pytest.mark.parametrize("max_depth", [1, 2, 3])
def test_max_depth_follows_mitsuba(tmp_path, max_depth):
    # max_depth 1: emitters seen directly; 2: plus direct light; d: Le * sum_{k<d} a^k.
    a, le = 0.5, 1.0
    scene = tracer.load_scene(scenes.closed_box(tmp_path, a, le, width=16, height=16))
    r = tracer.render(scene, spp=32, max_depth=max_depth, rr_depth=100)
    assert_clean(r)
    expected = le * sum(a**k for k in range(max_depth))
    mean, var = image_mean(r)
    if max_depth == 1:
        np.testing.assert_allclose(r.image, le, rtol=1e-6)  # no randomness left
    else:
        assert_z(mean, var, expected, n_tests=3 * 2, what=f"max_depth {max_depth}")


def test_light_seen_directly_reads_its_radiance(tmp_path):
    le = (3.0, 2.0, 0.5)
    scene = tracer.load_scene(scenes.light_quad(tmp_path, le))
    r = tracer.render(scene, spp=4)
    assert_clean(r)
    np.testing.assert_allclose(r.image.reshape(-1, 3), np.broadcast_to(le, (64, 3)), rtol=1e-6)
    assert np.all(r.variance == 0)


def test_light_back_side_is_black(tmp_path):
    le = (3.0, 2.0, 0.5)
    obj = scenes.light_quad(tmp_path, le)
    scene = tracer.load_scene(obj)
    from tracer.camera import Camera

    cam = scene.camera
    scene.camera = Camera.look_at(-cam.origin, [0, 0, 0], [0, 1, 0], 30.0, "x", scene.width, scene.height)
    r = tracer.render(scene, spp=2)
    assert_clean(r)
    assert np.all(r.image == 0)


def _sky_test(scene, albedo, radiance, spp, what):
    r = tracer.render(scene, spp=spp)
    assert_clean(r, what)
    alb = r.aovs["albedo"][:, :, 0]
    ball = np.isclose(alb, albedo, atol=1e-6)  # every sample of the pixel hit the sphere
    sky = alb == 0.0  # no sample hit
    assert ball.sum() > 50 and sky.sum() > 50
    np.testing.assert_allclose(r.image[sky], radiance, rtol=1e-6)
    mean, var = image_mean(r, ball)
    assert_z(mean, var, albedo * radiance, n_tests=6, what=what)


def test_convex_object_under_constant_sky_reads_albedo_times_radiance(tmp_path):
    a, L = 0.7, 2.0
    scene = tracer.load_scene(scenes.sphere_under_sky(tmp_path, a, L))
    _sky_test(scene, a, L, 64, "sphere under constant sky")


def test_constant_environment_map_matches_constant_sky(tmp_path):
    # The same sky given as an equirectangular map: exercises the map's 2D importance sampling.
    a, L = 0.7, 2.0
    tracer.write_image(tmp_path / "sky.exr", np.full((16, 32, 3), L, np.float32))
    scene = tracer.load_scene(scenes.sphere_under_sky(tmp_path, a, L, env={"map": "sky.exr", "scale": 1.0}))
    _sky_test(scene, a, L, 64, "sphere under constant map")
