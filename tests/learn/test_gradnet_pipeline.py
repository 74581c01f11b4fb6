"""learn/ for GradNet, tiny: two shards of small scenes, a few training steps with a checkpoint and a
resume, export, and a render with the exported weights.

What it can detect: a resumed run whose weights differ from an uninterrupted one's (the shuffle,
the learning-rate decay or the optimiser state not restored); a changed setting accepted on
resume; validation figures that are not what their names say (the reported baselines against an
L1 solve of the same patches computed here); an export whose manifest does not describe its
weights or whose stored check output the weights do not reproduce; weights the renderer cannot
load by name.
"""
import argparse
import os

import numpy as np
import pytest
import torch

import tracer
from learn import gradnet_data, gradnet_train
from learn.shards import list_shards, shard_path
from tracer import gradient, metrics
from tracer.gradient import gradnet, poisson

TINY = dict(width=24, height=20, patch=8, patches=3, reference_spp=4)


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("gradnet_data"))
    for seed in (3, 4):
        gradnet_data.make_shard(seed, shard_path(out, seed), **TINY)
    return out


def _args(data, run, epochs):
    return argparse.Namespace(data=data, run=run, width=2, blocks=1, layout="v2", epochs=epochs, patience=3, batch=4, lr=1e-3,
                              alpha=1.0, lambda_max=2.0, val_scenes=0.5, max_steps=2, minutes=None, seed=0, device="cpu")


def test_validation_baselines_are_the_solves_of_the_patches(shards):
    va = gradnet_train.load_shards(list_shards(shards)[1:])
    assert va["x"].shape[0] > 0, "every patch was dropped: this test would test nothing"
    got = gradnet_train.baselines(va)["l1"]
    for k in range(va["x"].shape[0]):
        x = va["x"][k].astype(np.float64).transpose(1, 2, 0)
        img = poisson.solve_l1(x[..., 0:3], x[..., 3:6], x[..., 6:9], 0.2) + x[..., 9:12]
        assert got[k] == pytest.approx(metrics.relmse(img, va["ref"][k].transpose(1, 2, 0)), rel=1e-9)


@pytest.mark.parametrize("k", range(8))
def test_augmentation_keeps_the_gradients_the_images(k):
    """Under each symmetry of the square, the transformed dx, dy are the forward differences of the
    transformed image (a wrong sign, shift or swap fails), and features move with the image."""
    rng = np.random.default_rng(k)
    img = rng.random((1, 3, 8, 8))
    x = np.zeros((1, 31, 8, 8))
    x[:, 0:3] = img
    x[:, 3:6, :, :-1] = img[..., 1:] - img[..., :-1]
    x[:, 6:9, :-1, :] = img[..., 1:, :] - img[..., :-1, :]
    x[:, 3:6, :, -1] = rng.random((1, 3, 8))  # a gradient to a pixel outside the patch
    x[:, 6:9, -1, :] = rng.random((1, 3, 8))
    x[:, 9:22] = rng.random((1, 13, 8, 8))
    # each gradient's variance: a function of the pair of pixels it joins (symmetric in them)
    x[:, 22:25, :, :-1] = img[..., 1:] * img[..., :-1]
    x[:, 25:28, :-1, :] = img[..., 1:, :] * img[..., :-1, :]
    x[:, 28:] = rng.random((1, 3, 8, 8))
    y = gradnet_train.dihedral(torch.from_numpy(x), k).numpy()
    t = y[:, 0:3]
    np.testing.assert_allclose(y[:, 3:6, :, :-1], t[..., 1:] - t[..., :-1], atol=1e-12)
    np.testing.assert_allclose(y[:, 6:9, :-1, :], t[..., 1:, :] - t[..., :-1, :], atol=1e-12)
    np.testing.assert_allclose(y[:, 22:25, :, :-1], t[..., 1:] * t[..., :-1], atol=1e-12)
    np.testing.assert_allclose(y[:, 25:28, :-1, :], t[..., 1:, :] * t[..., :-1, :], atol=1e-12)
    # the pixel at the image value's new place carries its own features, variance and L2 solution
    yy, xx = np.unravel_index(np.argmax(t[0, 0]), (8, 8))
    oy, ox = np.unravel_index(np.argmax(img[0, 0]), (8, 8))
    np.testing.assert_array_equal(y[0, 9:22, yy, xx], x[0, 9:22, oy, ox])
    np.testing.assert_array_equal(y[0, 28:, yy, xx], x[0, 28:, oy, ox])
    # the image itself goes where the symmetry sends it
    want = img.transpose(0, 1, 3, 2) if k & 1 else img
    want = want[..., ::-1] if k & 2 else want
    want = want[..., ::-1, :] if k & 4 else want
    np.testing.assert_array_equal(t, want)


def test_resume_export_and_render(shards, tmp_path, monkeypatch):
    straight, resumed = str(tmp_path / "straight"), str(tmp_path / "resumed")
    s0 = gradnet_train.train(_args(shards, straight, 3))
    s1 = gradnet_train.train(_args(shards, resumed, 2))
    assert s1["epoch"] == 2 and s1["steps"] > 0
    st = gradnet_train.train(_args(shards, resumed, 3))  # epoch 3 runs at the decayed rate
    assert st["epoch"] == 3 and st["steps"] == s0["steps"] == 3 * s1["steps"] // 2
    assert st["history"][2]["lr"] == pytest.approx(1e-3 * 0.95)
    a = torch.load(os.path.join(straight, "checkpoint.pt"), weights_only=False)
    b = torch.load(os.path.join(resumed, "checkpoint.pt"), weights_only=False)
    for k, v in a["model"].items():
        assert torch.equal(v, b["model"][k]), f"{k}: the resumed run's weights differ"
    assert set(a["state"]["history"][0]) >= {"val_relmse", "val_select", "val_g", "lam"}
    with pytest.raises(SystemExit, match="trained with width=2"):
        args = _args(shards, resumed, 3)
        args.width = 3
        gradnet_train.train(args)
    wdir = str(tmp_path / "weights")
    man = gradnet_train.export(resumed, wdir, name="tiny")
    assert man["data"]["config"]["patch"] == TINY["patch"] and man["model"] == {"width": 2, "blocks": 1, "full_res": True,
                                                                            "residual": "l1", "noise": True, "head": 2}
    model, manifest = gradnet.load("tiny", folder=wdir)
    assert manifest["parameters"] + manifest["parameters_g_branch"] == gradnet.parameter_count(model)
    y = gradnet.reconstruct(model, **gradnet_train.check_input())
    np.testing.assert_allclose(y[10, :8], manifest["check"]["output_row"], rtol=1e-5, atol=1e-6)
    monkeypatch.setattr(gradnet, "WEIGHTS_DIR", wdir)
    gradient.gradnet_model.cache_clear()
    try:
        sc = tracer.load_scene(os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(__file__))),
                                            "scenes", "cornell", "cornell.obj"), width=16, height=12)
        r = tracer.render(sc, spp=2, integrator="gpt", recon="gradnet", recon_settings={"weights": "tiny"})
    finally:
        gradient.gradnet_model.cache_clear()
    assert r.stats["nonfinite_samples"] == 0 and np.isfinite(r.image).all()
