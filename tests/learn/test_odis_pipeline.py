"""learn/ for the ODIS network, tiny: two shards of small diffuse scenes, a few training steps with
a checkpoint and a resume, export, and a render with the exported weights.

What it can detect: a shard that differs between two calls for one seed (non-determinism); shards
whose ground truth lies outside the valid hemisphere or whose masks disagree with the features;
a resumed run whose weights differ from an uninterrupted one's; an export whose manifest does not
describe its weights, the data's depth or the data command's options; weights the guide cannot render with.
"""
import argparse
import os

import numpy as np
import pytest

import tracer
from learn import odis_data, scenes
from learn.shards import list_shards, run_shards, shard_path
from tracer.guiding import make_guide

TINY = dict(width=24, height=24, centres=6, per_bin=4)


def _tiny_shard(seed, path):
    odis_data.make_shard(seed, path, **TINY)


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("odis_data"))
    for seed in (3, 4):
        _tiny_shard(seed, shard_path(out, seed))
    return out


def test_shards_are_deterministic_and_consistent(shards, tmp_path):
    assert run_shards(_tiny_shard, [3, 4], shards, workers=1, progress=False) == {}, "finished shards were rerun"
    _tiny_shard(3, str(tmp_path / "again.npz"))
    a, b = np.load(shard_path(shards, 3)), np.load(str(tmp_path / "again.npz"))
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k], err_msg=f"shard 3, {k}: two calls differ")
    d = odis_data.load_shards(list_shards(shards))
    assert d["gt"].shape[0] > 0, "the tiny shards kept no map: the rest of this test would test nothing"
    assert (d["gt"][d["valid"] == 0] == 0).all(), "ground truth below the surface"
    assert (d["sampled"] <= 1).all() and (d["feats"][:, 0][d["sampled"] == 0] == 0).all()
    np.testing.assert_allclose(np.linalg.norm(d["normal"], axis=1), 1.0, rtol=1e-6)


def _args(out, run, epochs):
    return argparse.Namespace(data=out, run=run, width=2, epochs=epochs, patience=3, batch=4, lr=1e-3, loss="kl",
                              val_scenes=0.5, max_steps=2, minutes=None, seed=0, device="cpu")


def test_resume_export_and_render(shards, tmp_path):
    import torch

    from learn.odis_train import export, train
    from tracer.guiding.odis import net as odis_net

    straight, resumed = str(tmp_path / "straight"), str(tmp_path / "resumed")
    s0 = train(_args(shards, straight, 2))
    s1 = train(_args(shards, resumed, 1))
    assert s1["epoch"] == 1 and s1["steps"] > 0
    st = train(_args(shards, resumed, 2))
    assert st["epoch"] == 2 and st["steps"] == s0["steps"] == 2 * s1["steps"]
    a = torch.load(os.path.join(straight, "checkpoint.pt"), weights_only=False)
    b = torch.load(os.path.join(resumed, "checkpoint.pt"), weights_only=False)
    for k, v in a["model"].items():
        assert torch.equal(v, b["model"][k]), f"{k}: the resumed run's weights differ"
    with pytest.raises(SystemExit, match="trained with loss=kl"):
        args = _args(shards, resumed, 3)
        args.loss = "l1"
        train(args)
    wdir = str(tmp_path / "weights")
    man = export(resumed, wdir, name="tiny")
    assert man["data"]["config"]["initial_depth"] == 3 and man["data"]["config"]["per_bin"] == TINY["per_bin"]
    cmd = man["data"]["command"]  # the options that remake the data
    assert f"--size {TINY['width']}" in cmd and f"--per-bin {TINY['per_bin']}" in cmd and "--initial-depth" not in cmd
    model, manifest = odis_net.load("tiny", folder=wdir)
    assert manifest["parameters"] == odis_net.parameter_count(model) == man["parameters"]
    g = make_guide("odis", stride=4)
    g.model, g.manifest = model, manifest
    sc = tracer.load_scene(scenes.make_scene(5, str(tmp_path / "scene"), 24, 24, diffuse_only=True))
    r = tracer.render(sc, spp=4, guide=g)
    assert r.stats["nonfinite_samples"] == 0
    assert g.stats()["fallback"] is None and g.stats()["pixels_guided"] > 0, "the exported network never ran"
    assert g.stats()["weights"] == "tiny", "the guide rendered with other weights than the exported ones"
