"""Open Image Denoise on a render (tracer.denoise, render(denoise=...), --denoise, bench's +oidn).

Skipped where the `denoise` extra (pyoidn) is not installed, except the checks of the error a
user then gets."""
import json
import os

import numpy as np
import pytest

import tracer
from tracer import denoise as dn
from tracer import metrics
from tracer.cli import main
from tracer.errors import SettingsError
from tests import scenes

needs_oidn = pytest.mark.skipif(not dn.available(), reason="pyoidn (the denoise extra) is not installed")


@needs_oidn
def test_a_clean_image_comes_back_as_it_went_in():
    """A smooth, noise-free ramp with a different gradient per channel must come out within 3% (mean
    relative difference; OIDN keeps it to about 0.5%). Detects images handed over in the wrong
    layout: channels swapped (33% here), rows and columns exchanged, a wrong format or scale."""
    h, w = 24, 40
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = np.stack([0.2 + x / w, 0.3 + 2 * y / h, np.full_like(x, 0.5)], axis=2)
    albedo = np.full((h, w, 3), 0.6, np.float32)
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = 1.0
    for aux in ((albedo, normal), (None, None)):
        out = dn.denoise(img, *aux, threads=1)
        assert out.shape == img.shape and out.dtype == np.float32
        for c in range(3):
            assert np.abs(out[..., c] / img[..., c] - 1.0).mean() < 0.03, c


@needs_oidn
def test_render_denoised_is_closer_to_the_analytic_image(tmp_path):
    """A closed box (albedo 0.5, every wall emitting 1) reads 1 / (1 - 0.5) = 2 in every pixel. At 2
    spp the raw image is noisy; the denoised one (render(denoise=True)) must have less than half its
    relMSE against that analytic image, and keep its mean within 5%. Detects a denoiser fed the
    wrong buffer or writing the wrong output (its relMSE would not drop), and a lost image mean."""
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=24, height=24)
    scene = tracer.load_scene(obj)
    r = tracer.render(scene, spp=2, seed=3, denoise=True, threads=1)
    truth = np.full_like(r.image, 2.0)
    raw, clean = metrics.relmse(r.image, truth), metrics.relmse(r.denoised, truth)
    assert raw > 0.0 and clean < raw / 2, (raw, clean)
    assert abs(r.denoised.mean() / 2.0 - 1.0) < 0.05
    s = r.stats
    assert s["nonfinite_samples"] == 0 and s["nonfinite_denoised"] == 0
    assert s["denoise"] == "high" and s["time_denoise"] > 0
    assert s["time_total"] >= s["time_render"] + s["time_denoise"]
    assert tracer.render(scene, spp=1).denoised is None


def _noisy(rng, h, w):
    """A noisy image, an albedo and unit normals, (h, w, 3) float32 each."""
    img = rng.gamma(1.0, 1.0, (h, w, 3)).astype(np.float32)
    albedo = rng.uniform(0.0, 1.0, (h, w, 3)).astype(np.float32)
    normal = rng.normal(size=(h, w, 3)).astype(np.float32)
    return img, albedo, normal / np.linalg.norm(normal, axis=2, keepdims=True)


@needs_oidn
def test_a_second_call_of_the_same_size_reuses_the_filters():
    """Denoiser keeps its three filters (two prefilters, the colour filter) per image size: a
    second call of that size builds none, and its result equals a fresh Denoiser's on the same
    input, bit for bit. Detects filters rebuilt on every call (the cost this saves), and reused
    filters that read stale inputs (the first call's image or buffers) or write elsewhere."""
    rng = np.random.default_rng(5)
    first, second = _noisy(rng, 12, 20), _noisy(rng, 12, 20)
    d = dn.Denoiser(threads=1)
    d(*first)
    assert d.filters_built == 3
    out = d(*second)
    assert d.filters_built == 3
    fresh = dn.Denoiser(threads=1)
    assert np.array_equal(out, fresh(*second))
    assert not np.array_equal(out, fresh(*first))
    assert np.array_equal(d(second[0]), fresh(second[0]))  # no buffers: a filter of its own
    assert d.filters_built == 4
    d(*_noisy(rng, 20, 12))  # another size: its own three
    assert d.filters_built == 7
    d.close()
    fresh.close()


def test_bad_settings_are_one_clear_error(monkeypatch):
    scene = None  # never loaded: the settings fail first
    with pytest.raises(SettingsError, match="denoise quality must be one of high, balanced, fast"):
        tracer.render(scene, spp=1, denoise="ultra")
    monkeypatch.setattr(dn, "available", lambda: False)
    with pytest.raises(SettingsError, match=r'pip install -e "\.\[denoise\]"'):
        tracer.render(scene, spp=1, denoise=True)


def test_cli_without_pyoidn_fails_before_rendering(tmp_path, capsys, monkeypatch):
    """--denoise without the extra: exit 2, one line that says how to install it, nothing written."""
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=8, height=8)
    monkeypatch.setattr(dn, "available", lambda: False)
    out = tmp_path / "o" / "box.exr"
    code = main([obj, "--spp", "1", "-o", str(out), "--denoise", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("tracer: denoising needs"), err
    assert not out.parent.exists()


def test_cli_denoise_quality_is_optional_before_the_scene(tmp_path, capsys, monkeypatch):
    """`--denoise SCENE` takes SCENE as the scene (quality high), `--denoise fast SCENE` and
    `--denoise=fast` the quality; a bare --denoise last is high. Detects the optional quality
    swallowing the scene ("the following arguments are required: scene")."""
    from tracer.cli import _denoise_quality, _parser

    def parse(*argv):
        a = _parser().parse_args(_denoise_quality(argv))
        return a.scene, a.denoise

    assert parse("--denoise", "s.xml") == ("s.xml", "high")
    assert parse("--denoise", "fast", "s.xml") == ("s.xml", "fast")
    assert parse("--denoise=balanced", "s.xml") == ("s.xml", "balanced")
    assert parse("s.xml", "--denoise") == ("s.xml", "high")
    assert parse("s.xml", "--spp", "2") == ("s.xml", None)
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=8, height=8)
    monkeypatch.setattr(dn, "available", lambda: False)  # the run gets as far as the denoiser's check
    assert main(["--denoise", str(obj), "--spp", "1", "-o", str(tmp_path / "o.exr"), "-q"]) == 2
    assert capsys.readouterr().err.startswith("tracer: denoising needs")


@needs_oidn
def test_cli_writes_the_denoised_image_beside_the_raw_one(tmp_path, capsys):
    obj = scenes.closed_box(tmp_path / "box", 0.5, 1.0, width=8, height=8)
    out = tmp_path / "box.exr"
    assert main([obj, "--spp", "2", "-o", str(out), "--denoise", "fast", "-q"]) == 0
    summary = capsys.readouterr().out
    assert "denoised (Open Image Denoise" in summary
    assert f"{tmp_path / 'box.denoised.exr'}, preview {tmp_path / 'box.denoised.png'}" in summary
    raw, clean = tracer.read_image(str(out)), tracer.read_image(str(tmp_path / "box.denoised.exr"))
    assert clean.shape == raw.shape and np.isfinite(clean).all() and not np.array_equal(clean, raw)
    assert os.path.isfile(tmp_path / "box.denoised.png")
    stats = json.loads((tmp_path / "box.json").read_text())
    assert stats["denoise"] == "fast" and stats["nonfinite_denoised"] == 0 and stats["nonfinite_samples"] == 0
    assert not [f for f in os.listdir(tmp_path) if ".tmp" in f]


def test_bench_methods_take_oidn():
    from bench import common

    assert common.render_args("bsdf+oidn") == {"guide": "bsdf", "guide_settings": None, "denoise": True}
    assert common.render_args("gpt-l1+oidn") == dict(common.GRADIENT_METHODS["gpt-l1"], denoise=True)
    if dn.available():
        common.check_method("photon:sigma=2+oidn")
    with pytest.raises(SystemExit, match="unknown gradient method"):
        common.check_method("gpt-l3+oidn")
