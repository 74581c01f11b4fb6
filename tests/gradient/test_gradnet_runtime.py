"""`--integrator gpt --recon gradnet`: the shipped weights and the render path.

What each test can detect: weights that no longer reproduce their manifest's stored output (a
changed network, loader or input convention); a render whose image is not the network's output
on its own buffers plus the direct light (buffers passed in the wrong order, colour channels mixed,
padding not cropped, the direct light added twice or not at all: checked against a slow twin
written here, one colour channel and one numpy edge-padded call at a time); energy correction
ignored or always on; a NaN, inf or non-finite sample on any built-in scene; a bad setting or a
missing weights file that does not give one clear error (exit 2 from the CLI).
"""
import json
import math
import os

import numpy as np
import pytest
import torch

import tracer
from learn.gradnet_train import check_input
from tracer import gradient
from tracer.cli import main
from tracer.errors import SettingsError
from tracer.gradient import gradnet
from tracer.testing.stats import assert_clean

from .test_gradnet_net import _dense_l2

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = ("ajar", "caustic", "cornell", "glossy", "manylights", "spotlit", "window")


def _scene(name, w=32, h=32):
    return tracer.load_scene(os.path.join(ROOT, "scenes", name, f"{name}.obj"), width=w, height=h)


SHIPPED = ("gradnet", "gradnet_v2")


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_weights_reproduce_their_manifest(name):
    model, manifest = gradnet.load(name)
    assert manifest["model"] == model.config()
    y = gradnet.reconstruct(model, **check_input())
    np.testing.assert_allclose(y.sum(axis=(0, 1)), manifest["check"]["output_sum"], rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(y[10, :8], manifest["check"]["output_row"], rtol=1e-4, atol=1e-5)
    assert manifest["parameters"] == gradnet.parameter_count(model) - gradnet.parameter_count(model.g_branch)


def _twin(model, b):
    """The reconstruction written out: per colour channel, numpy edge padding to multiples of 8,
    the signed mu-law (mu 16), one forward call, the crop and the inverse mu-law; a v2 network's
    L2 solution (a dense solve of its normal equations, on the unpadded image; the shortened L1
    solve, which has no closed form, is gradnet.solution's) and standard errors
    (the square roots of the variance buffers) among the inputs, in GradNet.forward's order."""
    h, w = b["indirect"].shape[:2]
    ph, pw = -h % 8, -w % 8
    pad = lambda a: np.pad(np.asarray(a, np.float64), ((0, ph), (0, pw), (0, 0)), mode="edge")  # noqa: E731
    comp = lambda x: np.sign(x) * np.log1p(16.0 * np.abs(x)) / np.log(17.0)  # noqa: E731
    feats = np.concatenate([pad(b["albedo"]), (pad(b["normal"]) + 1.0) / 2.0, pad(b["depth"])], axis=2)
    out = np.zeros((h, w, 3))
    if model.residual == "l1":  # a truncated IRLS (its three channels as one system) has no closed form
        l1 = gradnet.solution("l1", *(np.asarray(b[k], np.float64) for k in ("indirect", "dx", "dy")))
    for c in range(3):
        data = [comp(pad(b["indirect"])[..., c:c + 1]), feats]
        grads = [comp(pad(b["dx"])[..., c]), comp(pad(b["dy"])[..., c])]
        ind, gx, gy = (np.asarray(b[k], np.float64)[..., c] for k in ("indirect", "dx", "dy"))
        if model.residual == "l2":
            data.append(comp(pad(_dense_l2(ind, gx, gy, gradnet.L2_ALPHA)[..., None])))
        elif model.residual == "l1":
            data.append(comp(pad(l1[..., c:c + 1])))
        if model.noise:
            data.append(comp(np.sqrt(pad(b["base_variance"])[..., c:c + 1])))
            grads += [comp(np.sqrt(pad(b[k])[..., c])) for k in ("dx_variance", "dy_variance")]
        data = np.concatenate(data, axis=2).transpose(2, 0, 1)
        grads = np.stack(grads)
        with torch.no_grad():
            t = model(torch.tensor(data[None], dtype=torch.float32), torch.tensor(grads[None], dtype=torch.float32))
        t = t[0, 0, :h, :w].double().numpy()
        out[..., c] = np.sign(t) * np.expm1(np.abs(t) * np.log(17.0)) / 16.0
    return out


@pytest.mark.parametrize("name,correction", [("gradnet", 0), ("gradnet", 1), ("gradnet_v2", 1)])
def test_render_is_the_network_on_its_own_buffers(name, correction):
    """A 29 x 21 render (not a multiple of 8): image = twin(buffers) (energy-corrected against the
    indirect buffer when asked) + direct."""
    scene = _scene("cornell", 29, 21)
    r = tracer.render(scene, spp=4, seed=2, integrator="gpt", recon="gradnet",
                      recon_settings={"correction": correction, "weights": name})
    assert_clean(r)
    b = r.buffers
    rec = _twin(gradient.gradnet_model(name), b)
    if correction:
        rec = gradnet.energy_correction(rec, b["indirect"])
    np.testing.assert_allclose(r.image, rec + b["direct"], rtol=2e-4, atol=2e-5)
    assert r.stats["time_inference"] > 0 and r.stats["time_solve"] == r.stats["time_inference"]


def test_correction_changes_the_image():
    scene = _scene("cornell", 24, 24)
    a = tracer.render(scene, spp=2, seed=1, integrator="gpt", recon="gradnet")
    b = tracer.render(scene, spp=2, seed=1, integrator="gpt", recon="gradnet", recon_settings={"correction": 0})
    assert not np.array_equal(a.image, b.image)
    np.testing.assert_array_equal(a.buffers["indirect"], b.buffers["indirect"])


@pytest.mark.parametrize("name", SCENES)
def test_no_nonfinite_pixel_on_any_built_in_scene(name):
    """Every built-in scene at 16 x 16, 2 spp: no non-finite sample, a finite image."""
    r = tracer.render(_scene(name, 16, 16), spp=2, integrator="gpt", recon="gradnet", seed=1)
    assert_clean(r)
    assert np.isfinite(r.image).all()


def test_settings_errors():
    scene = _scene("cornell", 8, 8)
    with pytest.raises(SettingsError, match="integrator 'gpt' has no setting 'sigma'; valid: correction, direct_roughness, nee, recon, recon_alpha, roughness, "
                                                "shift, weights"):
        tracer.render(scene, spp=1, integrator="gpt", recon="gradnet", recon_settings={"sigma": 3})
    with pytest.raises(SettingsError, match="correction must be 0 or 1"):
        tracer.render(scene, spp=1, integrator="gpt", recon="gradnet", recon_settings={"correction": 2})
    with pytest.raises(SettingsError, match="nosuch.json: no weights"):
        tracer.render(scene, spp=1, integrator="gpt", recon="gradnet", recon_settings={"weights": "nosuch"})
    with pytest.raises(SettingsError, match="integrator 'path' has no setting 'correction'; valid: nee"):
        tracer.render(scene, spp=1, recon_settings={"correction": 0})
    with pytest.raises(SettingsError, match="reconstruction 'l1' has no setting"):
        tracer.render(scene, spp=1, integrator="gpt", recon="l1", recon_settings={"weights": "gradnet"})


def test_cli(tmp_path, capsys):
    obj = os.path.join(ROOT, "scenes", "cornell", "cornell.obj")
    out = str(tmp_path / "g.exr")
    assert main([obj, "--integrator", "gpt", "--recon", "gradnet", "--spp", "2", "--width", "12", "--height", "10",
                 "-q", "-o", out]) == 0
    with open(str(tmp_path / "g.json")) as f:
        st = json.load(f)
    assert st["recon"] == "gradnet" and st["recon_settings"] == {"weights": "gradnet", "correction": 1}
    assert math.isfinite(st["time_inference"])
    capsys.readouterr()
    assert main([obj, "--integrator", "gpt", "--recon", "gradnet", "--recon-opt", "weights=nosuch", "-q",
                 "-o", str(tmp_path / "h.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nosuch.json: no weights" in err[0]
    assert main([obj, "--recon-opt", "correction=0", "-q", "-o", str(tmp_path / "i.exr")]) == 2
    assert "integrator 'path' has no setting 'correction'" in capsys.readouterr().err
    assert main([obj, "--integrator", "gpt", "--recon", "gradnet", "--recon-opt", "weights=odis", "-q",
                 "-o", str(tmp_path / "j.exr")]) == 2  # another network's weights
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'odis' are not GradNet weights" in err[0]


def test_bench_convergence_runs_gpt_gradnet():
    """bench.convergence's gpt-gradnet and gpt-gradnet-raw are GradNet renders (with and without the
    correction): their records time the network and score its image."""
    from bench import convergence

    scene = _scene("cornell", 16, 16)
    ref = tracer.render(scene, spp=8, seed=9).image
    recs = {}
    for m in ("gpt-gradnet", "gpt-gradnet-raw"):
        convergence.check_method(m)
        recs[m] = convergence.run_one(scene, m, 0, ref, spp=2)
        assert recs[m]["solve_s"] > 0 and recs[m]["nonfinite_samples"] == 0
        assert math.isfinite(recs[m]["metrics"]["relMSE"])
    assert recs["gpt-gradnet"]["metrics"]["relMSE"] != recs["gpt-gradnet-raw"]["metrics"]["relMSE"]
    assert convergence.GRADIENT_METHODS["gpt-gradnet-raw"]["integrator"] == "gpt:recon=gradnet,correction=0"


def test_time_budget_with_gradnet_v2():
    """A timed render reserves the reconstruction's time from an estimate made on synthetic buffers:
    the v2 weights read the variance buffers, so synthetic buffers without them fail the render
    before it starts (what this detects), and the estimate must be a positive, finite time."""
    est = gradient.solve_time_estimate("gradnet", 256, 256, 0.2, {"weights": "gradnet_v2"})
    assert math.isfinite(est) and est > 0
    r = tracer.render(_scene("cornell", 16, 16), time=1.0, seed=0, integrator="gpt", recon="gradnet",
                      recon_settings={"weights": "gradnet_v2"})
    assert_clean(r)
    assert np.isfinite(r.image).all()
