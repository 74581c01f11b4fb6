"""Aimed environment photons (photons.EnvAim): the flux they carry through an opening, and that
aiming sends more of them inside a room with a window."""
import os

import numpy as np

import tracer
from tests.scenes import sphere_under_sky
from tracer.guiding import make_guide
from tracer.guiding.grid.photons import PhotonBuffers, emit, env_aim, no_aim
from tracer.lights import build_lights

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LE = 1.5
HALF = 0.2  # the opening: the square |x|, |y| <= HALF in the plane z = 0.3, lit side +z
Z0 = 0.3


def _flux_through_opening(aim, lt, tri, centre, radius, n=400000, seed=3):
    """Per-photon luminance power of the photons that cross the opening downwards (their mean is
    an estimate of the flux through it) for n photons of one iteration."""
    buf = PhotonBuffers(n)
    emit(lt, tri, centre, radius, np.zeros(len(tri)), seed, 0, 0, aim, buf.key, buf.o, buf.d, buf.power, buf.thr,
         buf.depth, buf.src)
    o, d = buf.o, buf.d
    down = d[:, 2] < 0.0
    t = np.where(down, (Z0 - o[:, 2]) / np.where(down, d[:, 2], -1.0), -1.0)
    p = o + t[:, None] * d
    cross = down & (t > 0) & (np.abs(p[:, 0]) <= HALF) & (np.abs(p[:, 1]) <= HALF)
    lum = buf.power @ np.array([0.2126, 0.7152, 0.0722])
    return np.where(cross, lum, 0.0), (buf.power > 0).any(axis=1).mean()


def test_aimed_photons_carry_the_flux_through_the_opening(tmp_path):
    """Under a constant sky of radiance Le, the flux into a one-sided square of area A is pi Le A.
    Photons aimed by escapes through that square (points on it, cosine-distributed directions
    out) must estimate it without bias, as the unaimed ones do (z-tests at 4 sigma from the sample
    variance): a wrong |cos| factor, rectangle area or start plane, or rectangles that miss part of
    the opening, shows as a biased mean. Most aimed photons must start where they can reach it."""
    scene = tracer.load_scene(sphere_under_sky(tmp_path, 0.5, LE))
    lt = build_lights(scene)
    centre = 0.5 * (scene.bounds[0] + scene.bounds[1])
    radius = 0.5 * float(np.linalg.norm(scene.bounds[1] - scene.bounds[0])) * 1.01
    rng = np.random.default_rng(0)
    m = 20000
    x = np.stack([rng.uniform(-HALF, HALF, m), rng.uniform(-HALF, HALF, m), np.full(m, Z0)], axis=1)
    r, phi = np.sqrt(rng.uniform(size=m)), rng.uniform(0, 2 * np.pi, m)
    w = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - r * r)], axis=1)
    aim = env_aim(x, w, centre, radius)
    assert aim.allowed.any() and not aim.allowed.all()
    want = np.pi * LE * (2 * HALF) ** 2
    shares = {}
    for name, a in (("disk", no_aim()), ("aimed", aim)):
        v, traced = _flux_through_opening(a, lt, scene.tri, centre, radius)
        mean, se = v.mean(), v.std() / np.sqrt(v.size)
        assert abs(mean - want) < 4 * se, (name, mean, want, se)
        shares[name] = (v > 0).mean() / traced
    assert shares["aimed"] > 5 * shares["disk"], shares


def test_aiming_sends_more_photons_inside_the_window_room():
    """The built-in window room: the share of traced environment photons that deposit anything
    inside must grow with aim_env (3% -> 20% at 256x192); and stay zero-escape without it."""
    scene = tracer.load_scene(os.path.join(ROOT, "scenes", "window", "window.obj"), width=48, height=36)
    share = {}
    for aim in (0, 1):
        g = make_guide("photon", aim_env=aim, iterations=2)
        st = tracer.render(scene, spp=4, guide=g).stats
        gs = st["guide_stats"]
        assert st["nonfinite_samples"] == 0
        assert (gs["escapes"] > 0) == bool(aim)
        share[aim] = gs["env_photons_inside"] / max(gs["env_photons_traced"], 1)
    assert share[1] > 2 * share[0], share
