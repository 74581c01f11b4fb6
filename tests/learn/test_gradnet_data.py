"""GradNet's training data (learn/gradnet_data.py).

What each test can detect: channels stacked in the wrong order or the normals not mapped to
[0, 1]; a patch with NaN, inf or negative light kept (or one with legitimately negative gradients
dropped); a shard that differs between two calls for one seed, loses count of its patches, or
cuts its reference from another place than its inputs.
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
    x = gradnet_data.patch_stack(bufs)
    assert x.shape == (19, h, w)
    np.testing.assert_array_equal(x[:12, 0, 0], np.repeat([1.0, 2.0, 3.0, 4.0], 3))
    np.testing.assert_array_equal(x[12:19, 1, 2], [0.25, 0.25, 0.25, 0.5, 0.5, 0.0, 0.75])


def test_illegal_patches():
    x = np.ones((19, 4, 4), np.float32)
    assert gradnet_data.legal(x)
    y = x.copy()
    y[3:9] = -2.0  # gradients may be negative
    assert gradnet_data.legal(y)
    for ch, v in ((0, -1e-3), (10, -1.0), (5, np.nan), (14, np.inf)):
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
