"""Gradient-domain path tracing (both shifts): the base image, the gradients, the outputs."""
import json
import os

import numpy as np
import pytest
from scipy import stats as sstats

import tracer
from tracer.cli import main
from tracer.errors import SettingsError
from tests.gradient.zscores import gradient_z
from tracer.testing.stats import assert_clean, z_critical

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = ("ajar", "caustic", "cornell", "glossy", "manylights", "spotlit", "window")


def _scene(name, w=32, h=32):
    return tracer.load_scene(os.path.join(ROOT, "scenes", name, f"{name}.obj"), width=w, height=h)


@pytest.mark.parametrize("shift", ["hybrid", "replay"])
def test_the_base_image_is_the_path_tracers_image(shift):
    """The base paths are the camera's paths with the same keys: the base image equals a path
    render of the same seed (on the loop that draws the same numbers) bit for bit (so it is unbiased exactly as the path tracer is), and the
    direct and indirect buffers add up to it."""
    scene = _scene("cornell")
    g = tracer.render(scene, spp=8, integrator="gpt", recon="none", seed=3, max_depth=6, shift=shift)
    # hybrid traces its own paths with tracer.rng's numbers, as the per-thread loop draws them; replay
    # traces through the path tracer's loop, the lanes by default
    p = tracer.render(scene, spp=8, seed=3, max_depth=6, path_loop="thread" if shift == "hybrid" else None)
    assert_clean(g)
    np.testing.assert_array_equal(g.buffers["base"], p.image)
    np.testing.assert_allclose(g.buffers["direct"] + g.buffers["indirect"], g.buffers["base"], rtol=1e-5, atol=1e-7)
    assert g.stats["samples"] == p.stats["samples"]


@pytest.mark.parametrize("shift", ["hybrid", "replay"])
@pytest.mark.parametrize("name", ["cornell", "glossy"])
def test_gradients_are_the_differences_of_the_path_tracers_pixels(name, shift):
    """Where no emitter is seen directly from the two pixels (the gradients hold the indirect
    light), dx(x, y) estimates I(x+1, y) - I(x, y) and dy(x, y) I(x, y+1) - I(x, y): against an
    independent path render (another seed), the per-pixel z-scores have sum of squares below the
    chi-square quantile and mean within its z-bound (Sidak over 4 tests). Detects a sign error, a
    pixel off by one or a factor 2 (the -x side's sign flipped: sum z^2 ~ 4500 over 543 pixels)."""
    for key, z in gradient_z(name, 24, 64, 512, shift=shift):
        m = z.size
        assert m > 200
        chi = float(np.sum(z * z))
        assert chi < sstats.chi2.isf(0.01 / 4, m), f"{name} {key}: sum z^2 = {chi:.0f} over {m} pixels"
        assert abs(z.mean()) * np.sqrt(m) < z_critical(4, 0.01), f"{name} {key}: mean z {z.mean():.3f}"


@pytest.mark.parametrize("name", SCENES)
def test_no_nonfinite_sample_on_any_built_in_scene(name):
    """Every built-in scene at 16x16, 2 spp, L1: no non-finite sample, finite buffers."""
    r = tracer.render(_scene(name, 16, 16), spp=2, integrator="gpt", seed=1)
    assert_clean(r)
    for k, v in r.buffers.items():
        assert np.isfinite(v).all(), k


def test_reconstruction_settings_are_checked():
    scene = _scene("cornell", 8, 8)
    for kw, frag in (({"integrator": "gtp"}, "integrator"), ({"integrator": "gpt", "shift": "manifold"}, "shift"),
                     ({"integrator": "gpt", "shift_roughness": -1.0}, "shift_roughness"),
                     ({"integrator": "gpt", "recon": "l3"}, "reconstruction"),
                     ({"integrator": "gpt", "recon_alpha": 0.0}, "recon_alpha"),
                     ({"integrator": "gpt", "shift": "hybrid", "guide": "odis"}, "per-pixel maps")):
        with pytest.raises(SettingsError, match=frag):
            tracer.render(scene, spp=1, **kw)


def test_cli_writes_the_reconstruction_and_the_buffers(tmp_path, capsys):
    out = tmp_path / "g" / "c.exr"
    code = main([os.path.join(ROOT, "scenes", "cornell", "cornell.obj"), "--integrator", "gpt", "--recon", "l2",
                 "--spp", "2", "--width", "16", "--height", "16", "-o", str(out), "-q"])
    assert code == 0
    for suffix in (".exr", ".png", ".json", ".base.exr", ".dx.exr", ".dy.exr"):
        assert (tmp_path / "g" / ("c" + suffix)).exists(), suffix
    st = json.loads((tmp_path / "g" / "c.json").read_text())
    assert st["integrator"] == "gpt" and st["recon"] == "l2" and st["time_solve"] >= 0.0
    assert st["shift"] == "hybrid" and st["shift_roughness"] == 0.001
    assert st["nonfinite_samples"] == 0
    dx = tracer.read_image(str(tmp_path / "g" / "c.dx.exr"))
    assert dx.shape == (16, 16, 3) and np.isfinite(dx).all()
    code = main([os.path.join(ROOT, "scenes", "cornell", "cornell.obj"), "--integrator", "gpt", "--shift", "hybrid",
                 "--guide", "odis", "-o", str(out), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "per-pixel maps" in err


SHARED = os.path.join(os.path.dirname(ROOT), "shared", "scenes")
EXTERNAL = ("cornell-glass-sphere", "veach-ajar", "veach-ajar-glossy", "veach-mis")


@pytest.mark.parametrize("name", EXTERNAL)
def test_no_nonfinite_sample_on_the_external_scenes(name):
    """The public scenes beside the repository (../shared/scenes), 24x24, 2 spp, L1: no non-finite
    sample, finite buffers (glass, glossy metal, small bright lights)."""
    path = os.path.join(SHARED, name, "scene.obj")
    if not os.path.isfile(path):
        pytest.skip(f"{path} is not there")
    r = tracer.render(tracer.load_scene(path, width=24, height=24), spp=2, integrator="gpt", seed=2)
    assert_clean(r)
    for k, v in r.buffers.items():
        assert np.isfinite(v).all(), k


def test_albedo_is_taken_past_a_mirror_and_depth_is_normalised(tmp_path):
    """A camera facing a mirror that reflects a diffuse wall behind the camera (Kd 0.2 0.5 0.8):
    every pixel's albedo AOV is the wall's, not the mirror's (for path and gpt alike); the
    normal and depth stay at the first hit (the mirror, 2 units away); gpt's depth buffer is in
    [0, 1] with its largest value 1."""
    from tests import scenes

    big = 20.0
    mirror = np.array([[-big, -big, -2.0], [big, -big, -2.0], [big, big, -2.0], [-big, big, -2.0]])
    wall = np.array([[-big, -big, 2.0], [-big, big, 2.0], [big, big, 2.0], [big, -big, 2.0]])
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    obj = scenes.write_scene(tmp_path, "mirror", [("mirror", mirror, quad), ("wall", wall, quad)],
                             {"mirror": "illum 3\nKs 1 1 1", "wall": "Kd 0.2 0.5 0.8\nKe 1 1 1"},
                             {"camera": {"origin": [0, 0, 0], "target": [0, 0, -1], "up": [0, 1, 0], "fov": 30},
                              "film": {"width": 8, "height": 8}})
    scene = tracer.load_scene(obj)
    for kw in ({}, {"integrator": "gpt"}):
        r = tracer.render(scene, spp=2, seed=1, max_depth=4, **kw)
        assert_clean(r)
        np.testing.assert_allclose(r.aovs["albedo"], np.broadcast_to([0.2, 0.5, 0.8], (8, 8, 3)), atol=1e-6)
        np.testing.assert_allclose(r.aovs["normal"][..., 2], 1.0, atol=1e-6)  # the mirror's, facing the camera
        assert (r.aovs["depth"] >= 2.0 - 1e-6).all()
    d = r.buffers["depth"]
    assert d.shape == (8, 8, 1) and d.min() >= 0.0 and np.isclose(d.max(), 1.0)


def test_callback_sees_each_gradient_pass_and_can_stop():
    """gpt calls render's callback after each pass with the base film and the stats so far; False
    stops the render after that pass, and the reconstruction covers the passes done (1 + 2 spp)."""
    seen = []

    def cb(i, film, st):
        seen.append((i, st["spp"], int(film.count.sum())))
        return i < 1

    r = tracer.render(_scene("cornell", 8, 8), spp=64, integrator="gpt", recon="l2", seed=1, callback=cb)
    assert seen == [(0, 1, 64), (1, 3, 192)]
    assert r.stats["spp"] == 3 and r.stats["samples"] == 3 * 64
    assert_clean(r)
