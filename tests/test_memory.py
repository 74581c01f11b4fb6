"""A render that the machine cannot hold is refused before anything is allocated, and the estimate
it is judged by stays above what each method really allocates."""
import gc
import json
import tracemalloc

import pytest

import tracer
from tracer import memory
from tracer.guiding import make_guide
from tracer.integrators import make_integrator
from tracer.wave import WaveBuffers
from tests import scenes
from tests.test_cli import CORNELL, fails_with


def test_huge_film_is_refused_in_one_line(tmp_path, capsys):
    """100000 x 100000 needs ~26 TB: one line naming the scene, the need and what is available, exit
    2, no output file (before this, numpy's 'Unable to allocate 74.5 GiB' and a 22-line traceback).
    The same from the sidecar's film size."""
    out = tmp_path / "o.exr"
    msg = fails_with(capsys, [CORNELL, "--width", 100000, "--height", 100000, "-o", out],
                     "cornell.obj", "100000x100000 render needs about", "GiB", "available")
    assert "pixels would fit" in msg
    assert not out.exists()
    obj = scenes.light_quad(tmp_path, (1, 1, 1))
    side = json.loads((tmp_path / "lamp.json").read_text())
    side["film"] = {"width": 60000, "height": 50000}
    (tmp_path / "lamp.json").write_text(json.dumps(side))
    fails_with(capsys, [obj, "-o", out], "lamp.obj", "60000x50000 render needs about")


def test_library_refuses_before_allocating():
    scene = tracer.load_scene(CORNELL, width=100000, height=100000)
    with pytest.raises(tracer.SettingsError, match="needs about .* available"):
        tracer.render(scene, spp=1)


def test_check_arithmetic():
    """check() passes what fits in HEADROOM of the available memory and names the largest square
    film that would fit when it refuses (an independent sum here)."""
    est = memory.estimate(1000 * 1000, 10, 1000)
    assert est["total"] == 1000 * 1000 * memory.PATH_PIXEL_BYTES + 1000 + 10 * memory.ACCEL_BYTES_PER_TRIANGLE
    memory.check(1000, 1000, est, available=est["total"] / memory.HEADROOM + 1)
    with pytest.raises(tracer.SettingsError) as e:
        memory.check(1000, 1000, est, available=est["total"])
    side = int(((memory.HEADROOM * est["total"] - est["fixed"]) / est["per_pixel"]) ** 0.5)
    assert f"about {side}x{side} pixels" in str(e.value)


def test_estimate_counts_the_environment_map(tmp_path):
    """An environment map's sampling tables (built when the render starts) are in the estimate: a
    32 x 32 render under a 512 x 1024 map allocates (tracemalloc) more than the estimate without
    the map, so an estimate that leaves the map out fails, and no more than the estimate with it
    (the map's image is held by the loaded scene, before the render)."""
    import numpy as np

    h, w = 512, 1024
    img = (np.random.default_rng(1).random((h, w, 3)) + 0.01).astype(np.float32)
    tracer.write_image(tmp_path / "env.exr", img)
    scene = tracer.load_scene(scenes.sphere_under_sky(tmp_path, 0.5, 1.0, env={"map": "env.exr"}, width=32,
                                                      height=32))
    wave = 4096
    tracer.render(scene, spp=1, wave_size=wave)  # compiled
    gc.collect()
    tracemalloc.start()
    try:
        r = tracer.render(scene, spp=1, wave_size=wave)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert r.stats["nonfinite_samples"] == 0
    wave_bytes = WaveBuffers.bytes_for(wave)
    assert memory.estimate(32 * 32, 0, wave_bytes)["total"] < peak <= memory.estimate(32 * 32, 0, wave_bytes,
                                                                                     env_texels=h * w)["total"]


METHODS = [("bsdf", {}), ("grid", {}), ("photon", {}), ("pss", {"guide_settings": {"train_seconds": 1.0}}),
           ("odis", {}), ("ppg", {}), ("gpt-l1", {}), ("gpt-l2", {})]


@pytest.mark.parametrize("method,kw", METHODS, ids=[m for m, _ in METHODS])
def test_estimate_bounds_the_allocations(method, kw, tmp_path):
    """The estimate (per pixel and fixed, the accel's part left out: Embree allocates outside
    Python) stays above the peak of what the render and its outputs allocate through NumPy
    (tracemalloc), at 256 x 256 with small waves so that the per-pixel part dominates: a method
    that starts holding another film's worth of memory a pixel (112 bytes) beyond its estimate's
    margin fails. Torch's allocations (pss, gradnet) are not traced."""
    w = h = 256
    wave = 4096
    scene = tracer.load_scene(CORNELL, width=w, height=h)
    gpt = method.startswith("gpt")
    args = dict(integrator="gpt", recon=method[4:]) if gpt else dict(guide=method, **kw)
    tracer.render(scene, spp=1, wave_size=wave, **args)  # compiled, torch imported, weights loaded
    gc.collect()
    tracemalloc.start()
    try:
        r = tracer.render(scene, spp=16, wave_size=wave, **args)
        tracer.write_outputs(r, tmp_path / "x.exr")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert r.stats["nonfinite_samples"] == 0
    g = None if gpt else make_guide(method, **kw.get("guide_settings", {}))
    integ = make_integrator(f"gpt:recon={method[4:]}" if gpt else "path")
    wave_bytes = WaveBuffers.bytes_for(wave, split=g is not None and g.splits) + integ.wave_bytes(wave)
    est = memory.estimate(w * h, 0, wave_bytes, g, integ)
    assert peak <= est["total"], (peak / (w * h), est)
