"""GradNet's training data (learn/gradnet_data.py).

What each test can detect: channels stacked in the wrong order or the normals not mapped to
[0, 1]; a patch with NaN, inf or negative light kept (or one with legitimately negative gradients
dropped); a shard that differs between two calls for one seed, loses count of its patches, or
cuts its reference from another place than its inputs; variance channels missing or out of order;
a `box` share that is not honoured (all boxes at 1, none at 0) or a box scene that is not closed.
"""
import numpy as np

import tracer
from learn import gradnet_data, scenes


def test_patch_stack_layout():
    h, w = 3, 4
    bufs = {name: np.full((h, w, 3), float(k + 1), np.float32) for k, name in enumerate(gradnet_data.CHANNELS)}
    bufs["albedo"] = np.full((h, w, 3), 0.25, np.float32)
    bufs["normal"] = np.zeros((h, w, 3), np.float32)
    bufs["normal"][..., 2] = -1.0
    bufs["depth"] = np.full((h, w, 1), 0.75, np.float32)
    for k, name in enumerate(gradnet_data.VARIANCES):
        bufs[name] = np.full((h, w, 3), 10.0 + k, np.float32)
    x = gradnet_data.patch_stack(bufs)
    assert x.shape == (gradnet_data.N_CHANNELS, h, w) == (28, h, w)
    np.testing.assert_array_equal(x[:12, 0, 0], np.repeat([1.0, 2.0, 3.0, 4.0], 3))
    np.testing.assert_array_equal(x[12:19, 1, 2], [0.25, 0.25, 0.25, 0.5, 0.5, 0.0, 0.75])
    np.testing.assert_array_equal(x[19:28, 2, 3], np.repeat([10.0, 11.0, 12.0], 3))


def test_illegal_patches():
    x = np.ones((28, 4, 4), np.float32)
    assert gradnet_data.legal(x)
    y = x.copy()
    y[3:9] = -2.0  # gradients may be negative
    assert gradnet_data.legal(y)
    for ch, v in ((0, -1e-3), (10, -1.0), (5, np.nan), (14, np.inf), (25, np.nan)):
        y = x.copy()
        y[ch, 1, 2] = v
        assert not gradnet_data.legal(y), (ch, v)


def test_a_tiny_shard(tmp_path):
    scene = tracer.load_scene(scenes.make_scene(3, str(tmp_path), 24, 20))
    cfg = dict(gradnet_data.DEFAULTS, patch=8, patches=5, reference_spp=4)
    a = gradnet_data.shard_arrays(scene, 3, cfg)
    b = gradnet_data.shard_arrays(scene, 3, cfg)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    m = a["x"].shape[0]
    assert m + int(a["dropped"]) == 5 and a["ref"].shape == (m, 3, 8, 8)
    assert int(a["spp"]) in gradnet_data.SPP
    assert np.isfinite(a["x"]).all() and (a["x"][:, 12:19] >= 0).all() and (a["x"][:, 12:19] <= 1).all()
    assert (a["x"][:, 19:28] >= 0).all() and (a["x"][:, 19:28] > 0).any()  # variances: some noise at 2+ spp
    # the spp comes from the config's set (data --spp), and the shard's own count says so
    for s in (0, 1, 2):
        assert int(gradnet_data.shard_arrays(scene, s, dict(cfg, spp=[2, 6]))["spp"]) in (2, 6)
    # every patch and its reference are cut at the same place of the two renders
    r = tracer.render(scene, spp=int(a["spp"]), seed=3, integrator="gpt", recon="none")
    full = gradnet_data.patch_stack(r.buffers)
    ref = tracer.render(scene, spp=4, seed=3 + 7919).image.transpose(2, 0, 1)
    assert m > 0, "every patch was dropped: the rest of this test would test nothing"
    for k, (y0, x0) in enumerate(a["where"]):
        np.testing.assert_array_equal(a["x"][k], full[:, y0:y0 + 8, x0:x0 + 8])
        np.testing.assert_array_equal(a["ref"][k], ref[:, y0:y0 + 8, x0:x0 + 8])


def test_box_share(tmp_path, monkeypatch):
    """`box` 1 makes every scene a box, 0 none; a box scene is closed (every camera ray hits)."""
    kinds = []
    real = scenes.make_scene

    def spy(seed, folder, width=64, height=64, kind=None, diffuse_only=False):
        kinds.append(kind)
        return real(seed, folder, width, height, kind, diffuse_only)

    monkeypatch.setattr(scenes, "make_scene", spy)
    monkeypatch.setattr(gradnet_data, "shard_arrays", lambda scene, seed, c: {"x": np.zeros(1)})
    monkeypatch.setattr("learn.shards.save_npz", lambda path, **arrays: None)
    for box in (1.0, 0.0):
        kinds.clear()
        for seed in range(6):
            gradnet_data.make_shard(seed, str(tmp_path / "s.npz"), box=box, width=8, height=8)
        assert kinds == (["box"] * 6 if box else [None] * 6)
    scene = tracer.load_scene(real(2, str(tmp_path / "b"), 16, 16, kind="box"))
    r = tracer.render(scene, spp=1, seed=0)
    assert np.isfinite(r.aovs["depth"]).all(), "a camera ray left the box"
