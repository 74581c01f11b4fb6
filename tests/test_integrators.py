"""Integrators as registered methods: the spec grammar, their settings, `nee` 0, and gpt with a guide."""
import json
import os

import numpy as np
import pytest

import tracer
from tracer.errors import SettingsError
from tracer.integrators import integrator_names, make_integrator
from tracer.methods import format_spec, parse_spec
from tracer.testing.stats import assert_clean, image_mean, z_critical
from tests.gradient.zscores import gradient_z
from tests.test_cli import fails_with, run_cli

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _scene(name, w=24, h=24):
    return tracer.load_scene(os.path.join(ROOT, "scenes", name, f"{name}.obj"), width=w, height=h)


def test_specs_parse_and_print_back():
    """The one grammar: NAME[:KEY=VALUE,...], values as int, float or text."""
    assert parse_spec("photon") == ("photon", {})
    assert parse_spec("gpt:shift=replay,recon_alpha=0.5,nee=0") == (
        "gpt", {"shift": "replay", "recon_alpha": 0.5, "nee": 0})
    assert parse_spec(format_spec("gpt", {"shift": "replay", "nee": 0})) == ("gpt", {"shift": "replay", "nee": 0})
    for bad in ("gpt:shift", ":x=1", "gpt:=1", 3):
        with pytest.raises(SettingsError):
            parse_spec(bad)


def test_unknown_integrators_and_settings_name_the_valid_ones():
    assert set(integrator_names()) == {"path", "gpt"}
    with pytest.raises(SettingsError, match="unknown integrator 'bdpt'; valid: gpt, path"):
        make_integrator("bdpt")
    with pytest.raises(SettingsError, match="integrator 'path' has no setting 'recon'; valid: nee"):
        make_integrator("path:recon=l1")
    with pytest.raises(SettingsError, match="nee must be 0 or 1"):
        make_integrator("path:nee=2")
    with pytest.raises(SettingsError, match="unknown shift"):
        make_integrator("gpt:shift=manifold")
    with pytest.raises(SettingsError, match="nee=0 goes with shift=replay"):
        make_integrator("gpt:nee=0")
    scene = _scene("cornell", 8, 8)
    with pytest.raises(SettingsError, match="the hybrid shift takes guides without per-pixel maps"):
        tracer.render(scene, spp=1, integrator="gpt:shift=hybrid", guide="odis")
    assert tracer.render(scene, spp=2, integrator="gpt", guide="odis").stats["shift"] == "replay"  # its default
    assert tracer.render(scene, spp=2, integrator="gpt", guide="grid").stats["shift"] == "hybrid"
    with pytest.raises(SettingsError, match="warps them"):
        tracer.render(scene, spp=1, integrator="gpt:shift=replay", guide="pss")
    with pytest.raises(SettingsError, match="has no setting 'shift'"):
        tracer.render(scene, spp=1, shift="replay")  # gpt's keyword on the path tracer


def test_keywords_and_spec_are_the_same_settings():
    """render(integrator="gpt", recon="l1", shift="replay") and the spec give the same image."""
    scene = _scene("cornell", 12, 12)
    a = tracer.render(scene, spp=2, integrator="gpt", shift="replay", recon="l1", recon_alpha=0.3)
    b = tracer.render(scene, spp=2, integrator="gpt:shift=replay,recon=l1,recon_alpha=0.3")
    np.testing.assert_array_equal(a.image, b.image)
    assert b.stats["integrator"] == "gpt" and b.stats["shift"] == "replay" and b.stats["recon_alpha"] == 0.3


@pytest.mark.parametrize("guide", ["bsdf", "grid", "photon", "odis"])
def test_nee_off_is_unbiased(guide):
    """path:nee=0 (emission counted in full, no shadow rays) against the NEE render's mean: a
    z-test of the image means with both renders' variances, per channel. Counting a BSDF-found
    emitter with its MIS weight (as with NEE on) would darken the image by the share NEE gives
    the light, several standard deviations here; the guides learn the direct light too."""
    scene = _scene("ajar", 24, 24)
    on = tracer.render(scene, spp=256, seed=1, guide=guide)
    off = tracer.render(scene, spp=256, seed=2, guide=guide, integrator="path:nee=0")
    assert_clean(on)
    assert_clean(off)
    assert off.stats["shadow_rays"] == 0 and on.stats["shadow_rays"] > 0 and off.stats["nee"] == 0
    m1, v1 = image_mean(on)
    m0, v0 = image_mean(off)
    z = (m0 - m1) / np.sqrt(v0 + v1)
    assert np.all(np.abs(z) < z_critical(3)), (guide, z, m0, m1)


def test_nee_off_gpt_replay_is_unbiased():
    """gpt:shift=replay,nee=0: the base image's mean against the NEE path render's (z-test)."""
    scene = _scene("cornell", 24, 24)
    on = tracer.render(scene, spp=256, seed=1)
    off = tracer.render(scene, spp=256, seed=2, integrator="gpt:shift=replay,nee=0,recon=none")
    assert_clean(off)
    assert off.stats["shadow_rays"] == 0
    m1, v1 = image_mean(on)
    m0, v0 = image_mean(off)
    z = (m0 - m1) / np.sqrt(v0 + v1)
    assert np.all(np.abs(z) < z_critical(3)), (z, m0, m1)


@pytest.mark.parametrize("guide,shift,name", [("photon", "replay", "cornell"), ("odis", "replay", "cornell"),
                                              ("photon", "hybrid", "cornell"), ("grid", "hybrid", "cornell"),
                                              ("photon", "hybrid", "ajar-textured")])
def test_guided_gpt_gradients_are_the_differences_of_the_path_tracers_pixels(guide, shift, name):
    """gpt with a guide: the guide trains by its own schedule, then base and offsets sample its
    mixture (the hybrid shift gives each offset its own pixel's mixture density in its weights).
    Per-pixel z-scores of dx, dy against an unguided path render's pixel differences
    (tests/gradient/zscores.py): their mean over m pixels, times sqrt(m), is a z-score; a
    gradient biased by a shift that drops the offset's own mixture density would move it by
    several units. `ajar-textured` (tests/scenes.textured): textures and shading normals at the
    offsets' own vertices."""
    for key, z in gradient_z(name, 24, 64, 512, shift=shift, guide=guide):
        m = z.size
        assert m > 100
        assert abs(z.mean()) * np.sqrt(m) < z_critical(2), f"{guide} {shift} {key}: mean z {z.mean():.3f}"
        assert 0.5 < z.std() < 1.5, f"{guide} {shift} {key}: z spread {z.std():.3f}"


@pytest.mark.parametrize("shift", ["replay", "hybrid"])
def test_guided_gpt_image_mean_is_the_path_tracers(shift):
    """gpt (recon l2) with the photon guide: the base image's mean against a path render's (z-test
    with both variances), and the reconstruction's mean the base's (the L2 solve keeps it)."""
    scene = _scene("ajar", 24, 24)
    p = tracer.render(scene, spp=256, seed=1)
    g = tracer.render(scene, spp=256, seed=2, guide="photon", integrator=f"gpt:shift={shift}")
    assert_clean(g)
    assert [e["kind"] for e in g.stats["passes"]][:2] == ["pilot", "train"]
    assert all(e["weight"] == (1.0 if e["kind"] == "gradient" else 0.0) for e in g.stats["passes"])
    m1, v1 = image_mean(p)
    base = g.buffers["base"].astype(np.float64).reshape(-1, 3)
    bvar = g.buffers["base_variance"].astype(np.float64).reshape(-1, 3)
    n = base.shape[0]
    z = (base.mean(axis=0) - m1) / np.sqrt(bvar.sum(axis=0) / n**2 + v1)
    assert np.all(np.abs(z) < z_critical(3)), z
    assert abs(g.image.mean() / base.mean() - 1.0) < 1e-3  # (the l2 solve keeps the mean)


def test_cli_runs_guided_gpt_and_lists_integrators(capsys, tmp_path):
    out = tmp_path / "g.exr"
    code, _, err = run_cli(capsys, os.path.join(ROOT, "scenes", "cornell", "cornell.obj"), "--width", "12",
                           "--height", "12", "--spp", "8", "--integrator", "gpt", "--guide",
                           "photon:iterations=1", "-q", "-o", str(out))
    assert code == 0, err
    st = json.loads((tmp_path / "g.json").read_text())
    assert st["integrator"] == "gpt" and st["guide"] == "photon" and st["shift"] == "hybrid"
    assert (tmp_path / "g.dx.exr").is_file()
    code, text, _ = run_cli(capsys, "--list-integrators")
    assert code == 0 and "gpt:" in text and "path:" in text and "nee = 1" in text and "shift = hybrid" in text
    fails_with(capsys, [os.path.join(ROOT, "scenes", "cornell", "cornell.obj"), "--integrator", "path:recon=l1"],
               "integrator 'path' has no setting 'recon'")
    fails_with(capsys, [os.path.join(ROOT, "scenes", "cornell", "cornell.obj"), "--integrator", "gpt:shift=hybrid",
                        "--guide", "odis"], "use gpt:shift=replay")
