"""learn/ end to end, tiny: procedural scenes, two dataset shards on a Dask LocalCluster of two
workers, a few training steps with a checkpoint and a resume, export, and a render with the
exported weights.

What it can detect: a shard that differs between two runs of one seed, or between the cluster
and a plain call (non-determinism, or state leaking between shards in a worker); a rerun that
regenerates finished shards; shards with inputs or targets that are not normalised maps; a
resumed training run whose weights differ from an uninterrupted one's (optimiser state or shuffle
not restored); an export whose manifest does not describe its weights or data; weights the
renderer cannot load.
"""
import argparse
import json
import os

import numpy as np
import pytest

import tracer
from learn import photon_data, scenes
from learn.shards import list_shards, run_shards, shard_path
from tracer.guiding import make_guide
from tracer.guiding.grid.reconstruct import CNN

TINY = dict(width=16, height=16, n0=30, t_max=3, n_gt=60_000, max_voxels=40, keep=16, gt_min=20, gt_ratio=2.0,
            r_min=6, r_max=12)


def _tiny_shard(seed, path):
    photon_data.make_shard(seed, path, **TINY)


def test_procedural_scenes_are_reproducible_and_load(tmp_path):
    for seed in range(6):
        a = scenes.make_scene(seed, str(tmp_path / "a"))
        b = scenes.make_scene(seed, str(tmp_path / "b"))
        for ext in (".obj", ".mtl", ".json"):
            assert open(a[:-4] + ext).read() == open(b[:-4] + ext).read()
        sc = tracer.load_scene(a)
        assert sc.emissive.any() or sc.environment is not None, f"seed {seed}: a scene without light"
        assert not sc.warnings, f"seed {seed}: {sc.warnings}"
    kinds = {json.load(open(scenes.make_scene(s, str(tmp_path / "k"))[:-4] + ".json")).get("environment") is not None
             for s in range(12)}
    assert kinds == {True, False}, "twelve seeds give no scene with a sky, or none without"


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("photon_data"))
    done = run_shards(_tiny_shard, [3, 4], out, workers=2, progress=False)
    return out, done


def test_two_shards_on_a_local_cluster_are_deterministic_and_resumable(shards, tmp_path):
    out, done = shards
    assert sorted(done) == [3, 4]
    assert run_shards(_tiny_shard, [3, 4], out, workers=2, progress=False) == {}, "finished shards were rerun"
    _tiny_shard(3, str(tmp_path / "again.npz"))
    a, b = np.load(shard_path(out, 3)), np.load(str(tmp_path / "again.npz"))
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k], err_msg=f"shard 3, {k}: the cluster's and a plain call differ")
    d = photon_data.load_shards(list_shards(out))
    n = d["target"].shape[0]
    assert n > 0, "the tiny shards kept no sample: the rest of this test would test nothing"
    k = d["target"].shape[1] * d["target"].shape[2]
    # maps are normalised to mean 1 (float16 storage: relative error ~1e-3 per bin)
    np.testing.assert_allclose(d["target"].astype(np.float64).mean(axis=(1, 2)), 1.0, rtol=5e-3)
    np.testing.assert_allclose(d["inputs"][:, 0].astype(np.float64).mean(axis=(1, 2)), 1.0, rtol=5e-3)
    counts = d["inputs"][:, 2].astype(np.float64)
    np.testing.assert_array_equal(counts.sum(axis=(1, 2)), d["n_in"])
    assert np.all(d["inputs"][:, 3] <= d["inputs"][:, 2]), "P_{t-1} exceeds P_t: the input is not cumulative"
    assert np.all((d["inputs"][:, 0] > 0) <= (counts > 0)), "power in a bin without photons"
    assert k == 2048


def _args(out, run, epochs):
    return argparse.Namespace(data=out, run=run, width=4, epochs=epochs, patience=3, batch=8, lr=1e-3, lam=2.0,
                              val_scenes=0.5, max_steps=2, seed=0, device="cpu")


def test_a_resumed_run_takes_the_steps_of_one_that_never_stopped(shards, tmp_path):
    import torch

    from learn.photon_train import train

    out, _ = shards
    straight, resumed = str(tmp_path / "straight"), str(tmp_path / "resumed")
    train(_args(out, straight, 2))
    st = train(_args(out, resumed, 1))
    assert st["epoch"] == 1 and st["steps"] == 2
    st = train(_args(out, resumed, 2))
    assert st["epoch"] == 2 and len(st["history"]) == 2 and st["steps"] == 4
    a = torch.load(os.path.join(straight, "checkpoint.pt"), weights_only=False)
    b = torch.load(os.path.join(resumed, "checkpoint.pt"), weights_only=False)
    for k, v in a["model"].items():
        assert torch.equal(v, b["model"][k]), f"{k}: the resumed run's weights differ"
    with pytest.raises(SystemExit, match="trained with width=4"):
        args = _args(out, resumed, 3)
        args.width = 8
        train(args)


def test_export_and_render_with_the_exported_weights(shards, tmp_path):
    from learn.photon_train import export, train

    out, _ = shards
    run = str(tmp_path / "run")
    train(_args(out, run, 1))
    wdir = str(tmp_path / "weights")
    man = export(run, wdir)
    assert man["data"]["config"]["n_gt"] == TINY["n_gt"], "the manifest does not record the shards' settings"
    rc = CNN(weights=wdir)
    model = rc.load()
    assert rc.manifest["parameters"] == sum(p.numel() for p in model.parameters()) == man["parameters"]
    g = make_guide("photon", reconstruct="cnn", iterations=2, cnn_max_photons=1e9)
    g.reconstructor = rc
    sc = tracer.load_scene(scenes.make_scene(5, str(tmp_path / "scene"), 24, 24))
    r = tracer.render(sc, spp=8, guide=g)
    assert r.stats["nonfinite_samples"] == 0
    assert rc.maps_inferred > 0 and g.stats()["voxels_with_map"] > 0, "the exported network never ran"
